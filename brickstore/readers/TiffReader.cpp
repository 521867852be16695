// TIFF volumes: a folder of one-slice files (each file's first page a z-slice, in natural
// name order) or one multi-page classic or BigTIFF file (each page a z-slice). libtiff reads
// the tags and decodes (readers/detail/TiffFile.h); this file lists and checks the slices,
// finds the spacing and streams the volume.
//
// Before the first slice is read, every file's (every page's) header is walked and must have
// the first page's size, type and sample layout, so a mismatch fails before ingest starts;
// each slice's header is checked again when it is decoded. Memory: one slice, decoded into
// the caller's buffer (strips directly, tiles through one tile buffer of at most 256 MiB),
// plus libtiff's one compressed strip or tile (at most 512 MiB); never the volume.
//
// libtiff runs in the parser sandbox (readers/detail/SandboxedSource.h), as DICOM does: a
// hostile file that makes it crash, hang or exhaust memory is a FormatError naming that file.
// A TIFF names no other file, so nothing read from one leads outside its folder.
#include "brickstore/Error.h"
#include "brickstore/Readers.h"
#include "brickstore/readers/detail/SandboxedSource.h"
#include "brickstore/readers/detail/TiffFile.h"

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <map>
#include <sstream>
#include <vector>

namespace bc::brickstore {
namespace {

namespace fs = std::filesystem;
using detail::TiffFile;
using detail::TiffPage;

/// The pre-walk of a multi-page file restarts the parse alarm every this many page headers:
/// the limit bounds a stalled parse, not a file of many pages.
constexpr std::uint64_t kPagesPerAlarm = 1024;

std::string numberText(double v) {
    char text[32];
    std::snprintf(text, sizeof text, "%g", v);
    return text;
}

bool isDigit(char c) {
    return c >= '0' && c <= '9';
}

/// "s2.tif" before "s10.tif": runs of digits compare by value, other characters byte by byte;
/// names equal by that ("s01", "s1") fall back to plain order, so the order is total.
bool naturalLess(const std::string& a, const std::string& b) {
    std::size_t i = 0, j = 0;
    while (i < a.size() && j < b.size()) {
        if (!isDigit(a[i]) || !isDigit(b[j])) {
            if (a[i] != b[j])
                return static_cast<unsigned char>(a[i]) < static_cast<unsigned char>(b[j]);
            ++i, ++j;
            continue;
        }
        std::size_t ei = i, ej = j;
        while (ei < a.size() && isDigit(a[ei]))
            ++ei;
        while (ej < b.size() && isDigit(b[ej]))
            ++ej;
        while (i + 1 < ei && a[i] == '0')
            ++i;
        while (j + 1 < ej && b[j] == '0')
            ++j;
        if (ei - i != ej - j) return ei - i < ej - j;
        if (const int c = a.compare(i, ei - i, b, j, ej - j); c != 0) return c < 0;
        i = ei, j = ej;
    }
    if (i < a.size() || j < b.size()) return j < b.size();
    return a < b;
}

bool isTiffName(std::string name) {
    std::transform(name.begin(), name.end(), name.begin(),
                   [](unsigned char c) { return char(std::tolower(c)); });
    const auto endsWith = [&](const std::string& end) {
        return name.size() > end.size() &&
               name.compare(name.size() - end.size(), end.size(), end) == 0;
    };
    return endsWith(".tif") || endsWith(".tiff");
}

/// The folder's .tif/.tiff files in natural order. Hidden names are skipped: "._s1.tif" is
/// macOS's resource fork of s1.tif, not a slice.
std::vector<std::string> listSlices(const std::string& folder) {
    std::error_code ec;
    fs::directory_iterator it(folder, ec);
    if (ec) throw FormatError(folder, "path", "cannot list the folder: " + ec.message());
    std::vector<std::string> names;
    for (; it != fs::directory_iterator(); it.increment(ec)) {
        if (ec) throw FormatError(folder, "path", "cannot list the folder: " + ec.message());
        const std::string name = it->path().filename().string();
        if (name[0] == '.' || !isTiffName(name) || !it->is_regular_file(ec)) continue;
        names.push_back(name);
        if (names.size() > kMaxDimVoxels)
            throw FormatError(folder, "files",
                              "holds more than " + std::to_string(kMaxDimVoxels) +
                                  " .tif files, the limit of slices along z");
    }
    if (names.empty()) throw FormatError(folder, "files", "holds no .tif or .tiff file");
    std::sort(names.begin(), names.end(), naturalLess);
    std::vector<std::string> paths;
    for (const std::string& name : names)
        paths.push_back((fs::path(folder) / name).string());
    return paths;
}

/// Millimetres per unit of an ImageJ "unit=" value; nothing for units it cannot be ("pixel").
std::optional<double> unitMm(const std::string& unit) {
    static const std::map<std::string, double> kUnits = {
        {"nm", 1e-6},  {"nanometer", 1e-6}, {"micron", 1e-3},    {"microns", 1e-3},
        {"um", 1e-3},  {"\\u00B5m", 1e-3},  {"\xC2\xB5m", 1e-3}, {"\xCE\xBCm", 1e-3},
        {"mm", 1.0},   {"millimeter", 1.0}, {"cm", 10.0},        {"centimeter", 10.0},
        {"m", 1000.0}, {"meter", 1000.0},   {"inch", 25.4},      {"in", 25.4}};
    const auto it = kUnits.find(unit);
    return it == kUnits.end() ? std::nullopt : std::optional<double>(it->second);
}

/// What an ImageJ ImageDescription ("ImageJ=1.54f\nimages=40\nslices=40\nspacing=2.5\n
/// unit=micron\n") says about the stack.
struct ImageJ {
    bool present = false;
    std::optional<double> spacing; ///< z, in `unit`s
    std::optional<double> unitMm;
    std::uint64_t images = 0, channels = 1, frames = 1;
};

ImageJ parseImageJ(const std::string& text, const std::string& path) {
    ImageJ ij;
    if (text.rfind("ImageJ=", 0) != 0) return ij;
    ij.present = true;
    std::istringstream lines(text);
    for (std::string line; std::getline(lines, line);) {
        if (!line.empty() && line.back() == '\r') line.pop_back();
        const std::size_t eq = line.find('=');
        if (eq == std::string::npos) continue;
        const std::string key = line.substr(0, eq), value = line.substr(eq + 1);
        const char* end = value.data() + value.size();
        if (key == "unit") {
            ij.unitMm = unitMm(value);
        } else if (key == "spacing") {
            double v = 0;
            if (std::from_chars(value.data(), end, v).ptr != end || !std::isfinite(v) || v <= 0)
                throw FormatError(path, "ImageDescription",
                                  "ImageJ spacing='" + value.substr(0, 40) +
                                      "' is not a finite positive number");
            ij.spacing = v;
        } else if (key == "images" || key == "channels" || key == "frames") {
            std::uint64_t n = 0;
            if (std::from_chars(value.data(), end, n).ptr != end)
                throw FormatError(path, "ImageDescription",
                                  "ImageJ " + key + "='" + value.substr(0, 40) +
                                      "' is not a count");
            (key == "images" ? ij.images : key == "channels" ? ij.channels : ij.frames) = n;
        }
    }
    return ij;
}

/// Voxel size from XResolution/YResolution (pixels per ResolutionUnit; a unit of none takes
/// ImageJ's "unit=") and z from ImageJ's "spacing="; 1 where the file says nothing. A unit
/// that cannot be known keeps the numbers as they are, read as millimetres.
std::array<double, 3> spacingOf(const TiffFile& file, const ImageJ& ij, const std::string& path) {
    std::array<double, 3> spacing{1, 1, 1};
    const double imagejUnit = ij.unitMm.value_or(1.0);
    if (ij.spacing) spacing[2] = *ij.spacing * imagejUnit;
    const detail::TiffResolution r = file.resolution();
    if (!r.present) return spacing;
    // ResolutionUnit: 1 none, 2 inch, 3 centimetre.
    if (r.unit < 1 || r.unit > 3)
        throw FormatError(path, "ResolutionUnit",
                          std::to_string(r.unit) + " is none of 1 (none), 2 (inch), 3 (cm)");
    const double unit = r.unit == 2 ? 25.4 : r.unit == 3 ? 10.0 : imagejUnit;
    for (const auto& [value, field] : {std::pair{r.x, "XResolution"}, {r.y, "YResolution"}})
        if (!std::isfinite(value) || value <= 0)
            throw FormatError(path, field,
                              numberText(value) +
                                  " pixels per unit; it must be finite and positive");
    spacing[0] = unit / r.x;
    spacing[1] = unit / r.y;
    return spacing;
}

/// In the sandbox's child; `files` are the folder's slices (listed by the parent, which reads
/// the located ones itself) or the one multi-page file.
class TiffVolume final : public VolumeSource, public detail::SliceLocator {
  public:
    TiffVolume(const std::string& path, bool folder, std::vector<std::string> files,
               const std::optional<std::array<double, 3>>& spacingMm,
               const detail::ReadingFile& reading)
        : mPath(path), mReading(reading), mFolder(folder), mFiles(std::move(files)) {
        const std::string first = mFiles.front();
        mFirstName = mFolder ? "the first slice's (" + fs::path(first).filename().string() + ")"
                             : "the first page's";
        report(first);
        mFile = std::make_unique<TiffFile>(first, !mFolder);
        mFirst = mFile->layout();
        mInfo.dims = {mFirst.width, mFirst.length, 1};
        mInfo.type = mFirst.type;
        validateVolumeInfo(mInfo, first, "ImageWidth/ImageLength");
        const ImageJ ij = parseImageJ(mFile->description(), first);
        checkImageJ(ij, first);
        mInfo.spacingMm = spacingMm ? *spacingMm : spacingOf(*mFile, ij, first);
        mInfo.dims[2] = mFolder ? walkFiles() : walkPages(ij);
        validateVolumeInfo(mInfo, path, mFolder ? "files" : "pages");
        mInfo.description = describe();
        if (mFolder) {
            mFile.reset();
        } else {
            mFile->rewind();
            mAt = 0;
        }
    }

    const VolumeInfo& info() const override { return mInfo; }

    bool locateSlice(std::uint64_t z, std::vector<detail::FileExtent>& out) override {
        const TiffPage page = moveTo(z);
        return mFile->locateStrips(page, std::uint32_t(mFolder ? z : 0), out);
    }

    void decodeSlice(std::uint64_t z, std::span<std::byte> out) override {
        const TiffPage page = moveTo(z);
        mFile->readPage(page, out);
        readAhead(z);
        if (mInfo.type == VoxelType::F32) checkFinite(out, *mFile);
    }

  private:
    void readNextSlices(std::uint64_t count, std::span<std::byte> out) override {
        const std::uint64_t bytes = mInfo.sliceBytes();
        for (std::uint64_t i = 0; i < count; ++i)
            decodeSlice(nextSlice() + i, out.subspan(i * bytes, bytes));
    }

    void report(const std::string& file) const {
        if (mReading) mReading(file);
    }

    /// A hyperstack's pages interleave channels and time points: they are not z-slices.
    static void checkImageJ(const ImageJ& ij, const std::string& path) {
        if (ij.channels > 1 || ij.frames > 1)
            throw FormatError(path, "ImageDescription",
                              "an ImageJ hyperstack of " + std::to_string(ij.channels) +
                                  " channels and " + std::to_string(ij.frames) +
                                  " frames; brickcast reads a stack of one channel and frame");
    }

    std::uint64_t walkFiles() const {
        for (std::size_t i = 1; i < mFiles.size(); ++i) {
            report(mFiles[i]);
            TiffFile file(mFiles[i], false);
            checkSameLayout(file.layout(), file);
        }
        return mFiles.size();
    }

    std::uint64_t walkPages(const ImageJ& ij) {
        std::uint64_t pages = 1;
        while (mFile->nextPage()) {
            if (++pages > kMaxDimVoxels)
                throw FormatError(mPath, "pages",
                                  "more than " + std::to_string(kMaxDimVoxels) +
                                      " pages, the limit of slices along z");
            if (pages % kPagesPerAlarm == 0) report(mPath);
            checkSameLayout(mFile->layout(), *mFile);
        }
        // ImageJ writes a stack over 4 GiB as one page header followed by all the slices.
        if (ij.images > pages)
            throw FormatError(mPath, "ImageDescription",
                              "ImageJ says images=" + std::to_string(ij.images) +
                                  " but the file has " + std::to_string(pages) +
                                  " pages: ImageJ's headerless layout of stacks over 4 GiB is "
                                  "not read; save it as BigTIFF or OME-TIFF");
        return pages;
    }

    void checkSameLayout(const TiffPage& page, const TiffFile& file) const {
        const auto same = [&](const char* field, std::uint64_t value, std::uint64_t first) {
            if (value != first)
                file.fail(field, std::string(field) + " is " + std::to_string(value) + "; " +
                                     mFirstName + " is " + std::to_string(first));
        };
        same("ImageWidth", page.width, mFirst.width);
        same("ImageLength", page.length, mFirst.length);
        same("BitsPerSample", page.bitsPerSample, mFirst.bitsPerSample);
        same("SampleFormat", page.sampleFormat, mFirst.sampleFormat);
    }

    /// Opens slice `z`'s file or page (once: locateSlice and then decodeSlice ask for the
    /// same z) and returns its layout, checked against the first page's.
    TiffPage moveTo(std::uint64_t z) {
        if (mAt != z) {
            if (mFolder) {
                report(mFiles[z]);
                mFile.reset(); // one file open at a time
                mFile = std::make_unique<TiffFile>(mFiles[z], false);
            } else {
                report(mPath);
                if (z != mAt + 1 || !mFile->nextPage())
                    throw FormatError(mPath, "pages",
                                      "ends after " + std::to_string(z) + " pages, not the " +
                                          std::to_string(mInfo.dims[2]) + " it had when opened");
            }
            mAt = z;
        }
        const TiffPage page = mFile->layout();
        checkSameLayout(page, *mFile);
        return page;
    }

    /// The next slices' bytes asked of the kernel while this one is decoded and sent (see
    /// TiffFile::readAhead): a window of pages of a file, or of the folder's next files.
    void readAhead(std::uint64_t z) {
        if (!mFolder) return mFile->readAhead();
        detail::willNeedAfter(mFiles, z, mInfo.sliceBytes(), mAdvised);
    }

    /// NaN or infinity would poison every min/max and average the store keeps.
    void checkFinite(std::span<const std::byte> slice, const TiffFile& file) const {
        for (std::size_t i = 0; i < slice.size(); i += 4) {
            float v;
            std::memcpy(&v, slice.data() + i, 4);
            if (std::isfinite(v)) continue;
            const std::uint64_t voxel = i / 4;
            file.fail("data", "voxel (" + std::to_string(voxel % mInfo.dims[0]) + "," +
                                  std::to_string(voxel / mInfo.dims[0]) + ") is " +
                                  (std::isnan(v) ? "NaN" : "infinite") +
                                  "; float volumes must be finite");
        }
    }

    std::string describe() const {
        std::string name = mPath;
        while (name.size() > 1 && name.back() == '/')
            name.pop_back(); // "stack/" names the folder "stack"
        name = fs::path(name).filename().string();
        const std::string layout = std::string(detail::compressionName(mFirst.compression)) +
                                   (mFirst.tiled ? " tiles" : " strips");
        const std::string type(voxelTypeName(mInfo.type));
        if (mFolder)
            return "TIFF stack " + name + " (" + std::to_string(mFiles.size()) + " files, " +
                   layout + "), " + type;
        return std::string(mFile->bigTiff() ? "BigTIFF " : "TIFF ") + name + " (" +
               std::to_string(mInfo.dims[2]) + " pages, " + layout + "), " + type;
    }

    std::string mPath;
    detail::ReadingFile mReading;
    bool mFolder = false;
    std::vector<std::string> mFiles; ///< a folder's slices, in natural order, or the one file
    std::string mFirstName;          ///< "the first page's", as mismatch errors say it
    std::unique_ptr<TiffFile> mFile; ///< the multi-page file, or the folder's current slice
    TiffPage mFirst;
    VolumeInfo mInfo;
    std::uint64_t mAdvised = 0;     ///< a folder's files before this one were asked for (readAhead)
    std::uint64_t mAt = UINT64_MAX; ///< the slice mFile is on (UINT64_MAX: none yet)
};

} // namespace

std::unique_ptr<VolumeSource> openTiff(const std::string& path,
                                       const std::optional<std::array<double, 3>>& spacingMm) {
    // The folder is listed here, before the fork: the parent reads located slices itself and
    // takes a file only from this list, never a path the parser names.
    std::error_code ec;
    const bool folder = fs::is_directory(path, ec);
    std::vector<std::string> files = folder ? listSlices(path) : std::vector<std::string>{path};
    detail::SandboxedParser parser{path, "TIFF", "per file or page", files};
    return detail::openSandboxed(
        parser, parserSandboxLimits(),
        [path, folder, files = std::move(files), spacingMm](const detail::ReadingFile& reading) {
            return std::make_unique<TiffVolume>(path, folder, files, spacingMm, reading);
        });
}

} // namespace bc::brickstore
