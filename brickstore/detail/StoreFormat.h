#pragma once
// Byte-level encoding of the store header and index (FORMAT.md), shared by the writer and
// the reader so that the two can never disagree on a field.
#include "brickstore/BrickStore.h"

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

namespace bc::brickstore::detail {

constexpr char kMagic[8] = {'B', 'C', 'S', 'T', 'O', 'R', 'E', '\0'};
/// What this build writes. Version 1 (read still) kept a leaf table of every leaf of a brick;
/// version 2 keeps only the leaves whose payload meets the volume (StoreLayout::leavesInside).
constexpr std::uint32_t kFormatVersion = 2;
constexpr std::uint32_t kOldestFormatVersion = 1;
constexpr std::uint64_t kHeaderBytes = 4096;
constexpr std::uint64_t kLevelEntryBytes = 40;
constexpr std::uint64_t kRecordBytes = 48;
constexpr std::uint32_t kMaxHistogramBins = 1u << 16;
constexpr std::uint32_t kMaxDescriptionBytes = 4096;
constexpr std::uint64_t kLeafEntryBytes = 8;

/// The fixed header fields (offsets in FORMAT.md).
struct StoreHeader {
    std::uint32_t version = kFormatVersion;
    VolumeInfo volume;
    BrickGeometry geometry;
    std::uint32_t levelCount = 0;
    std::uint32_t histogramBins = 0;
    double valueMin = 0.0, valueMax = 0.0;
    std::uint64_t indexOffset = 0, indexBytes = 0, indexChecksum = 0;
    std::uint64_t fileBytes = 0, brickCount = 0, storedBricks = 0, storedBytes = 0;
};

std::uint64_t checksum(std::span<const std::byte> bytes);
std::uint64_t checksum(const void* data, std::size_t bytes);

/// Leaf table entries a stored brick of a store of `version` carries.
std::uint64_t leafEntries(const StoreLayout& layout, const BrickKey& key, std::uint32_t version);

/// Exactly kHeaderBytes bytes, checksum included (header.version is written as given).
std::vector<std::byte> encodeHeader(const StoreHeader& header);
/// @throw StoreCorrupt (prefixed by `storeName`) on a bad checksum, magic, version or field.
StoreHeader decodeHeader(std::span<const std::byte> bytes, const std::string& storeName);

std::uint64_t indexBytesFor(std::uint32_t levelCount, std::uint64_t brickCount, std::uint32_t bins,
                            std::size_t descriptionBytes);
std::vector<std::byte> encodeIndex(const StoreLayout& layout, std::span<const BrickRecord> records,
                                   std::span<const std::uint64_t> histogram,
                                   const std::string& description);

struct DecodedIndex {
    std::vector<BrickRecord> records;
    std::vector<std::uint64_t> histogram;
    std::string description;
};
/// Checks the level table against `layout` and every field's own limits (not offsets).
/// @throw StoreCorrupt naming the store and, per record, the brick.
DecodedIndex decodeIndex(std::span<const std::byte> bytes, const StoreHeader& header,
                         const StoreLayout& layout, const std::string& storeName);

/// Little-endian cursor over a byte span; reading past the end throws StoreCorrupt.
class ByteReader {
  public:
    ByteReader(std::span<const std::byte> bytes, std::string context)
        : mBytes(bytes), mContext(std::move(context)) {}
    std::uint8_t u8();
    std::uint32_t u32();
    std::uint64_t u64();
    float f32();
    double f64();
    std::span<const std::byte> take(std::size_t n);
    std::size_t position() const { return mPos; }

  private:
    std::span<const std::byte> mBytes;
    std::string mContext;
    std::size_t mPos = 0;
};

/// Little-endian appender.
class ByteWriter {
  public:
    void u8(std::uint8_t v) { mBytes.push_back(std::byte{v}); }
    void u32(std::uint32_t v);
    void u64(std::uint64_t v);
    void f32(float v);
    void f64(double v);
    void bytes(const void* data, std::size_t n);
    void zeros(std::size_t n) { mBytes.insert(mBytes.end(), n, std::byte{0}); }
    std::vector<std::byte>& data() { return mBytes; }

  private:
    std::vector<std::byte> mBytes;
};

} // namespace bc::brickstore::detail
