#pragma once
// One TIFF file opened with libtiff for the TIFF reader (readers/TiffReader.cpp): its pages'
// layouts, checked against what brickcast reads, and a page decoded straight into a slice.
// Defined in TiffFile.cpp, the one place libtiff's errors become FormatErrors: every open has
// its own error handler, so libtiff's message ends the FormatError instead of reaching stderr.
#include "brickstore/VoxelType.h"
#include "brickstore/readers/detail/ReadAhead.h"
#include "brickstore/readers/detail/SandboxedSource.h"

#include <cstdarg>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

struct tiff; // libtiff's TIFF, kept out of this header

namespace bc::brickstore::detail {

/// What the reader needs of one page (IFD), read from its tags and found supported: one
/// sample per pixel of a VoxelType, minisblack, a codec libtiff decodes, strips or tiles.
struct TiffPage {
    std::uint32_t width = 0;  ///< ImageWidth
    std::uint32_t length = 0; ///< ImageLength
    std::uint16_t bitsPerSample = 0;
    std::uint16_t sampleFormat = 0;
    std::uint16_t compression = 0;
    VoxelType type = VoxelType::U8;
    bool tiled = false;
    std::uint32_t tileWidth = 0, tileLength = 0; ///< tiles only
    std::uint32_t rowsPerStrip = 0;              ///< strips only

    std::uint64_t sliceBytes() const { return std::uint64_t(width) * length * voxelBytes(type); }
};

/// The resolution tags of a page: pixels per unit, unit 1 (none), 2 (inch) or 3 (cm).
struct TiffResolution {
    bool present = false; ///< false: no XResolution
    double x = 0, y = 0;
    std::uint16_t unit = 2;
};

/// "LZW", "deflate": a supported Compression value as descriptions write it.
const char* compressionName(std::uint16_t compression);

/// A TIFF file open on one page (the first, then each next). Not copyable: libtiff's error
/// handler holds its address.
class TiffFile {
  public:
    /// Opens `path` without memory mapping (the parser sandbox bounds address space) and with
    /// strip and tile arrays loaded on demand (a page header stays cheap to walk); libtiff's
    /// single allocations are bounded by kMaxLibtiffAllocBytes. `namePages`: errors say which
    /// page ("page 3: ...") in a multi-page file. @throw FormatError(path, "header").
    TiffFile(const std::string& path, bool namePages);
    ~TiffFile();
    TiffFile(const TiffFile&) = delete;
    TiffFile& operator=(const TiffFile&) = delete;

    bool bigTiff() const;
    /// Index of the current page, 0 for the first.
    std::uint64_t pageIndex() const { return mPage; }
    /// Moves to the next page; false when the current one is the last.
    /// @throw FormatError(path, "header") when the next page's header cannot be read.
    bool nextPage();
    /// Back to the first page. @throw FormatError(path, "header").
    void rewind();

    /// The current page's layout. @throw FormatError naming the field that is missing or not
    /// supported (SamplesPerPixel, BitsPerSample, SampleFormat, Compression, ...).
    TiffPage layout() const;
    /// The current page's ImageDescription (its first 64 KiB); empty when it has none.
    std::string description() const;
    TiffResolution resolution() const;

    /// Decodes the current page, whose layout is `page`, into `out` (page.sliceBytes(), x
    /// fastest, host byte order): strips straight into it, tiles through one tile buffer.
    /// Each strip or tile must lie inside the file before libtiff reads it.
    /// @throw FormatError(path, "StripByteCounts"/"TileByteCounts", ...) for data past the
    /// file's end, FormatError(path, "data") when libtiff cannot decode it.
    void readPage(const TiffPage& page, std::span<std::byte> out);
    /// Where the current page's voxels lie when they need no decoding (uncompressed strips in
    /// host byte order, most significant bit first): appends them to `out` as extents of
    /// `file` (growing the last extent where they continue it) and returns true; false, with
    /// `out` untouched, for a page readPage must decode. Each strip is checked as readPage
    /// checks it. @throw FormatError(path, "StripByteCounts"/"StripOffsets", ...) for a strip
    /// past the file's end or one too short for its rows.
    bool locateStrips(const TiffPage& page, std::uint32_t file, std::vector<FileExtent>& out);
    /// Moves the file's read-ahead window (ReadAhead, a thread of its own) past the last strip
    /// or tile read: in the parser sandbox the child decodes a slab and then waits while the
    /// pipe drains and the ingest cuts bricks, so the next pages come from the disk meanwhile
    /// instead of after (pages are written in order).
    void readAhead();

    /// "page 3: " in a multi-page file, "" otherwise: how errors name the page.
    std::string where() const;
    /// Throws FormatError(path, field, where() + why), libtiff's last error appended.
    [[noreturn]] void fail(const std::string& field, const std::string& why) const;

  private:
    static int onError(struct tiff*, void* self, const char* module, const char* format,
                       std::va_list args);
    void checkSupported(const TiffPage& page, std::uint16_t samples,
                        std::uint16_t photometric) const;
    /// Checks that strip or tile `index` lies inside the file; returns where it ends.
    std::uint64_t checkStrile(std::uint32_t index, bool tiled, const char* kind) const;
    /// The strips the page's ImageLength and RowsPerStrip need, checked against those it holds.
    std::uint64_t checkStrips(const TiffPage& page) const;
    void readStrips(const TiffPage& page, std::span<std::byte> out);
    void readTiles(const TiffPage& page, std::span<std::byte> out);

    std::string mPath;
    bool mNamePages;
    struct tiff* mTiff = nullptr;
    std::uint64_t mFileBytes = 0;
    std::uint64_t mPage = 0;
    std::uint64_t mReadEnd = 0;        ///< the end of the furthest strip or tile read
    std::unique_ptr<ReadAhead> mAhead; ///< from the first readAhead(); ends before TIFFClose
    mutable std::string mError;        ///< libtiff's first error since the last call that checks
    std::vector<std::byte> mTile;
};

} // namespace bc::brickstore::detail
