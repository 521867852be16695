#include "brickstore/detail/StoreFormat.h"

#include "brickstore/Error.h"

#include <bit>
#include <cmath>
#include <cstring>
#include <xxhash.h>
#include <zstd.h>

namespace bc::brickstore::detail {

static_assert(std::endian::native == std::endian::little,
              "the store is little-endian; a big-endian host needs byte swaps here");

std::uint64_t checksum(const void* data, std::size_t bytes) {
    return XXH3_64bits(data, bytes);
}
std::uint64_t checksum(std::span<const std::byte> bytes) {
    return checksum(bytes.data(), bytes.size());
}

// ---- ByteReader / ByteWriter ------------------------------------------------------------

std::span<const std::byte> ByteReader::take(std::size_t n) {
    if (n > mBytes.size() - mPos)
        throw StoreCorrupt(mContext + ": truncated at byte " + std::to_string(mPos));
    auto s = mBytes.subspan(mPos, n);
    mPos += n;
    return s;
}
template <typename T> static T load(std::span<const std::byte> s) {
    T v;
    std::memcpy(&v, s.data(), sizeof v);
    return v;
}
std::uint8_t ByteReader::u8() {
    return load<std::uint8_t>(take(1));
}
std::uint32_t ByteReader::u32() {
    return load<std::uint32_t>(take(4));
}
std::uint64_t ByteReader::u64() {
    return load<std::uint64_t>(take(8));
}
float ByteReader::f32() {
    return load<float>(take(4));
}
double ByteReader::f64() {
    return load<double>(take(8));
}

void ByteWriter::bytes(const void* data, std::size_t n) {
    auto p = static_cast<const std::byte*>(data);
    mBytes.insert(mBytes.end(), p, p + n);
}
void ByteWriter::u32(std::uint32_t v) {
    bytes(&v, 4);
}
void ByteWriter::u64(std::uint64_t v) {
    bytes(&v, 8);
}
void ByteWriter::f32(float v) {
    bytes(&v, 4);
}
void ByteWriter::f64(double v) {
    bytes(&v, 8);
}

// ---- header -------------------------------------------------------------------------------

std::vector<std::byte> encodeHeader(const StoreHeader& h) {
    ByteWriter w;
    w.bytes(kMagic, 8);
    w.u32(h.version);
    w.u32(static_cast<std::uint32_t>(kHeaderBytes));
    for (auto d : h.volume.dims)
        w.u64(d);
    w.u8(static_cast<std::uint8_t>(h.volume.type));
    w.zeros(3);
    w.u32(h.geometry.brickVoxels);
    w.u32(h.geometry.apronVoxels);
    w.u32(h.geometry.leafVoxels);
    w.u32(h.levelCount);
    w.u32(h.histogramBins);
    for (auto s : h.volume.spacingMm)
        w.f64(s);
    for (auto o : h.volume.originMm)
        w.f64(o);
    w.f64(h.valueMin);
    w.f64(h.valueMax);
    w.f64(h.volume.background);
    for (auto v : {h.indexOffset, h.indexBytes, h.indexChecksum, h.fileBytes, h.brickCount,
                   h.storedBricks, h.storedBytes})
        w.u64(v);
    w.f64(h.volume.valueScale);
    w.f64(h.volume.valueOffset);
    w.zeros(kHeaderBytes - 8 - w.data().size());
    w.u64(checksum(w.data().data(), w.data().size()));
    return std::move(w.data());
}

StoreHeader decodeHeader(std::span<const std::byte> bytes, const std::string& store) {
    if (bytes.size() < kHeaderBytes)
        throw StoreCorrupt(store + ": truncated: " + std::to_string(bytes.size()) +
                           " bytes, shorter than the header");
    if (std::memcmp(bytes.data(), kMagic, 8) != 0)
        throw StoreCorrupt(store + ": not a brickcast store (bad magic; an unfinished ingest?)");
    std::uint64_t stored = load<std::uint64_t>(bytes.subspan(kHeaderBytes - 8, 8));
    if (stored != checksum(bytes.data(), kHeaderBytes - 8))
        throw StoreCorrupt(store + ": header checksum mismatch");
    ByteReader r(bytes.first(kHeaderBytes), store + ": header");
    r.take(8);
    StoreHeader h;
    h.version = r.u32();
    if (h.version < kOldestFormatVersion || h.version > kFormatVersion)
        throw StoreCorrupt(store + ": format version " + std::to_string(h.version) +
                           " is not supported (this build reads versions " +
                           std::to_string(kOldestFormatVersion) + " to " +
                           std::to_string(kFormatVersion) + ")");
    if (r.u32() != kHeaderBytes) throw StoreCorrupt(store + ": header: unexpected header size");
    for (auto& d : h.volume.dims)
        d = r.u64();
    std::uint8_t type = r.u8();
    if (!isValidVoxelType(type))
        throw StoreCorrupt(store + ": header: unknown voxel type " + std::to_string(type));
    h.volume.type = static_cast<VoxelType>(type);
    r.take(3);
    h.geometry.brickVoxels = r.u32();
    h.geometry.apronVoxels = r.u32();
    h.geometry.leafVoxels = r.u32();
    h.levelCount = r.u32();
    h.histogramBins = r.u32();
    for (auto& s : h.volume.spacingMm)
        s = r.f64();
    for (auto& o : h.volume.originMm)
        o = r.f64();
    h.valueMin = r.f64();
    h.valueMax = r.f64();
    h.volume.background = r.f64();
    for (auto* v : {&h.indexOffset, &h.indexBytes, &h.indexChecksum, &h.fileBytes, &h.brickCount,
                    &h.storedBricks, &h.storedBytes})
        *v = r.u64();
    h.volume.valueScale = r.f64();
    h.volume.valueOffset = r.f64();
    if (!std::isfinite(h.volume.valueScale) || h.volume.valueScale == 0.0 ||
        !std::isfinite(h.volume.valueOffset))
        throw StoreCorrupt(store + ": header: value scale/offset must be finite, scale non-zero");
    if (h.histogramBins > kMaxHistogramBins)
        throw StoreCorrupt(store + ": header: histogram of " + std::to_string(h.histogramBins) +
                           " bins exceeds the limit");
    if (!(h.valueMin <= h.valueMax))
        throw StoreCorrupt(store + ": header: value range is empty or NaN");
    return h;
}

// ---- index --------------------------------------------------------------------------------

std::uint64_t indexBytesFor(std::uint32_t levels, std::uint64_t bricks, std::uint32_t bins,
                            std::size_t descriptionBytes) {
    return levels * kLevelEntryBytes + bricks * kRecordBytes + std::uint64_t(bins) * 8 + 4 +
           descriptionBytes;
}

std::vector<std::byte> encodeIndex(const StoreLayout& layout, std::span<const BrickRecord> records,
                                   std::span<const std::uint64_t> histogram,
                                   const std::string& description) {
    ByteWriter w;
    for (const auto& l : layout.levels()) {
        for (auto d : l.dims)
            w.u64(d);
        for (auto b : l.bricks)
            w.u32(b);
        w.u32(0);
    }
    for (const auto& r : records) {
        w.u64(r.offset);
        w.u32(r.compressedBytes);
        w.u32(r.leafBytes);
        w.u32(r.flags);
        w.f32(r.range.min);
        w.f32(r.range.max);
        w.u32(0);
        w.u64(r.payloadChecksum);
        w.u64(r.leafChecksum);
    }
    for (auto c : histogram)
        w.u64(c);
    std::string d = description.substr(0, kMaxDescriptionBytes);
    w.u32(static_cast<std::uint32_t>(d.size()));
    w.bytes(d.data(), d.size());
    return std::move(w.data());
}

std::uint64_t leafEntries(const StoreLayout& layout, const BrickKey& key, std::uint32_t version) {
    if (version < 2) return layout.leafCount();
    const auto n = layout.leavesInside(key);
    return std::uint64_t(n[0]) * n[1] * n[2];
}

static void checkRecord(const BrickRecord& r, const StoreLayout& layout, std::uint64_t index,
                        std::uint32_t version, const std::string& store) {
    auto fail = [&](const std::string& why) {
        throw StoreCorrupt(store + ": brick " + layout.keyOf(index).toString() + ": " + why);
    };
    if ((r.flags & ~kBrickStored) != 0) fail("unknown flags");
    if (!(r.range.min <= r.range.max)) fail("value range is empty or NaN");
    if (!r.stored()) {
        if (r.offset || r.compressedBytes || r.leafBytes) fail("constant brick with a payload");
        return;
    }
    std::uint64_t brickBytes = layout.storedVoxels() * 4; // bound for any type
    if (r.compressedBytes == 0 || r.compressedBytes > ZSTD_compressBound(brickBytes))
        fail("compressed size " + std::to_string(r.compressedBytes) + " out of range");
    const std::uint64_t leafBytes =
        leafEntries(layout, layout.keyOf(index), version) * kLeafEntryBytes;
    if (r.leafBytes != leafBytes)
        fail("leaf table of " + std::to_string(r.leafBytes) + " bytes, expected " +
             std::to_string(leafBytes));
}

DecodedIndex decodeIndex(std::span<const std::byte> bytes, const StoreHeader& h,
                         const StoreLayout& layout, const std::string& store) {
    ByteReader r(bytes, store + ": index");
    if (layout.levels().size() != h.levelCount)
        throw StoreCorrupt(store + ": header: level count " + std::to_string(h.levelCount) +
                           " does not match dims and brick size");
    for (std::size_t li = 0; li < layout.levels().size(); ++li) {
        const auto& l = layout.levels()[li];
        bool same = true;
        for (auto d : l.dims)
            same &= r.u64() == d;
        for (auto b : l.bricks)
            same &= r.u32() == b;
        r.u32();
        if (!same)
            throw StoreCorrupt(store + ": index: level " + std::to_string(li) +
                               " table is inconsistent");
    }
    DecodedIndex out;
    out.records.resize(layout.brickCount());
    for (std::uint64_t i = 0; i < layout.brickCount(); ++i) {
        BrickRecord& rec = out.records[i];
        rec.offset = r.u64();
        rec.compressedBytes = r.u32();
        rec.leafBytes = r.u32();
        rec.flags = r.u32();
        rec.range.min = r.f32();
        rec.range.max = r.f32();
        r.u32();
        rec.payloadChecksum = r.u64();
        rec.leafChecksum = r.u64();
        checkRecord(rec, layout, i, h.version, store);
    }
    out.histogram.resize(h.histogramBins);
    for (auto& c : out.histogram)
        c = r.u64();
    std::uint32_t len = r.u32();
    if (len > kMaxDescriptionBytes) throw StoreCorrupt(store + ": index: description too long");
    auto d = r.take(len);
    out.description.assign(reinterpret_cast<const char*>(d.data()), d.size());
    if (r.position() != bytes.size()) throw StoreCorrupt(store + ": index: trailing bytes");
    return out;
}

} // namespace bc::brickstore::detail
