// PNG I/O through libpng. libpng reports errors by longjmp: every call into it sits in a
// small function whose locals are trivially destructible (nothing is skipped by the jump),
// and the C++ side (buffers, owners, exceptions) lives in the callers.
#include "render/Image.h"
#include "render/Error.h"

#include <png.h>

#include <atomic>
#include <cerrno>
#include <cmath>
#include <csetjmp>
#include <cstdio>
#include <cstring>
#include <stdexcept>

#include <unistd.h>

namespace bc::render {
namespace {

constexpr std::size_t kPngSignatureBytes = 8;

/// One libpng session: trivially destructible so it may live across setjmp/longjmp.
struct PngSession {
    png_structp png = nullptr;
    png_infop info = nullptr;
    std::FILE* file = nullptr;
    char message[256] = {};
};

[[noreturn]] void onPngError(png_structp png, png_const_charp message) {
    auto* session = static_cast<PngSession*>(png_get_error_ptr(png));
    std::snprintf(session->message, sizeof session->message, "%s", message);
    png_longjmp(png, 1);
}

void onPngWarning(png_structp, png_const_charp) {}

void readFromFile(png_structp png, png_bytep data, png_size_t bytes) {
    auto* file = static_cast<std::FILE*>(png_get_io_ptr(png));
    if (std::fread(data, 1, bytes, file) != bytes)
        png_error(png, std::feof(file) ? "file is truncated" : "read error");
}

void writeToFile(png_structp png, png_bytep data, png_size_t bytes) {
    auto* file = static_cast<std::FILE*>(png_get_io_ptr(png));
    if (std::fwrite(data, 1, bytes, file) != bytes) png_error(png, std::strerror(errno));
}

void flushFile(png_structp png) {
    std::fflush(static_cast<std::FILE*>(png_get_io_ptr(png)));
}

/// The decoded layout after the RGBA transforms.
struct PngHeader {
    png_uint_32 width = 0, height = 0;
    int bitDepth = 0, channels = 0;
    png_size_t rowBytes = 0;
};

/// Reads IHDR and everything before the image data; asks libpng to expand to RGBA.
bool readHeader(PngSession& s, PngHeader& header) {
    if (setjmp(png_jmpbuf(s.png))) return false;
    png_set_read_fn(s.png, s.file, readFromFile);
    png_set_sig_bytes(s.png, int(kPngSignatureBytes));
    png_read_info(s.png, s.info);
    const png_byte colour = png_get_color_type(s.png, s.info);
    if (colour == PNG_COLOR_TYPE_PALETTE) png_set_palette_to_rgb(s.png);
    if (colour == PNG_COLOR_TYPE_GRAY || colour == PNG_COLOR_TYPE_GRAY_ALPHA) {
        png_set_expand_gray_1_2_4_to_8(s.png);
        png_set_gray_to_rgb(s.png);
    }
    const bool transparency = png_get_valid(s.png, s.info, PNG_INFO_tRNS) != 0;
    if (transparency) png_set_tRNS_to_alpha(s.png);
    if (!(colour & PNG_COLOR_MASK_ALPHA) && !transparency)
        png_set_add_alpha(s.png, 0xffff, PNG_FILLER_AFTER);
    png_set_interlace_handling(s.png);
    png_read_update_info(s.png, s.info);
    header.width = png_get_image_width(s.png, s.info);
    header.height = png_get_image_height(s.png, s.info);
    header.bitDepth = png_get_bit_depth(s.png, s.info);
    header.channels = png_get_channels(s.png, s.info);
    header.rowBytes = png_get_rowbytes(s.png, s.info);
    return true;
}

/// Decodes every row into `rows` and reads to IEND, so a cut-off file is noticed.
bool readRows(PngSession& s, png_bytepp rows) {
    if (setjmp(png_jmpbuf(s.png))) return false;
    png_read_image(s.png, rows);
    png_read_end(s.png, nullptr);
    return true;
}

/// Encodes `pixels` (8-bit RGBA, top row first) into the session's file.
bool encodeRgba8(PngSession& s, const std::uint8_t* pixels, png_uint_32 width, png_uint_32 height) {
    if (setjmp(png_jmpbuf(s.png))) return false;
    png_set_write_fn(s.png, s.file, writeToFile, flushFile);
    png_set_IHDR(s.png, s.info, width, height, 8, PNG_COLOR_TYPE_RGBA, PNG_INTERLACE_NONE,
                 PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
    png_write_info(s.png, s.info);
    for (png_uint_32 y = 0; y < height; ++y)
        png_write_row(s.png, pixels + std::size_t(y) * width * 4);
    png_write_end(s.png, nullptr);
    return true;
}

/// Owns a read session: destroys the libpng structs and closes the file.
class PngReader {
  public:
    explicit PngReader(std::FILE* file) {
        mSession.file = file;
        mSession.png =
            png_create_read_struct(PNG_LIBPNG_VER_STRING, &mSession, onPngError, onPngWarning);
        if (mSession.png) mSession.info = png_create_info_struct(mSession.png);
        if (!mSession.info) {
            if (mSession.png) png_destroy_read_struct(&mSession.png, nullptr, nullptr);
            std::fclose(file);
            throw std::bad_alloc();
        }
    }
    ~PngReader() {
        if (mSession.png) png_destroy_read_struct(&mSession.png, &mSession.info, nullptr);
        std::fclose(mSession.file);
    }
    PngReader(const PngReader&) = delete;
    PngReader& operator=(const PngReader&) = delete;
    PngSession& session() { return mSession; }

  private:
    PngSession mSession;
};

/// Owns a write session: destroys the libpng structs and closes the file if still open.
class PngWriter {
  public:
    explicit PngWriter(std::FILE* file) {
        mSession.file = file;
        mSession.png =
            png_create_write_struct(PNG_LIBPNG_VER_STRING, &mSession, onPngError, onPngWarning);
        if (mSession.png) mSession.info = png_create_info_struct(mSession.png);
        if (!mSession.info) {
            if (mSession.png) png_destroy_write_struct(&mSession.png, nullptr);
            close();
            throw std::bad_alloc();
        }
    }
    ~PngWriter() {
        if (mSession.png) png_destroy_write_struct(&mSession.png, &mSession.info);
        close();
    }
    PngWriter(const PngWriter&) = delete;
    PngWriter& operator=(const PngWriter&) = delete;
    PngSession& session() { return mSession; }
    /// Closes the file; false when buffered bytes could not be written.
    bool close() {
        if (!mSession.file) return true;
        const bool ok = std::fclose(mSession.file) == 0;
        mSession.file = nullptr;
        return ok;
    }

  private:
    PngSession mSession;
};

std::uint8_t toByte(float v) {
    const float clamped = v > 0.0f ? (v < 1.0f ? v : 1.0f) : 0.0f; // NaN -> 0
    return std::uint8_t(std::lround(clamped * 255.0f));
}

void checkWritable(const std::string& path, const Image& image) {
    if (image.width == 0 || image.height == 0)
        throw std::invalid_argument(path + ": cannot write an empty image");
    if (image.rgba.size() != std::size_t(image.width) * image.height * 4)
        throw std::invalid_argument(path + ": image holds " + std::to_string(image.rgba.size()) +
                                    " floats, not width*height*4");
}

/// A name beside `path` that no other writer of this process or another uses.
std::string temporaryName(const std::string& path) {
    static std::atomic<std::uint64_t> counter{0};
    return path + ".tmp-" + std::to_string(::getpid()) + "-" + std::to_string(counter++);
}

/// Opens `path` and checks the 8-byte PNG signature. @throw RenderInputError
std::FILE* openPng(const std::string& path) {
    std::FILE* file = std::fopen(path.c_str(), "rb");
    if (!file) throw RenderInputError(path, "open", std::strerror(errno));
    png_byte signature[kPngSignatureBytes] = {};
    const std::size_t got = std::fread(signature, 1, kPngSignatureBytes, file);
    if (got == kPngSignatureBytes && png_sig_cmp(signature, 0, kPngSignatureBytes) == 0)
        return file;
    std::fclose(file);
    throw RenderInputError(path, "signature",
                           got == 0 ? "file is empty" : "not a PNG file (bad signature)");
}

void checkHeader(const std::string& path, const PngHeader& h) {
    const std::uint64_t pixels = std::uint64_t(h.width) * h.height;
    if (h.width == 0 || h.height == 0 || pixels > kMaxPngPixels)
        throw RenderInputError(path, "IHDR",
                               "image size " + std::to_string(h.width) + "x" +
                                   std::to_string(h.height) + " is empty or exceeds " +
                                   std::to_string(kMaxPngPixels) + " pixels");
    if (h.channels != 4 || (h.bitDepth != 8 && h.bitDepth != 16) ||
        h.rowBytes != std::size_t(h.width) * 4 * std::size_t(h.bitDepth / 8))
        throw RenderInputError(path, "IHDR", "unsupported pixel layout after expansion to RGBA");
}

Image toImage(const PngHeader& h, const std::vector<png_byte>& bytes) {
    Image image(h.width, h.height);
    if (h.bitDepth == 8) {
        for (std::size_t i = 0; i < image.rgba.size(); ++i)
            image.rgba[i] = float(bytes[i]) / 255.0f;
        return image;
    }
    for (std::size_t i = 0; i < image.rgba.size(); ++i) {
        const unsigned v = unsigned(bytes[2 * i]) << 8 | bytes[2 * i + 1]; // big-endian
        image.rgba[i] = float(double(v) / 65535.0);
    }
    return image;
}

} // namespace

std::vector<std::uint8_t> toRgba8(const Image& image) {
    std::vector<std::uint8_t> bytes(image.rgba.size());
    for (std::size_t i = 0; i < bytes.size(); ++i)
        bytes[i] = toByte(image.rgba[i]);
    return bytes;
}

void writePng(const std::string& path, const Image& image) {
    checkWritable(path, image);
    const std::vector<std::uint8_t> pixels = toRgba8(image);
    const std::string temporary = temporaryName(path);
    std::FILE* file = std::fopen(temporary.c_str(), "wbx");
    if (!file) throw RenderError(path + ": cannot write PNG: " + std::strerror(errno));
    std::string failure;
    {
        PngWriter writer(file);
        if (!encodeRgba8(writer.session(), pixels.data(), image.width, image.height))
            failure = writer.session().message;
        else if (!writer.close())
            failure = std::strerror(errno);
    }
    if (failure.empty() && std::rename(temporary.c_str(), path.c_str()) != 0)
        failure = std::strerror(errno);
    if (failure.empty()) return;
    std::remove(temporary.c_str());
    throw RenderError(path + ": cannot write PNG: " + failure);
}

Image readPng(const std::string& path) {
    PngReader reader(openPng(path));
    PngSession& s = reader.session();
    PngHeader header;
    if (!readHeader(s, header)) throw RenderInputError(path, "IHDR", s.message);
    checkHeader(path, header);
    std::vector<png_byte> bytes(header.rowBytes * header.height);
    std::vector<png_bytep> rows(header.height);
    for (png_uint_32 y = 0; y < header.height; ++y)
        rows[y] = bytes.data() + y * header.rowBytes;
    if (!readRows(s, rows.data())) throw RenderInputError(path, "data", s.message);
    return toImage(header, bytes);
}

} // namespace bc::render
