#pragma once
// What the HDF5 reader needs of libhdf5 beyond single calls: owners of its identifiers, the one
// translation of its failures into FormatError (with the text of its error stack), the voxel
// types its datatypes convert to without loss, and the listing of a file's volumes that an
// error about a missing dataset shows. Used only in the parser sandbox's child: the parent
// never initializes the library.
#include "brickstore/Error.h"
#include "brickstore/VoxelType.h"

#include <hdf5.h>

#include <optional>
#include <string>

namespace bc::brickstore::detail {

/// Owns one HDF5 identifier and closes it with the matching H5*close (H5Dclose, H5Sclose...).
class H5Id {
  public:
    using Closer = herr_t (*)(hid_t);
    H5Id() = default;
    H5Id(hid_t id, Closer close) : mId(id), mClose(close) {}
    ~H5Id() { reset(); }
    H5Id(H5Id&& other) noexcept : mId(other.mId), mClose(other.mClose) { other.mId = -1; }
    H5Id& operator=(H5Id&& other) noexcept {
        if (this != &other) {
            reset();
            mId = other.mId;
            mClose = other.mClose;
            other.mId = -1;
        }
        return *this;
    }
    H5Id(const H5Id&) = delete;
    H5Id& operator=(const H5Id&) = delete;
    hid_t get() const { return mId; }

  private:
    void reset() {
        if (mId >= 0 && mClose) mClose(mId);
        mId = -1;
    }
    hid_t mId = -1;
    Closer mClose = nullptr;
};

/// Turns off libhdf5's printing of its error stack (errors become FormatError text instead).
void quietHdf5Errors();

/// The current error stack of libhdf5 in one line (innermost messages first, at most ~200
/// characters), and clears it; empty when the stack is empty.
std::string hdf5ErrorText();

/// The one translation of libhdf5's failures: a negative `result` (a failed call) throws
/// FormatError(file, field, what + ": " + hdf5ErrorText()); any other is returned.
template <class T>
T h5Check(T result, const std::string& file, const std::string& field, const std::string& what) {
    if (result >= 0) return result;
    const std::string stack = hdf5ErrorText();
    throw FormatError(file, field, what + (stack.empty() ? "" : ": libhdf5: " + stack));
}

/// The voxel type a stored datatype converts to without loss: u8, u16, i16 and IEEE f32 as
/// they are, i8 widened to i16 and IEEE half floats to f32; nullopt for anything else.
std::optional<VoxelType> voxelTypeOf(hid_t type);

/// A stored datatype in words: "u16 big-endian", "f64", "compound", "variable-length string".
std::string datatypeText(hid_t type);

/// libhdf5's native memory type of `type` (H5T_NATIVE_UINT16...), what H5Dread converts to.
hid_t nativeTypeOf(VoxelType type);

/// "/entry/data/volume (256x256x113 u16), /raw (64x64x93 f32)": the file's 3D datasets of a
/// type voxelTypeOf accepts, dims as x,y,z, at most 20 and ~300 characters ("and 3 more"
/// after), or "none"; objects past the first 10000 are not looked at.
std::string volumeList(hid_t file);

} // namespace bc::brickstore::detail
