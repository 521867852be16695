// One scalar grid of an OpenVDB file as a dense f32 slice stream over its active bounding box.
// The sparse tree stays as OpenVDB loaded it (leaf buffers on demand); each readSlices call
// paints only the leaves and active tiles that cross the requested slab, so the dense volume
// never exists in memory.
//
// All of that runs in a child process (fork), because OpenVDB's own security notes say its
// parser may hang or exhaust memory on a hostile file: a truncated gaffer_smoke.vdb took
// 5-6 GB and 6-14 s before failing. The child lowers RLIMIT_AS and RLIMIT_CPU, arms an alarm
// for the parse, and streams the volume's description and then its slabs over a pipe; the
// parent (SandboxedVdb) is the VolumeSource ingest sees. Why fork is safe here: the child only
// runs code that the parent never started (OpenVDB and TBB are initialized in the child, never
// in the parent), glibc resets its malloc locks across fork, and openVdb is called before
// ingest starts its workers; the child leaves with _exit, running no parent destructors.
#include "brickstore/Error.h"
#include "brickstore/Readers.h"

#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <climits>
#include <cmath>
#include <csignal>
#include <cstring>
#include <filesystem>
#include <mutex>
#include <new>
#include <vector>

#include <fcntl.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

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

// ---- the sandbox: child and pipe --------------------------------------------------------------

/// Messages on the pipe, child to parent: 'I' info, then 'S' slab (u64 slices, bytes) ...;
/// 'E' (field, why) ends the stream with an error. Integers in host order (same machine).
constexpr char kInfo = 'I', kSlab = 'S', kError = 'E';
constexpr std::size_t kMaxErrorText = 400; ///< per string: the parent's error stays < 1 kB
constexpr std::uint64_t kSlabBytes = 64ull << 20;

std::atomic<std::uint64_t> gAddressSpaceBytes{VdbSandboxLimits{}.addressSpaceBytes};
std::atomic<std::uint32_t> gParseSeconds{VdbSandboxLimits{}.parseSeconds};
std::atomic<std::uint32_t> gCpuSeconds{VdbSandboxLimits{}.cpuSeconds};

constexpr std::size_t kMaxDescriptionText = 4096; ///< as a store's description

std::string clip(const std::string& text, std::size_t maxBytes = kMaxErrorText) {
    return text.size() <= maxBytes ? text : text.substr(0, maxBytes) + "...";
}

/// The child's side: blocking writes; a parent gone (EPIPE) ends the child.
class ChildWriter {
  public:
    explicit ChildWriter(int fd) : mFd(fd) {}
    void bytes(const void* data, std::size_t n) {
        const auto* p = static_cast<const char*>(data);
        while (n > 0) {
            const ssize_t w = ::write(mFd, p, n);
            if (w < 0 && errno == EINTR) continue;
            if (w <= 0) ::_exit(3);
            p += w;
            n -= std::size_t(w);
        }
    }
    template <class T> void value(T v) { bytes(&v, sizeof v); }
    void text(const std::string& s, std::size_t maxBytes = kMaxErrorText) {
        const std::string c = clip(s, maxBytes);
        value(std::uint32_t(c.size()));
        bytes(c.data(), c.size());
    }

  private:
    int mFd;
};

void sendInfo(ChildWriter& w, const VolumeInfo& i) {
    w.value(kInfo);
    for (int a = 0; a < 3; ++a)
        w.value(i.dims[a]);
    w.value(std::uint8_t(i.type));
    for (int a = 0; a < 3; ++a)
        w.value(i.spacingMm[a]);
    for (int a = 0; a < 3; ++a)
        w.value(i.originMm[a]);
    w.value(i.background);
    w.value(i.valueScale);
    w.value(i.valueOffset);
    w.text(i.description, kMaxDescriptionText);
}

/// Runs in the child: limits, parse, stream. Never returns.
[[noreturn]] void childMain(int fd, const std::string& path, const std::string& gridName,
                            std::uint64_t addressSpaceBytes, std::uint32_t parseSeconds,
                            std::uint32_t cpuSeconds) {
    const rlimit as{addressSpaceBytes, addressSpaceBytes};
    const rlimit cpu{cpuSeconds, cpuSeconds + 1};
    ::setrlimit(RLIMIT_AS, &as);
    ::setrlimit(RLIMIT_CPU, &cpu);
    ::signal(SIGALRM, SIG_DFL);
    ::signal(SIGXCPU, SIG_DFL);
    sigset_t limitSignals;
    sigemptyset(&limitSignals);
    sigaddset(&limitSignals, SIGALRM);
    sigaddset(&limitSignals, SIGXCPU);
    ::sigprocmask(SIG_UNBLOCK, &limitSignals, nullptr); // a parent's mask is inherited
    ::alarm(parseSeconds);
    ChildWriter w(fd);
    try {
        auto source = openInProcess(path, gridName);
        ::alarm(0); // parsed: from here the parent's pace sets the time, RLIMIT_CPU the bound
        const VolumeInfo& info = source->info();
        sendInfo(w, info);
        const std::uint64_t sliceBytes = info.sliceBytes();
        const std::uint64_t perSlab = std::max<std::uint64_t>(1, kSlabBytes / sliceBytes);
        std::vector<std::byte> slab;
        for (std::uint64_t z = 0; z < info.dims[2];) {
            const std::uint64_t n = std::min(perSlab, info.dims[2] - z);
            slab.resize(n * sliceBytes);
            source->readSlices(n, slab);
            w.value(kSlab);
            w.value(n);
            w.bytes(slab.data(), slab.size());
            z += n;
        }
        ::_exit(0);
    } catch (const FormatError& e) {
        // what() is "FILE: FIELD: why"; only the why crosses, bounded (never copied whole).
        const char* what = e.what();
        const std::size_t prefix = e.file().size() + e.field().size() + 4;
        const std::size_t skip = ::strnlen(what, prefix);
        w.value(kError);
        w.text(e.field());
        w.text(std::string(what + skip, ::strnlen(what + skip, kMaxErrorText + 1)));
    } catch (const std::bad_alloc&) {
        w.value(kError);
        w.text("file");
        w.text("out of memory under the parser's " + std::to_string(addressSpaceBytes >> 20) +
               " MiB address-space limit (a damaged or hostile file?)");
    } catch (const std::exception& e) {
        w.value(kError);
        w.text("file");
        w.text(std::string("OpenVDB cannot read it: ") +
               std::string(e.what(), ::strnlen(e.what(), kMaxErrorText)));
    }
    ::_exit(2);
}

/// The parent's side: the VolumeSource ingest reads, fed by the child.
class SandboxedVdb final : public VolumeSource {
  public:
    SandboxedVdb(const std::string& path, const std::string& gridName) : mPath(path) {
        mLimitText = std::to_string(gAddressSpaceBytes.load() >> 20) + " MiB, " +
                     std::to_string(gParseSeconds.load()) + " s to parse";
        int fds[2];
        if (::pipe2(fds, O_CLOEXEC) != 0)
            throw FormatError(path, "file",
                              std::string("cannot create a pipe: ") + std::strerror(errno));
        const std::uint64_t as = gAddressSpaceBytes.load();
        const std::uint32_t parse = gParseSeconds.load(), cpu = gCpuSeconds.load();
        mPid = ::fork();
        if (mPid < 0) {
            ::close(fds[0]);
            ::close(fds[1]);
            throw FormatError(path, "file",
                              std::string("cannot fork the parser: ") + std::strerror(errno));
        }
        if (mPid == 0) {
            ::close(fds[0]);
            childMain(fds[1], path, gridName, as, parse, cpu);
        }
        ::close(fds[1]);
        mFd = fds[0];
        readInfo();
    }
    ~SandboxedVdb() override {
        if (mFd >= 0) ::close(mFd);
        reap(true);
    }
    const VolumeInfo& info() const override { return mInfo; }

  private:
    void readNextSlices(std::uint64_t count, std::span<std::byte> out) override {
        const std::uint64_t sliceBytes = mInfo.sliceBytes();
        std::uint64_t done = 0;
        while (done < count) {
            if (mPendingSlices == 0) nextSlab();
            const std::uint64_t n = std::min(count - done, mPendingSlices);
            read(out.data() + done * sliceBytes, n * sliceBytes);
            mPendingSlices -= n;
            done += n;
        }
    }

    void readInfo() {
        expectTag(kInfo);
        for (int a = 0; a < 3; ++a)
            mInfo.dims[a] = value<std::uint64_t>();
        const auto type = value<std::uint8_t>();
        if (type != std::uint8_t(VoxelType::F32)) fail("the parser sent an unknown voxel type");
        mInfo.type = VoxelType::F32;
        for (int a = 0; a < 3; ++a)
            mInfo.spacingMm[a] = value<double>();
        for (int a = 0; a < 3; ++a)
            mInfo.originMm[a] = value<double>();
        mInfo.background = value<double>();
        mInfo.valueScale = value<double>();
        mInfo.valueOffset = value<double>();
        mInfo.description = text();
        validateVolumeInfo(mInfo, mPath);
    }

    void nextSlab() {
        expectTag(kSlab);
        const auto n = value<std::uint64_t>();
        if (n == 0 || n > mInfo.dims[2] - nextSlice())
            fail("the parser sent a slab of " + std::to_string(n) + " slices");
        mPendingSlices = n;
    }

    /// Reads the next tag; an 'E' from the child becomes its FormatError.
    void expectTag(char want) {
        const char tag = value<char>();
        if (tag == want) return;
        if (tag == kError) {
            const std::string field = text(), why = text();
            reap(false);
            throw FormatError(mPath, field.empty() ? "file" : field,
                              why + " [sandboxed parser: " + mLimitText + "]");
        }
        fail("the parser sent an unexpected message");
    }

    template <class T> T value() {
        T v{};
        read(&v, sizeof v);
        return v;
    }
    std::string text() {
        const auto n = value<std::uint32_t>();
        if (n > kMaxDescriptionText + 3) fail("the parser sent a text too long");
        std::string s(n, '\0');
        read(s.data(), n);
        return s;
    }

    void read(void* data, std::size_t n) {
        auto* p = static_cast<char*>(data);
        while (n > 0) {
            const ssize_t r = ::read(mFd, p, n);
            if (r < 0 && errno == EINTR) continue;
            if (r <= 0) fail(childEnd());
            p += r;
            n -= std::size_t(r);
        }
    }

    /// Why the stream ended early: how the child ended (waited for).
    std::string childEnd() {
        const int status = reap(false);
        if (WIFSIGNALED(status)) {
            const int sig = WTERMSIG(status);
            if (sig == SIGALRM)
                return "the parser took longer than its time limit (" + mLimitText + ")";
            if (sig == SIGXCPU) return "the parser used more than its CPU-time limit";
            if (sig == SIGKILL) return "the parser was killed (SIGKILL; out of memory?)";
            return std::string("the parser crashed: ") + ::strsignal(sig) + " (limits " +
                   mLimitText + ")";
        }
        if (WIFEXITED(status))
            return "the parser ended early with status " + std::to_string(WEXITSTATUS(status));
        return "the parser ended early";
    }

    [[noreturn]] void fail(const std::string& why) {
        throw FormatError(mPath, "file", "sandboxed OpenVDB parser: " + clip(why));
    }

    /// Waits for the child (killing it first when `kill`); its wait status, once.
    int reap(bool kill) {
        if (mPid <= 0) return mStatus;
        if (kill) ::kill(mPid, SIGKILL);
        while (::waitpid(mPid, &mStatus, 0) < 0 && errno == EINTR) {
        }
        mPid = -1;
        return mStatus;
    }

    std::string mPath, mLimitText;
    VolumeInfo mInfo;
    pid_t mPid = -1;
    int mFd = -1, mStatus = 0;
    std::uint64_t mPendingSlices = 0;
};

} // namespace

std::unique_ptr<VolumeSource> openVdb(const std::string& path, const std::string& gridName) {
    return std::make_unique<SandboxedVdb>(path, gridName);
}

void setVdbSandboxLimits(const VdbSandboxLimits& limits) {
    gAddressSpaceBytes = limits.addressSpaceBytes;
    gParseSeconds = limits.parseSeconds;
    gCpuSeconds = limits.cpuSeconds;
}

VdbSandboxLimits vdbSandboxLimits() {
    return {gAddressSpaceBytes.load(), gParseSeconds.load(), gCpuSeconds.load()};
}

} // namespace bc::brickstore
