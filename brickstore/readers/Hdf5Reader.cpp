// A named 3D dataset of an HDF5 file (C order [z][y][x], x fastest) as a slice stream. Each
// readSlices step is one H5Dread of a hyperslab of z-slices straight into the caller's buffer;
// libhdf5 converts byte order (and widens i8 and f16) on the way. Contiguous, compact and
// chunked layouts; the filters of a chunked dataset must be available (a missing plugin, blosc
// or zstd say, is named before anything is read).
//
// Memory: a chunked dataset gets a chunk cache sized to one z-row of chunks (every chunk that
// a z-range of one chunk's depth touches), at most kMaxChunkCacheBytes, so a chunk cut by the
// boundary between two readSlices calls is decoded once; one chunk is at most kMaxChunkBytes.
// With a chunk being decoded and the sandbox's 64 MiB slab, the child holds under 1 GB for a
// well-formed file, whatever the volume's size (the sandbox's address-space limit bounds the
// rest).
//
// Every name inside the file stays inside it: external links are not followed, and datasets
// whose voxels live in other files (external storage, virtual datasets) are refused. libhdf5
// has a long record of crashes on hostile files, so all of it runs in the parser sandbox
// (readers/detail/SandboxedSource.h); the parent never initializes the library.
#include "brickstore/Error.h"
#include "brickstore/Readers.h"
#include "brickstore/readers/detail/Hdf5Library.h"
#include "brickstore/readers/detail/SandboxedSource.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <vector>

namespace bc::brickstore {
namespace {

using detail::h5Check;
using detail::H5Id;

constexpr std::uint64_t kMaxChunkCacheBytes = 256ull << 20;
constexpr std::uint64_t kMaxChunkBytes = 256ull << 20;
/// Slots of the chunk cache's hash table (8 bytes each).
constexpr std::uint64_t kMaxChunkCacheSlots = 1ull << 20;
constexpr const char* kSpacingAttribute = "element_size_um";

/// A dataset path as messages show it: in quotes, cut at 80 characters.
std::string quoted(const std::string& name) {
    std::string text = "\"";
    text += name.substr(0, 80);
    text += "\"";
    return text;
}

std::string fileName(const std::string& path) {
    return std::filesystem::path(path).filename().string();
}

/// libhdf5 asks this before it follows an external link; failing refuses every one.
herr_t refuseExternalLink(const char*, const char*, const char*, const char*, unsigned*, hid_t,
                          void*) {
    return -1;
}

H5Id openFile(const std::string& path) {
    const htri_t isHdf5 = H5Fis_hdf5(path.c_str());
    if (isHdf5 == 0)
        throw FormatError(path, "file",
                          "not an HDF5 file: no HDF5 signature (\\x89HDF\\r\\n\\x1a\\n) at offset "
                          "0, 512, 1024 or any power of two after");
    h5Check(isHdf5, path, "file", "cannot read it");
    H5Id access(h5Check(H5Pcreate(H5P_FILE_ACCESS), path, "file", "H5Pcreate"), H5Pclose);
    // Reading takes no lock: file locks fail on some network file systems, and nothing is
    // written.
    h5Check(H5Pset_file_locking(access.get(), false, true), path, "file", "H5Pset_file_locking");
    return H5Id(h5Check(H5Fopen(path.c_str(), H5F_ACC_RDONLY, access.get()), path, "file",
                        "cannot open it (damaged or truncated?)"),
                H5Fclose);
}

/// "/entry/data/volume" from "entry/data/volume" or "/entry//data/volume/".
std::vector<std::string> pathComponents(const std::string& name) {
    std::vector<std::string> parts;
    for (std::size_t i = 0; i < name.size();) {
        const std::size_t end = std::min(name.find('/', i), name.size());
        if (end > i) parts.push_back(name.substr(i, end - i));
        i = end + 1;
    }
    return parts;
}

/// Checks that `wanted` names a dataset reached through this file's own links only and
/// returns its absolute path. @throw FormatError("dataset") listing the file's volumes.
std::string findDataset(hid_t file, hid_t linkAccess, const std::string& path,
                        const std::string& wanted) {
    const std::string hint = "; pick one of its 3D datasets with --dataset: ";
    if (wanted.empty())
        throw FormatError(path, "dataset", "no dataset given" + hint + detail::volumeList(file));
    const std::string shown = quoted(wanted);
    std::string name;
    for (const std::string& part : pathComponents(wanted)) {
        name += "/" + part;
        if (H5Lexists(file, name.c_str(), linkAccess) <= 0) {
            detail::hdf5ErrorText(); // clears what a missing parent group left on the stack
            throw FormatError(path, "dataset",
                              "no dataset " + shown + hint + detail::volumeList(file));
        }
        H5L_info_t link{};
        h5Check(H5Lget_info(file, name.c_str(), &link, linkAccess), path, "dataset",
                "cannot read the link " + name.substr(0, 80));
        if (link.type == H5L_TYPE_EXTERNAL)
            throw FormatError(path, "dataset",
                              "\"" + name.substr(0, 80) +
                                  "\" is an external link to another file; only the file's own "
                                  "objects are read");
        if (link.type != H5L_TYPE_HARD && link.type != H5L_TYPE_SOFT)
            throw FormatError(path, "dataset",
                              "\"" + name.substr(0, 80) + "\" is a user-defined link");
    }
    H5O_info_t object{};
    h5Check(H5Oget_info_by_name2(file, name.empty() ? "/" : name.c_str(), &object, H5O_INFO_BASIC,
                                 linkAccess),
            path, "dataset", "cannot read the object " + shown);
    if (object.type != H5O_TYPE_DATASET)
        throw FormatError(path, "dataset",
                          shown + " is a group, not a dataset" + hint + detail::volumeList(file));
    return name;
}

/// Dims (x, y, z) and voxel type of the dataset, checked.
VolumeInfo shapeOf(hid_t dataset, hid_t type, const std::string& path, const std::string& name) {
    H5Id space(h5Check(H5Dget_space(dataset), path, "dataspace", "H5Dget_space"), H5Sclose);
    const int rank = H5Sget_simple_extent_ndims(space.get());
    std::array<hsize_t, H5S_MAX_RANK> dims{};
    if (H5Sget_simple_extent_type(space.get()) != H5S_SIMPLE || rank < 0 || rank > H5S_MAX_RANK)
        throw FormatError(path, "dataspace",
                          "\"" + name + "\" has a scalar or null dataspace, not rank 3");
    h5Check(H5Sget_simple_extent_dims(space.get(), dims.data(), nullptr), path, "dataspace",
            "H5Sget_simple_extent_dims");
    if (rank != 3) {
        std::string shape;
        for (int i = 0; i < rank; ++i)
            shape.append(i ? "x" : "").append(std::to_string(dims[std::size_t(i)]));
        throw FormatError(path, "dataspace",
                          "\"" + name + "\" has rank " + std::to_string(rank) + " (shape " + shape +
                              "); a volume is rank 3, [z][y][x]");
    }
    const std::optional<VoxelType> voxel = detail::voxelTypeOf(type);
    if (!voxel)
        throw FormatError(path, "type",
                          "\"" + name + "\" holds " + detail::datatypeText(type) +
                              "; supported: u8, u16, i16, f32 in either byte order (i8 and f16 "
                              "are widened to i16 and f32)");
    VolumeInfo info;
    info.dims = {dims[2], dims[1], dims[0]};
    info.type = *voxel;
    validateVolumeInfo(info, path, "dataspace");
    return info;
}

/// The spacing in mm from element_size_um (z, y, x in micrometres, as ilastik and Fiji write
/// it); 1 mm when there is none.
std::array<double, 3> spacingOf(hid_t dataset, const std::string& path) {
    const htri_t has = h5Check(H5Aexists(dataset, kSpacingAttribute), path, kSpacingAttribute,
                               "cannot look for the attribute");
    if (has == 0) return {1, 1, 1};
    H5Id attribute(h5Check(H5Aopen(dataset, kSpacingAttribute, H5P_DEFAULT), path,
                           kSpacingAttribute, "cannot open the attribute"),
                   H5Aclose);
    H5Id space(h5Check(H5Aget_space(attribute.get()), path, kSpacingAttribute, "H5Aget_space"),
               H5Sclose);
    H5Id type(h5Check(H5Aget_type(attribute.get()), path, kSpacingAttribute, "H5Aget_type"),
              H5Tclose);
    const H5T_class_t kind = H5Tget_class(type.get());
    const hssize_t count = H5Sget_simple_extent_npoints(space.get());
    if ((kind != H5T_INTEGER && kind != H5T_FLOAT) || count != 3)
        throw FormatError(path, kSpacingAttribute,
                          "holds " + std::to_string(count) + " values of type " +
                              detail::datatypeText(type.get()) +
                              ", not 3 numbers (z, y, x in micrometres)");
    std::array<double, 3> um{};
    h5Check(H5Aread(attribute.get(), H5T_NATIVE_DOUBLE, um.data()), path, kSpacingAttribute,
            "cannot read the attribute");
    for (double v : um)
        if (!std::isfinite(v) || v <= 0)
            throw FormatError(path, kSpacingAttribute,
                              "holds " + std::to_string(v) + "; sizes must be finite and positive");
    return {um[2] / 1000, um[1] / 1000, um[0] / 1000};
}

/// How the dataset is stored, and the chunk cache its reads want (none: 0 bytes).
struct Storage {
    std::string text; ///< "chunked 64x64x8 shuffle+gzip", for the description
    std::uint64_t cacheBytes = 0;
    std::uint64_t cacheSlots = 0;
};

std::string filterText(H5Z_filter_t id, const char* name) {
    switch (id) {
    case H5Z_FILTER_DEFLATE:
        return "gzip";
    case H5Z_FILTER_SHUFFLE:
        return "shuffle";
    case H5Z_FILTER_FLETCHER32:
        return "fletcher32";
    case H5Z_FILTER_SZIP:
        return "szip";
    case H5Z_FILTER_NBIT:
        return "nbit";
    case H5Z_FILTER_SCALEOFFSET:
        return "scaleoffset";
    default:
        return std::to_string(id).append(*name ? "(" : "").append(name).append(*name ? ")" : "");
    }
}

/// The filter pipeline in words; @throw FormatError("filter") for one libhdf5 cannot decode.
std::string checkFilters(hid_t create, const std::string& path, const std::string& name) {
    const int count = h5Check(H5Pget_nfilters(create), path, "filter", "H5Pget_nfilters");
    std::string text;
    for (int i = 0; i < count; ++i) {
        unsigned flags = 0, config = 0;
        std::size_t values = 0;
        std::array<char, 64> stored{};
        const H5Z_filter_t id =
            h5Check(H5Pget_filter2(create, unsigned(i), &flags, &values, nullptr, stored.size(),
                                   stored.data(), &config),
                    path, "filter", "cannot read the filter pipeline");
        stored.back() = '\0';
        std::string label;
        for (const char* p = stored.data(); *p; ++p)
            label += (*p >= 0x20 && *p < 0x7f) ? *p : '?';
        unsigned available = 0;
        if (H5Zfilter_avail(id) <= 0 || H5Zget_filter_info(id, &available) < 0 ||
            !(available & H5Z_FILTER_CONFIG_DECODE_ENABLED)) {
            detail::hdf5ErrorText();
            throw FormatError(path, "filter",
                              "\"" + name + "\" is compressed with HDF5 filter " +
                                  std::to_string(id) + " (\"" + label +
                                  "\"), which this libhdf5 cannot decode: its plugin is not "
                                  "installed (see HDF5_PLUGIN_PATH)");
        }
        text.append(i ? "+" : " ").append(filterText(id, label.c_str()));
    }
    return text;
}

Storage checkChunks(hid_t create, const VolumeInfo& info, std::size_t typeBytes,
                    const std::string& path, const std::string& name) {
    std::array<hsize_t, 3> chunk{};
    if (H5Pget_chunk(create, 3, chunk.data()) != 3)
        throw FormatError(path, "chunks", "\"" + name + "\" has chunks of a rank other than 3");
    std::uint64_t chunkBytes = 0;
    if (!checkedVolumeBytes({chunk[2], chunk[1], chunk[0]}, typeBytes, chunkBytes) ||
        chunkBytes == 0 || chunkBytes > kMaxChunkBytes)
        throw FormatError(path, "chunks",
                          "\"" + name + "\" has chunks of " +
                              dimsText({chunk[2], chunk[1], chunk[0]}) +
                              " voxels; the reader takes chunks of 1 byte to " +
                              bytesText(double(kMaxChunkBytes)));
    checkChunkCount(info, {chunk[2], chunk[1], chunk[0]}, path, "chunks");
    Storage storage;
    storage.text =
        "chunked " + dimsText({chunk[2], chunk[1], chunk[0]}) + checkFilters(create, path, name);
    const std::uint64_t rowChunks =
        ((info.dims[1] + chunk[1] - 1) / chunk[1]) * ((info.dims[0] + chunk[2] - 1) / chunk[2]);
    const std::uint64_t held =
        std::max<std::uint64_t>(1, std::min(rowChunks, kMaxChunkCacheBytes / chunkBytes));
    storage.cacheBytes = held * chunkBytes;
    // A z-row's chunks have consecutive indices in libhdf5's hash (index mod slots), as do
    // those of the next row that a slab may start: twice as many slots as chunks held keeps
    // them from evicting each other.
    storage.cacheSlots = std::clamp<std::uint64_t>(2 * held + 1, 521, kMaxChunkCacheSlots);
    return storage;
}

/// Checks that the voxels lie in this file, inside it, in a layout the reader takes.
Storage checkStorage(hid_t dataset, hid_t create, const VolumeInfo& info, std::size_t typeBytes,
                     const std::string& path, const std::string& name) {
    const std::uint64_t fileBytes = std::filesystem::file_size(path);
    const std::uint64_t declared = info.voxelCount() * typeBytes; // < kMaxVolumeBytes: checked
    const std::uint64_t stored = H5Dget_storage_size(dataset);
    if (stored > fileBytes)
        throw FormatError(path, "storage",
                          "\"" + name + "\" claims " + bytesText(double(stored)) +
                              " of storage in a file of " + bytesText(double(fileBytes)));
    // Chunks never written, or contiguous data never allocated, read as the fill value: a
    // header of a kilobyte can declare a terabyte of them.
    checkInputHolds(info, stored, "the chunks and data stored for " + quoted(name), path,
                    "storage");
    switch (H5Pget_layout(create)) {
    case H5D_CHUNKED:
        return checkChunks(create, info, typeBytes, path, name);
    case H5D_COMPACT:
        if (stored != declared)
            throw FormatError(path, "storage",
                              "\"" + name + "\" is compact with " + std::to_string(stored) +
                                  " bytes, not the " + std::to_string(declared) +
                                  " its dataspace needs");
        return {"compact", 0, 0};
    case H5D_CONTIGUOUS:
        break;
    case H5D_VIRTUAL:
        throw FormatError(path, "layout",
                          "\"" + name +
                              "\" is a virtual dataset (its voxels come from other "
                              "datasets or files); not supported");
    default:
        throw FormatError(path, "layout", "\"" + name + "\" has an unknown layout");
    }
    const int external =
        h5Check(H5Pget_external_count(create), path, "storage", "H5Pget_external_count");
    if (external > 0)
        throw FormatError(path, "storage",
                          "\"" + name + "\" keeps its voxels in " + std::to_string(external) +
                              " external file(s); only data inside the HDF5 file is read");
    const haddr_t offset = H5Dget_offset(dataset);
    if (offset == HADDR_UNDEF) return {"contiguous, never written (reads as its fill value)", 0, 0};
    if (stored < declared || offset > fileBytes || fileBytes - offset < declared)
        throw FormatError(path, "storage",
                          "\"" + name + "\" needs " + std::to_string(declared) +
                              " bytes at offset " + std::to_string(offset) +
                              ", past the end of the file (" + std::to_string(fileBytes) +
                              " bytes): truncated?");
    return {"contiguous", 0, 0};
}

class Hdf5Volume final : public VolumeSource {
  public:
    Hdf5Volume(const std::string& path, const std::string& name, H5Id file, H5Id dataset,
               const VolumeInfo& info)
        : mPath(path), mName(name), mFile(std::move(file)), mDataset(std::move(dataset)),
          mInfo(info) {
        mFileSpace = H5Id(h5Check(H5Dget_space(mDataset.get()), path, "dataspace", "H5Dget_space"),
                          H5Sclose);
    }

    const VolumeInfo& info() const override { return mInfo; }

  private:
    void readNextSlices(std::uint64_t count, std::span<std::byte> out) override {
        if (count == 0) return;
        const std::array<hsize_t, 3> start{nextSlice(), 0, 0},
            size{count, mInfo.dims[1], mInfo.dims[0]};
        const std::string slices = "slices " + std::to_string(nextSlice()) + ".." +
                                   std::to_string(nextSlice() + count - 1) + " of \"" + mName +
                                   "\"";
        h5Check(H5Sselect_hyperslab(mFileSpace.get(), H5S_SELECT_SET, start.data(), nullptr,
                                    size.data(), nullptr),
                mPath, "data", "cannot select " + slices);
        H5Id memory(
            h5Check(H5Screate_simple(3, size.data(), nullptr), mPath, "data", "H5Screate_simple"),
            H5Sclose);
        h5Check(H5Dread(mDataset.get(), detail::nativeTypeOf(mInfo.type), memory.get(),
                        mFileSpace.get(), H5P_DEFAULT, out.data()),
                mPath, "data", "cannot read " + slices + " (damaged or truncated?)");
        if (mInfo.type == VoxelType::F32) checkFinite(out);
    }

    /// NaN or infinity would poison every min/max and average the store keeps.
    void checkFinite(std::span<const std::byte> slab) const {
        for (std::size_t i = 0; i + 4 <= slab.size(); i += 4) {
            float v;
            std::memcpy(&v, slab.data() + i, 4);
            if (std::isfinite(v)) continue;
            const std::uint64_t voxel = i / 4, x = voxel % mInfo.dims[0],
                                y = voxel / mInfo.dims[0] % mInfo.dims[1],
                                z = nextSlice() + voxel / (mInfo.dims[0] * mInfo.dims[1]);
            throw FormatError(mPath, "data",
                              "voxel (" + std::to_string(x) + "," + std::to_string(y) + "," +
                                  std::to_string(z) + ") of \"" + mName + "\" is " +
                                  (std::isnan(v) ? "NaN" : "infinite") +
                                  "; float volumes must be finite");
        }
    }

    std::string mPath;
    std::string mName;
    H5Id mFile;
    H5Id mDataset;
    H5Id mFileSpace;
    VolumeInfo mInfo;
};

std::unique_ptr<VolumeSource> openInProcess(const std::string& path, const std::string& wanted) {
    detail::quietHdf5Errors();
    H5Id file = openFile(path);
    H5Id access(h5Check(H5Pcreate(H5P_DATASET_ACCESS), path, "dataset", "H5Pcreate"), H5Pclose);
    h5Check(H5Pset_elink_cb(access.get(), refuseExternalLink, nullptr), path, "dataset",
            "H5Pset_elink_cb");
    const std::string name = findDataset(file.get(), access.get(), path, wanted);
    H5Id dataset(h5Check(H5Dopen2(file.get(), name.c_str(), access.get()), path, "dataset",
                         "cannot open \"" + name + "\""),
                 H5Dclose);
    H5Id type(h5Check(H5Dget_type(dataset.get()), path, "type", "H5Dget_type"), H5Tclose);
    VolumeInfo info = shapeOf(dataset.get(), type.get(), path, name);
    H5Id create(h5Check(H5Dget_create_plist(dataset.get()), path, "layout", "H5Dget_create_plist"),
                H5Pclose);
    const Storage storage =
        checkStorage(dataset.get(), create.get(), info, H5Tget_size(type.get()), path, name);
    info.spacingMm = spacingOf(dataset.get(), path);
    const std::string stored = detail::datatypeText(type.get());
    const std::string as(voxelTypeName(info.type));
    info.description = "HDF5 " + fileName(path) + " " + name + ", " + stored +
                       (stored.rfind(as, 0) == 0 ? "" : " as " + as) + ", " + storage.text;
    if (storage.cacheBytes > 0) {
        // The cache is made when a dataset is first opened: close it and open it again with one
        // sized to a row (an open kept meanwhile would keep the default 1 MiB cache).
        h5Check(H5Pset_chunk_cache(access.get(), storage.cacheSlots, storage.cacheBytes, 1.0), path,
                "chunks", "H5Pset_chunk_cache");
        dataset = H5Id();
        dataset = H5Id(h5Check(H5Dopen2(file.get(), name.c_str(), access.get()), path, "dataset",
                               "cannot open \"" + name + "\""),
                       H5Dclose);
    }
    return std::make_unique<Hdf5Volume>(path, name, std::move(file), std::move(dataset), info);
}

} // namespace

std::unique_ptr<VolumeSource> openHdf5(const std::string& path, const std::string& dataset) {
    return detail::openSandboxed(
        {path, "HDF5", "to parse", {}}, parserSandboxLimits(),
        [path, dataset](const detail::ReadingFile&) { return openInProcess(path, dataset); });
}

} // namespace bc::brickstore
