#pragma once
// Little-endian primitives of the wire format: a writer that appends to a byte vector and a
// bounds-checked reader over a payload. Private to bc_protocol.
#include <bit>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string_view>
#include <vector>

namespace bc::protocol::detail {

/// Appends little-endian values to `out`; never clears it.
class ByteWriter {
  public:
    explicit ByteWriter(std::vector<std::uint8_t>& out) : mOut(out) {}

    void u8(std::uint8_t v) { mOut.push_back(v); }
    void u16(std::uint16_t v) { uint(v, 2); }
    void u32(std::uint32_t v) { uint(v, 4); }
    void u64(std::uint64_t v) { uint(v, 8); }
    void f32(float v) { u32(std::bit_cast<std::uint32_t>(v)); }
    void f64(double v) { u64(std::bit_cast<std::uint64_t>(v)); }
    void boolean(bool v) { u8(v ? 1 : 0); }
    /// A `str`: u16 byte count then the bytes (the caller has checked the length).
    void str(std::string_view s) {
        u16(static_cast<std::uint16_t>(s.size()));
        mOut.insert(mOut.end(), s.begin(), s.end());
    }
    void bytes(std::span<const std::uint8_t> b) { mOut.insert(mOut.end(), b.begin(), b.end()); }
    /// Overwrites 4 bytes at `offset` (a length patched in once the payload is written).
    void patchU32(std::size_t offset, std::uint32_t v) {
        for (int i = 0; i < 4; ++i)
            mOut[offset + i] = static_cast<std::uint8_t>(v >> (8 * i));
    }
    std::size_t size() const { return mOut.size(); }

  private:
    void uint(std::uint64_t v, int bytes) {
        for (int i = 0; i < bytes; ++i)
            mOut.push_back(static_cast<std::uint8_t>(v >> (8 * i)));
    }
    std::vector<std::uint8_t>& mOut;
};

/// Reads little-endian values from the front of `bytes`. The caller checks remaining()
/// first: reading past the end is a programming error here (asserted by returning zeros).
class ByteReader {
  public:
    explicit ByteReader(std::span<const std::uint8_t> bytes) : mBytes(bytes) {}

    std::uint8_t u8() { return static_cast<std::uint8_t>(uint(1)); }
    std::uint16_t u16() { return static_cast<std::uint16_t>(uint(2)); }
    std::uint32_t u32() { return static_cast<std::uint32_t>(uint(4)); }
    std::uint64_t u64() { return uint(8); }
    float f32() { return std::bit_cast<float>(u32()); }
    double f64() { return std::bit_cast<double>(u64()); }
    /// The next n bytes (n <= remaining()).
    std::span<const std::uint8_t> take(std::size_t n) {
        if (n > remaining()) n = remaining();
        auto s = mBytes.subspan(mPos, n);
        mPos += n;
        return s;
    }
    std::size_t remaining() const { return mBytes.size() - mPos; }
    std::size_t offset() const { return mPos; }

  private:
    std::uint64_t uint(std::size_t bytes) {
        if (bytes > remaining()) {
            mPos = mBytes.size();
            return 0;
        }
        std::uint64_t v = 0;
        for (std::size_t i = 0; i < bytes; ++i)
            v |= std::uint64_t(mBytes[mPos + i]) << (8 * i);
        mPos += bytes;
        return v;
    }
    std::span<const std::uint8_t> mBytes;
    std::size_t mPos = 0;
};

} // namespace bc::protocol::detail
