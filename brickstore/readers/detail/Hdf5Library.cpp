// libhdf5 for the HDF5 reader (Hdf5Library.h): identifiers, errors, datatypes, the listing.
#include "brickstore/readers/detail/Hdf5Library.h"

#include "brickstore/VolumeSource.h"

#include <array>
#include <cstddef>
#include <vector>

namespace bc::brickstore::detail {
namespace {

constexpr std::size_t kMaxErrorStackText = 200;
constexpr std::size_t kMaxListedVolumes = 20;
/// The listing travels inside one error of the sandbox, whose text stays under 400 characters.
constexpr std::size_t kMaxListText = 300;
constexpr std::size_t kMaxVisitedObjects = 10000;
constexpr std::size_t kMaxNameText = 80;

herr_t appendErrorRecord(unsigned, const H5E_error2_t* record, void* data) {
    auto& text = *static_cast<std::string*>(data);
    if (!record->desc || !*record->desc || text.size() >= kMaxErrorStackText) return 0;
    const std::string desc(record->desc);
    if (text.find(desc) != std::string::npos) return 0;
    text += (text.empty() ? "" : "; ") + desc;
    return 0;
}

/// A name from the file as one line of text: bytes outside printable ASCII become '?'.
std::string printable(const char* name) {
    std::string text;
    for (const char* p = name; *p && text.size() < kMaxNameText; ++p)
        text += (*p >= 0x20 && *p < 0x7f) ? *p : '?';
    return text;
}

struct Listing {
    std::vector<std::string> entries;
    std::size_t found = 0;
    std::size_t visited = 0;
};

/// The listing's entry for dataset `name` under `group`, or empty when it is no volume.
std::string volumeEntry(hid_t group, const char* name) {
    H5Id dataset(H5Dopen2(group, name, H5P_DEFAULT), H5Dclose);
    if (dataset.get() < 0) return {};
    H5Id space(H5Dget_space(dataset.get()), H5Sclose);
    H5Id type(H5Dget_type(dataset.get()), H5Tclose);
    if (space.get() < 0 || type.get() < 0 || H5Sget_simple_extent_ndims(space.get()) != 3)
        return {};
    std::array<hsize_t, 3> dims{};
    if (H5Sget_simple_extent_dims(space.get(), dims.data(), nullptr) != 3) return {};
    const std::optional<VoxelType> voxel = voxelTypeOf(type.get());
    if (!voxel) return {};
    // Appended piece by piece: GCC 12 warns (-Wrestrict, wrongly) on the one-expression form.
    std::string entry = "/";
    entry += printable(name);
    entry += " (" + dimsText({dims[2], dims[1], dims[0]}) + " " + datatypeText(type.get()) + ")";
    return entry;
}

herr_t listVolume(hid_t group, const char* name, const H5O_info_t* info, void* data) {
    auto& listing = *static_cast<Listing*>(data);
    if (++listing.visited > kMaxVisitedObjects) return 1; // stops the walk, without failing
    if (info->type != H5O_TYPE_DATASET) return 0;
    try {
        std::string entry = volumeEntry(group, name);
        H5Eclear2(H5E_DEFAULT); // a dataset that does not open is simply not listed
        if (entry.empty()) return 0;
        ++listing.found;
        if (listing.entries.size() < kMaxListedVolumes) listing.entries.push_back(entry);
        return 0;
    } catch (...) {
        return -1; // no exception may cross libhdf5's C frames
    }
}

} // namespace

void quietHdf5Errors() {
    H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
}

std::string hdf5ErrorText() {
    std::string text;
    H5Ewalk2(H5E_DEFAULT, H5E_WALK_UPWARD, appendErrorRecord, &text);
    H5Eclear2(H5E_DEFAULT);
    return text;
}

std::optional<VoxelType> voxelTypeOf(hid_t type) {
    const std::size_t bytes = H5Tget_size(type);
    if (H5Tget_class(type) == H5T_INTEGER) {
        const bool isSigned = H5Tget_sign(type) != H5T_SGN_NONE;
        if (bytes == 1) return isSigned ? VoxelType::I16 : VoxelType::U8;
        if (bytes == 2) return isSigned ? VoxelType::I16 : VoxelType::U16;
        return std::nullopt;
    }
    if (H5Tget_class(type) != H5T_FLOAT) return std::nullopt;
    // Only the IEEE layouts: another 4-byte float (a VAX one, say) would not convert exactly.
    std::size_t signBit = 0, exponentBit = 0, exponentBits = 0, mantissaBit = 0, mantissaBits = 0;
    if (H5Tget_fields(type, &signBit, &exponentBit, &exponentBits, &mantissaBit, &mantissaBits) < 0)
        return std::nullopt;
    const std::array<std::size_t, 5> fields{signBit, exponentBit, exponentBits, mantissaBit,
                                            mantissaBits};
    const std::size_t bias = H5Tget_ebias(type);
    if (bytes == 4 && fields == std::array<std::size_t, 5>{31, 23, 8, 0, 23} && bias == 127)
        return VoxelType::F32;
    if (bytes == 2 && fields == std::array<std::size_t, 5>{15, 10, 5, 0, 10} && bias == 15)
        return VoxelType::F32;
    return std::nullopt;
}

std::string datatypeText(hid_t type) {
    const std::string bits = std::to_string(H5Tget_size(type) * 8);
    const std::string order = H5Tget_order(type) == H5T_ORDER_BE ? " big-endian" : "";
    switch (H5Tget_class(type)) {
    case H5T_INTEGER:
        return (H5Tget_sign(type) == H5T_SGN_NONE ? "u" : "i") + bits + order;
    case H5T_FLOAT:
        return "f" + bits + order;
    case H5T_STRING:
        return H5Tis_variable_str(type) > 0
                   ? "variable-length string"
                   : "string of " + std::to_string(H5Tget_size(type)) + " bytes";
    case H5T_COMPOUND:
        return "compound of " + std::to_string(H5Tget_nmembers(type)) + " members";
    case H5T_ENUM:
        return "enum";
    case H5T_ARRAY:
        return "array";
    case H5T_OPAQUE:
        return "opaque";
    case H5T_BITFIELD:
        return "bitfield";
    case H5T_REFERENCE:
        return "reference";
    case H5T_VLEN:
        return "variable-length sequence";
    case H5T_TIME:
        return "time";
    default:
        return "unknown datatype";
    }
}

hid_t nativeTypeOf(VoxelType type) {
    switch (type) {
    case VoxelType::U8:
        return H5T_NATIVE_UINT8;
    case VoxelType::U16:
        return H5T_NATIVE_UINT16;
    case VoxelType::I16:
        return H5T_NATIVE_INT16;
    case VoxelType::F32:
        return H5T_NATIVE_FLOAT;
    }
    return H5T_NATIVE_UINT8;
}

std::string volumeList(hid_t file) {
    Listing listing;
    const herr_t walked =
        H5Ovisit2(file, H5_INDEX_NAME, H5_ITER_INC, listVolume, &listing, H5O_INFO_BASIC);
    H5Eclear2(H5E_DEFAULT); // a damaged group ends the walk; what was found is still listed
    std::string text;
    std::size_t shown = 0;
    for (const std::string& entry : listing.entries) {
        if (shown > 0 && text.size() + entry.size() > kMaxListText) break;
        text += (shown++ ? ", " : "") + entry;
    }
    if (listing.found > shown) text += " and " + std::to_string(listing.found - shown) + " more";
    if (listing.found == 0) text = "none";
    if (walked != 0)
        text += " (the walk stopped after " + std::to_string(listing.visited) + " objects)";
    return text;
}

} // namespace bc::brickstore::detail
