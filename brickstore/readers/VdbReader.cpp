// One scalar grid of an OpenVDB file as a dense f32 slice stream over its active bounding box.
// The sparse tree stays as OpenVDB loaded it (leaf buffers on demand); each readSlices call
// paints only the leaves and active tiles that cross the requested slab, so the dense volume
// never exists in memory.
//
// All of that runs in the parser sandbox (readers/detail/SandboxedSource.h), because
// OpenVDB's own security notes say its parser may hang or exhaust memory on a hostile file:
// a truncated gaffer_smoke.vdb took 5-6 GB and 6-14 s before failing. OpenVDB and TBB are
// initialized in the child only, never in the parent.
#include "brickstore/Error.h"
#include "brickstore/Readers.h"
#include "brickstore/readers/detail/SandboxedSource.h"

#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <mutex>
#include <vector>

namespace bc::brickstore {
namespace {

void initializeOpenVdb() {
    static std::once_flag once;
    std::call_once(once, [] { openvdb::initialize(); });
}

bool isScalarGrid(const openvdb::GridBase& grid) {
    return grid.isType<openvdb::FloatGrid>() || grid.isType<openvdb::DoubleGrid>();
}

std::string coordText(const openvdb::Coord& ijk) {
    return "(" + std::to_string(ijk.x()) + "," + std::to_string(ijk.y()) + "," +
           std::to_string(ijk.z()) + ")";
}

/// "the file holds: density (float), v (vec3s)", for errors that must say what exists.
std::string gridList(const openvdb::GridPtrVec& grids) {
    if (grids.empty()) return "the file holds no grids";
    std::string text = "the file holds:";
    for (std::size_t i = 0; i < grids.size(); ++i)
        text += (i ? ", \"" : " \"") + grids[i]->getName() + "\" (" + grids[i]->valueType() + ")";
    return text;
}

/// The name of the grid to read: `wanted`, or the first scalar grid when `wanted` is empty.
std::string chooseGrid(const std::string& path, const openvdb::GridPtrVec& grids,
                       const std::string& wanted) {
    for (const auto& grid : grids) {
        if (wanted.empty() && isScalarGrid(*grid)) return grid->getName();
        if (wanted.empty() || grid->getName() != wanted) continue;
        if (!isScalarGrid(*grid))
            throw FormatError(path, "grid",
                              "grid \"" + wanted + "\" holds " + grid->valueType() +
                                  " values, not a float or double scalar; " + gridList(grids));
        return wanted;
    }
    if (wanted.empty())
        throw FormatError(path, "grid", "no float or double scalar grid; " + gridList(grids));
    throw FormatError(path, "grid", "no grid named \"" + wanted + "\"; " + gridList(grids));
}

/// Reads the chosen grid (metadata first, so that a missing or vector grid costs no tree).
openvdb::GridBase::Ptr readChosenGrid(const std::string& path, const std::string& gridName) {
    try {
        openvdb::io::File file(path);
        file.open();
        openvdb::GridPtrVecPtr grids = file.readAllGridMetadata();
        openvdb::GridBase::Ptr grid = file.readGrid(chooseGrid(path, *grids, gridName));
        file.close();
        return grid;
    } catch (const openvdb::Exception& e) {
        // OpenVDB's message can be huge (1.6 GB of spaces was seen): keep its start only.
        throw FormatError(path, "file",
                          "OpenVDB cannot read it (damaged or truncated?): " +
                              std::string(e.what(), ::strnlen(e.what(), 300)));
    }
}

void storeFloat(std::byte* out, std::uint64_t index, float value) {
    std::memcpy(out + index * sizeof(float), &value, sizeof(float));
}

template <typename GridT> class VdbVolume final : public VolumeSource {
  public:
    using TreeT = typename GridT::TreeType;
    using LeafT = typename TreeT::LeafNodeType;

    VdbVolume(const std::string& path, typename GridT::Ptr grid)
        : mPath(path), mGrid(std::move(grid)) {
        describe();
        collectLeaves();
        collectActiveTiles();
    }

    const VolumeInfo& info() const override { return mInfo; }

  private:
    void readNextSlices(std::uint64_t count, std::span<std::byte> out) override {
        if (count == 0) return;
        fillBackground(out);
        const int z0 = mBox.min().z() + static_cast<int>(nextSlice());
        const int z1 = z0 + static_cast<int>(count); // exclusive
        auto first =
            std::lower_bound(mLeaves.begin(), mLeaves.end(), z0 - int(LeafT::DIM) + 1,
                             [](const LeafT* leaf, int z) { return leaf->origin().z() < z; });
        for (auto it = first; it != mLeaves.end() && (*it)->origin().z() < z1; ++it)
            paintLeaf(**it, z0, z1, out.data());
        for (const ActiveTile& tile : mTiles)
            paintTile(tile, z0, z1, out.data());
    }

    struct ActiveTile {
        openvdb::CoordBBox box;
        float value;
    };

    void describe() {
        const std::string file = std::filesystem::path(mPath).filename().string();
        const openvdb::math::Transform& xform = mGrid->transform();
        if (!xform.isLinear())
            throw FormatError(mPath, "transform",
                              "grid \"" + mGrid->getName() + "\" has a non-linear (" +
                                  xform.mapType() + ") transform; only linear ones are supported");
        const openvdb::Vec3d voxel = xform.voxelSize();
        for (int a = 0; a < 3; ++a)
            if (!std::isfinite(voxel[a]) || voxel[a] <= 0.0)
                throw FormatError(mPath, "transform",
                                  "voxel size " + std::to_string(voxel[a]) + " along axis " +
                                      std::to_string(a) + " is not finite and positive");
        mBox = mGrid->evalActiveVoxelBoundingBox();
        if (mBox.empty())
            throw FormatError(mPath, "grid",
                              "grid \"" + mGrid->getName() + "\" has no active voxels");
        mBackground = toFloat(mGrid->background());
        if (!std::isfinite(mBackground))
            throw FormatError(mPath, "background", "background value is not finite");
        const openvdb::Coord dim = mBox.dim();
        const openvdb::Vec3d origin = mGrid->indexToWorld(mBox.min());
        for (int a = 0; a < 3; ++a) {
            mInfo.dims[a] = static_cast<std::uint64_t>(dim[a]);
            mInfo.spacingMm[a] = voxel[a];
            mInfo.originMm[a] = origin[a];
        }
        mInfo.type = VoxelType::F32;
        mInfo.background = mBackground;
        const bool half = mGrid->saveFloatAsHalf();
        mInfo.description = "OpenVDB " + file + " grid \"" + mGrid->getName() + "\" (" +
                            mGrid->valueType() + (half ? ", half on disk" : "") + "), f32";
        validateVolumeInfo(mInfo, mPath);
    }

    void collectLeaves() {
        mLeaves.reserve(mGrid->tree().leafCount());
        for (auto it = mGrid->tree().cbeginLeaf(); it; ++it)
            mLeaves.push_back(it.getLeaf());
        std::sort(mLeaves.begin(), mLeaves.end(),
                  [](const LeafT* a, const LeafT* b) { return a->origin().z() < b->origin().z(); });
    }

    /// Active tiles above the leaf level: a uniform active region with no leaf under it.
    void collectActiveTiles() {
        auto it = mGrid->tree().cbeginValueOn();
        it.setMaxDepth(TreeT::ValueOnCIter::LEAF_DEPTH - 1);
        for (; it; ++it) {
            if (!it.isTileValue()) continue;
            ActiveTile tile;
            it.getBoundingBox(tile.box);
            tile.value = checkedValue(*it, tile.box.min());
            mTiles.push_back(tile);
        }
    }

    float toFloat(double value) const { return static_cast<float>(value); }

    float checkedValue(typename GridT::ValueType value, const openvdb::Coord& ijk) const {
        const float f = toFloat(value);
        if (!std::isfinite(f))
            throw FormatError(mPath, "value",
                              "value " + std::to_string(value) + " at active voxel " +
                                  coordText(ijk) + " is not a finite f32");
        return f;
    }

    void fillBackground(std::span<std::byte> out) const {
        const std::uint64_t voxels = out.size() / sizeof(float);
        if (mBackground == 0.0f && !std::signbit(mBackground)) {
            std::memset(out.data(), 0, out.size());
            return;
        }
        storeFloat(out.data(), 0, mBackground);
        for (std::uint64_t done = 1; done < voxels; done *= 2)
            std::memcpy(out.data() + done * sizeof(float), out.data(),
                        std::min(done, voxels - done) * sizeof(float));
    }

    std::uint64_t outIndex(int x, int y, int z, int z0) const {
        const std::uint64_t dx = mInfo.dims[0], dy = mInfo.dims[1];
        return (std::uint64_t(z - z0) * dy + std::uint64_t(y - mBox.min().y())) * dx +
               std::uint64_t(x - mBox.min().x());
    }

    void paintLeaf(const LeafT& leaf, int z0, int z1, std::byte* out) const {
        const openvdb::Coord o = leaf.origin();
        const int lzBegin = std::max(z0 - o.z(), 0), lzEnd = std::min(z1 - o.z(), int(LeafT::DIM));
        for (int lx = 0; lx < int(LeafT::DIM); ++lx) {
            for (int ly = 0; ly < int(LeafT::DIM); ++ly) {
                for (int lz = lzBegin; lz < lzEnd; ++lz) {
                    const openvdb::Index offset = LeafT::coordToOffset(openvdb::Coord(lx, ly, lz));
                    if (!leaf.isValueOn(offset)) continue;
                    const openvdb::Coord ijk = o + openvdb::Coord(lx, ly, lz);
                    if (!mBox.isInside(ijk))
                        continue; // cannot happen for an active voxel; cheap guard
                    storeFloat(out, outIndex(ijk.x(), ijk.y(), ijk.z(), z0),
                               checkedValue(leaf.getValue(offset), ijk));
                }
            }
        }
    }

    void paintTile(const ActiveTile& tile, int z0, int z1, std::byte* out) const {
        openvdb::CoordBBox box = tile.box;
        box.intersect(openvdb::CoordBBox(openvdb::Coord(mBox.min().x(), mBox.min().y(), z0),
                                         openvdb::Coord(mBox.max().x(), mBox.max().y(), z1 - 1)));
        if (box.empty()) return;
        for (int z = box.min().z(); z <= box.max().z(); ++z)
            for (int y = box.min().y(); y <= box.max().y(); ++y)
                for (int x = box.min().x(); x <= box.max().x(); ++x)
                    storeFloat(out, outIndex(x, y, z, z0), tile.value);
    }

    std::string mPath;
    typename GridT::Ptr mGrid;
    VolumeInfo mInfo;
    openvdb::CoordBBox mBox;
    float mBackground = 0.0f;
    std::vector<const LeafT*> mLeaves; ///< sorted by origin z, for slab look-ups
    std::vector<ActiveTile> mTiles;
};

std::unique_ptr<VolumeSource> openInProcess(const std::string& path, const std::string& gridName) {
    initializeOpenVdb();
    openvdb::GridBase::Ptr grid = readChosenGrid(path, gridName);
    if (auto floatGrid = openvdb::gridPtrCast<openvdb::FloatGrid>(grid))
        return std::make_unique<VdbVolume<openvdb::FloatGrid>>(path, floatGrid);
    if (auto doubleGrid = openvdb::gridPtrCast<openvdb::DoubleGrid>(grid))
        return std::make_unique<VdbVolume<openvdb::DoubleGrid>>(path, doubleGrid);
    throw FormatError(path, "grid",
                      "grid \"" + grid->getName() + "\" is not a float or double scalar grid");
}

} // namespace

std::unique_ptr<VolumeSource> openVdb(const std::string& path, const std::string& gridName) {
    return detail::openSandboxed(
        {path, "OpenVDB", "to parse", {}}, parserSandboxLimits(),
        [path, gridName](const detail::ReadingFile&) { return openInProcess(path, gridName); });
}

} // namespace bc::brickstore
