// libFuzzer target of the brick store reader: BrickStore::open (header, index, placement
// checks; brickstore/detail/StoreFormat) and the reads a renderer makes (records, bricks,
// leaf tables); scripts/fuzz.sh brick_store builds and runs it.
//
// Input: byte 0 says which checksums to repair after mutation (so the fuzzer gets past them
// to the fields they guard): bit 0 the header checksum, bit 1 the index checksum, bit 2 the
// stored bricks' payload and leaf checksums, bit 3 the header's file size. The rest is the
// store file, written to a private scratch folder. StoreCorrupt or StoreIoError is the
// expected refusal; a crash, sanitizer report or other exception is a finding. A store that
// opens must answer record(), leafRanges() (leafCount entries) and readBrick() for its first
// 64 bricks with data or StoreCorrupt; for a small store, verify() must find no fault exactly
// when every stored brick read cleanly.
//
// With BC_FUZZ_SEED_DIR set, the binary first writes seeds there: small stores ingested
// (brickstore/Ingest.h, 8^3 bricks) from crops of real scans (BC_SHARED_DATA_DIR) and from
// synthetic volumes, with every repair bit set.
#include "brickstore/BrickStore.h"
#include "brickstore/Error.h"
#include "brickstore/Ingest.h"
#include "brickstore/Readers.h"
#include "brickstore/detail/StoreFormat.h"
#include "tests/fuzz/FuzzSupport.h"

#include <cstring>

namespace {

using namespace bc;
using namespace bc::brickstore;
using fuzz::Bytes;
using fuzz::require;

constexpr std::uint8_t kFixHeader = 1, kFixIndex = 2, kFixBricks = 4, kFixFileBytes = 8;
constexpr std::uint64_t kMaxBricksRead = 64;
constexpr std::uint64_t kMaxFuzzBrickBytes = 8u << 20;

std::uint64_t u64At(const Bytes& b, std::size_t at) {
    std::uint64_t v = 0;
    if (at + 8 <= b.size()) std::memcpy(&v, b.data() + at, 8);
    return v;
}

std::uint32_t u32At(const Bytes& b, std::size_t at) {
    std::uint32_t v = 0;
    if (at + 4 <= b.size()) std::memcpy(&v, b.data() + at, 4);
    return v;
}

void setU64(Bytes& b, std::size_t at, std::uint64_t v) {
    if (at + 8 <= b.size()) std::memcpy(b.data() + at, &v, 8);
}

bool inside(const Bytes& b, std::uint64_t offset, std::uint64_t bytes) {
    return offset <= b.size() && bytes <= b.size() - offset;
}

std::uint64_t sum(const Bytes& b, std::uint64_t offset, std::uint64_t bytes) {
    return detail::checksum(b.data() + offset, std::size_t(bytes));
}

/// Recomputes the checksums (and file size) `fix` names, where the fields locating them lie
/// inside the file (offsets of FORMAT.md).
void repair(Bytes& store, std::uint8_t fix) {
    if (store.size() < detail::kHeaderBytes) return;
    const std::uint64_t indexOffset = u64At(store, 136), indexBytes = u64At(store, 144);
    const bool indexInside = inside(store, indexOffset, indexBytes);
    if ((fix & kFixBricks) && indexInside) {
        const std::uint64_t first =
            indexOffset + std::uint64_t(u32At(store, 56)) * detail::kLevelEntryBytes;
        const std::uint64_t count = u64At(store, 168);
        for (std::uint64_t i = 0; i < count && i < 4096; ++i) {
            const std::uint64_t at = first + i * detail::kRecordBytes;
            if (!inside(store, at, detail::kRecordBytes) ||
                at + detail::kRecordBytes > indexOffset + indexBytes)
                break;
            const std::uint64_t offset = u64At(store, at), frame = u32At(store, at + 8),
                                leaf = u32At(store, at + 12);
            if (!(u32At(store, at + 16) & kBrickStored)) continue;
            if (inside(store, offset, frame)) setU64(store, at + 32, sum(store, offset, frame));
            if (offset <= store.size() && inside(store, offset + frame, leaf))
                setU64(store, at + 40, sum(store, offset + frame, leaf));
        }
    }
    if ((fix & kFixIndex) && indexInside) setU64(store, 152, sum(store, indexOffset, indexBytes));
    if (fix & kFixFileBytes) setU64(store, 160, store.size());
    if (fix & kFixHeader)
        setU64(store, detail::kHeaderBytes - 8, sum(store, 0, detail::kHeaderBytes - 8));
}

void exercise(const BrickStore& store) {
    const StoreLayout& layout = store.layout();
    const std::uint64_t bricks = std::min(layout.brickCount(), kMaxBricksRead);
    const bool readVoxels = store.brickBytes() <= kMaxFuzzBrickBytes;
    std::vector<std::byte> buffer(readVoxels ? store.brickBytes() : 0);
    bool allClean = true;
    for (std::uint64_t i = 0; i < bricks; ++i) {
        const BrickKey key = layout.keyOf(i);
        require(layout.contains(key) && layout.indexOf(key) == i, "keyOf and indexOf disagree");
        const bool stored = store.record(key).stored();
        try {
            require(store.leafRanges(key).size() == layout.leafCount(),
                    "leafRanges is not leafCount entries");
            if (readVoxels) store.readBrick(key, buffer);
        } catch (const StoreCorrupt&) {
            require(stored, "a brick that is not stored failed to read");
            allClean = false;
        }
    }
    if (!readVoxels || layout.brickCount() > kMaxBricksRead) return;
    // verify() also compares value ranges with the voxels: it may find more, never less.
    if (store.verify(1).empty()) require(allClean, "verify() passed a store whose bricks fail");
}

/// A volume held in memory (a crop of a real scan), as a slice stream.
class MemoryVolume final : public VolumeSource {
  public:
    MemoryVolume(VolumeInfo info, Bytes voxels)
        : mInfo(std::move(info)), mVoxels(std::move(voxels)) {}
    const VolumeInfo& info() const override { return mInfo; }

  private:
    void readNextSlices(std::uint64_t count, std::span<std::byte> out) override {
        std::memcpy(out.data(), mVoxels.data() + nextSlice() * mInfo.sliceBytes(), out.size());
    }
    VolumeInfo mInfo;
    Bytes mVoxels;
};

void writeStoreSeed(const std::string& seeds, const std::string& name, VolumeSource& source) {
    IngestConfig config;
    config.geometry = {8, 1, 4};
    config.threads = 1;
    config.histogramBins = 16;
    const auto path = fuzz::scratchDir() / "seed.bcs";
    ingest(source, path.string(), config);
    Bytes bytes = {kFixHeader | kFixIndex | kFixBricks | kFixFileBytes};
    const Bytes store = fuzz::readFile(path);
    bytes.insert(bytes.end(), store.begin(), store.end());
    fuzz::writeSeed(seeds, name, bytes);
}

void writeScanSeed(const std::string& seeds, const std::string& file, std::size_t x, std::size_t y,
                   VoxelType type) {
    const std::size_t bytes = voxelBytes(type), edge = 12, slices = 10;
    const Bytes whole = fuzz::readPrefix(fuzz::sharedData() + "/" + file, x * y * bytes * slices);
    VolumeInfo info;
    info.dims = {edge, edge, slices};
    info.type = type;
    info.description = "crop of " + file;
    Bytes voxels = fuzz::cropVoxels(whole, 0, x, y, bytes, edge, edge, slices);
    if (voxels.empty()) return;
    MemoryVolume volume(info, std::move(voxels));
    writeStoreSeed(seeds, file, volume);
}

void writeSeeds(const std::string& seeds) {
    auto phantom = makeSynthetic(SynthKind::Phantom, {20, 20, 20}, 1);
    writeStoreSeed(seeds, "phantom", *phantom);
    auto vessels = makeSynthetic(SynthKind::Vessels, {24, 16, 12}, 2);
    writeStoreSeed(seeds, "vessels", *vessels);
    if (fuzz::sharedData().empty()) return;
    writeScanSeed(seeds, "vtk_headsq_quarter_64x64x93_uint16.raw", 64, 64, VoxelType::U16);
    writeScanSeed(seeds, "hydrogen_64x64x64_float32.raw", 64, 64, VoxelType::F32);
}

} // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    if (size == 0) return 0;
    Bytes store(data + 1, data + size);
    repair(store, data[0]);
    const std::string path = (fuzz::scratchDir() / "store.bcs").string();
    fuzz::writeFile(path, store);
    std::unique_ptr<BrickStore> opened;
    try {
        opened = BrickStore::open(path);
    } catch (const StoreCorrupt&) {
        return 0;
    } catch (const StoreIoError&) {
        return 0;
    }
    exercise(*opened);
    return 0;
}

extern "C" int LLVMFuzzerInitialize(int*, char***) {
    if (const std::string seeds = fuzz::envFolder("BC_FUZZ_SEED_DIR"); !seeds.empty())
        writeSeeds(seeds);
    return 0;
}
