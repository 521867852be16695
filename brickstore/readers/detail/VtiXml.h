#pragma once
// The XML part of a VTK XML image data file (.vti), parsed by expat (VtiXml.cpp): what the
// VTKFile, ImageData, Piece and chosen point-data DataArray say, and where that array's bytes
// lie. Only the markup is parsed and held: parsing stops at the AppendedData element, and the
// base64 text of an inline ("binary") array is located and checked, never kept, so a .vti of
// any size costs at most kMaxVtiMarkupBytes of parsing.
#include "brickstore/Readers.h"

#include <cstdint>
#include <string>

namespace bc::brickstore::detail {

/// More markup than this (all but inline array data) is not a .vti header.
constexpr std::uint64_t kMaxVtiMarkupBytes = 1 << 20;

/// Where and how the chosen array's bytes are stored.
enum class VtiEncoding {
    AppendedRaw,    ///< binary bytes after AppendedData's "_", at `offset`
    AppendedBase64, ///< base64 text after AppendedData's "_", at `offset` characters
    InlineBase64,   ///< base64 text inside the DataArray element (format="binary")
};

/// What the XML says about the volume and its scalar array, checked for what brickcast reads.
struct VtiLayout {
    VolumeInfo info; ///< dims from WholeExtent, origin of extent's first voxel, spacing
    Endian endian = Endian::Little;
    std::uint32_t headerBytes = 4; ///< UInt32 or UInt64 sizes in the binary headers
    bool zlib = false;             ///< vtkZLibDataCompressor blocks
    VtiEncoding encoding = VtiEncoding::AppendedRaw;
    std::string arrayName;
    /// Appended: file offset of the first byte after "_" plus the array's offset. Inline: file
    /// offset of the DataArray's text.
    std::uint64_t dataBegin = 0;
    /// Inline: file offset just past the DataArray's text. Appended: the file's size.
    std::uint64_t dataEnd = 0;
};

/// Parses the markup of `path` (file size `fileBytes`). @throw FormatError naming the file and
/// the attribute or element at fault: not well-formed XML, markup past kMaxVtiMarkupBytes, an
/// unsupported type, compressor, layout or array.
VtiLayout parseVtiXml(const std::string& path, std::uint64_t fileBytes);

} // namespace bc::brickstore::detail
