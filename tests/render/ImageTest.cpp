// PNG I/O: exact 8-bit round trips, every PNG flavour another tool may hand us (written
// here with libpng directly), and every kind of bad file named in the error.
#include "render/Image.h"
#include "render/Error.h"
#include "tests/TestSupport.h"

#include <png.h>

#include <algorithm>
#include <csetjmp>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <random>
#include <utility>

namespace bc::render {
namespace {

/// A PNG as libpng takes it: raw rows in the file's own layout.
struct RawPng {
    png_uint_32 width = 0, height = 0;
    int colourType = PNG_COLOR_TYPE_RGB;
    int bitDepth = 8;
    int interlace = PNG_INTERLACE_NONE;
    const png_byte* rows = nullptr; ///< height rows of rowBytes bytes, big-endian samples
    std::size_t rowBytes = 0;
    const png_color* palette = nullptr;
    int paletteSize = 0;
    const png_byte* paletteAlpha = nullptr;
    int paletteAlphaSize = 0;
};

/// libpng calls only; no C++ objects in this frame (longjmp).
bool encodeRaw(std::FILE* file, const RawPng& raw) {
    png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, nullptr, nullptr, nullptr);
    png_infop info = png ? png_create_info_struct(png) : nullptr;
    if (!info || setjmp(png_jmpbuf(png))) {
        png_destroy_write_struct(&png, &info);
        return false;
    }
    png_init_io(png, file);
    png_set_IHDR(png, info, raw.width, raw.height, raw.bitDepth, raw.colourType, raw.interlace,
                 PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
    if (raw.palette) png_set_PLTE(png, info, raw.palette, raw.paletteSize);
    if (raw.paletteAlpha) png_set_tRNS(png, info, raw.paletteAlpha, raw.paletteAlphaSize, nullptr);
    png_write_info(png, info);
    const int passes = png_set_interlace_handling(png);
    for (int pass = 0; pass < passes; ++pass)
        for (png_uint_32 y = 0; y < raw.height; ++y)
            png_write_row(png, raw.rows + y * raw.rowBytes);
    png_write_end(png, nullptr);
    png_destroy_write_struct(&png, &info);
    return true;
}

void writeRaw(const std::string& path, const RawPng& raw) {
    std::FILE* file = std::fopen(path.c_str(), "wb");
    ASSERT_NE(file, nullptr) << path;
    const bool ok = encodeRaw(file, raw);
    std::fclose(file);
    ASSERT_TRUE(ok) << path;
}

Image randomImage(std::uint32_t w, std::uint32_t h, unsigned seed) {
    std::mt19937 rng(seed);
    std::uniform_int_distribution<int> level(0, 255);
    Image image(w, h);
    for (float& v : image.rgba)
        v = float(level(rng)) / 255.0f;
    return image;
}

/// Byte-wise CRC-32 of PNG chunks, to forge a header that still passes libpng's CRC check.
std::uint32_t crc32Of(const std::uint8_t* data, std::size_t n) {
    std::uint32_t crc = 0xffffffffu;
    for (std::size_t i = 0; i < n; ++i) {
        crc ^= data[i];
        for (int k = 0; k < 8; ++k)
            crc = (crc >> 1) ^ (0xedb88320u & (0u - (crc & 1u)));
    }
    return ~crc;
}

void putBigEndian(std::uint8_t* at, std::uint32_t v) {
    for (int i = 0; i < 4; ++i)
        at[i] = std::uint8_t(v >> (24 - 8 * i));
}

void putBigEndian16(std::uint8_t* at, std::uint16_t v) {
    at[0] = std::uint8_t(v >> 8);
    at[1] = std::uint8_t(v);
}

void expectInputError(const std::string& path, const std::string& field) {
    try {
        readPng(path);
        ADD_FAILURE() << path << ": read without error";
    } catch (const RenderInputError& e) {
        EXPECT_EQ(e.file(), path);
        EXPECT_EQ(e.field(), field) << e.what();
        EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
    }
}

TEST(ImageTest, ConstructorZeroFillsAndPixelAddressesRowsFromTheTop) {
    Image image(3, 2);
    ASSERT_EQ(image.rgba.size(), 24u);
    for (float v : image.rgba)
        EXPECT_EQ(v, 0.0f);
    image.pixel(2, 1)[3] = 1.0f;
    EXPECT_EQ(image.rgba[(1 * 3 + 2) * 4 + 3], 1.0f);
    EXPECT_EQ(std::as_const(image).pixel(2, 1), image.rgba.data() + 20);
}

TEST(ImageTest, PngRoundTripIsExactAt8BitsForRandomImages) {
    test::TempDir dir;
    for (auto [w, h] : {std::pair{1u, 1u}, {37u, 23u}, {256u, 128u}}) {
        const Image image = randomImage(w, h, w * 31 + h);
        writePng(dir.file("a.png"), image);
        const Image back = readPng(dir.file("a.png"));
        ASSERT_EQ(back.width, w);
        ASSERT_EQ(back.height, h);
        EXPECT_EQ(back.rgba, image.rgba) << w << "x" << h;
    }
}

TEST(ImageTest, WritingRoundsAndClampsToTheNearest8BitLevel) {
    test::TempDir dir;
    Image image(4, 1);
    const float values[16] = {-0.5f,
                              0.0f,
                              1.0f,
                              2.0f,
                              0.5f / 255.0f + 1e-4f,
                              0.5f / 255.0f - 1e-4f,
                              0.25f,
                              0.75f,
                              100.4f / 255.0f,
                              100.6f / 255.0f,
                              0.1f,
                              0.9f,
                              std::numeric_limits<float>::quiet_NaN(),
                              0.0f,
                              0.0f,
                              0.0f};
    std::copy(values, values + 16, image.rgba.begin());
    writePng(dir.file("r.png"), image);
    const Image back = readPng(dir.file("r.png"));
    const int want[16] = {0, 0, 255, 255, 1, 0, 64, 191, 100, 101, 26, 230, 0, 0, 0, 0};
    for (int i = 0; i < 16; ++i)
        EXPECT_EQ(back.rgba[i], float(want[i]) / 255.0f) << "value " << i;
}

TEST(ImageTest, WritingLeavesNoTemporaryFileAndReplacesAnOldImage) {
    test::TempDir dir;
    writePng(dir.file("f.png"), randomImage(8, 8, 1));
    const Image second = randomImage(16, 4, 2);
    writePng(dir.file("f.png"), second);
    EXPECT_EQ(readPng(dir.file("f.png")).rgba, second.rgba);
    int files = 0;
    for (const auto& entry : std::filesystem::directory_iterator(dir.path())) {
        ++files;
        EXPECT_EQ(entry.path().filename(), "f.png");
    }
    EXPECT_EQ(files, 1);
}

TEST(ImageTest, WritingIntoAMissingFolderThrowsRenderErrorNamingThePath) {
    test::TempDir dir;
    const std::string path = dir.file("no/such/folder/x.png");
    try {
        writePng(path, randomImage(2, 2, 3));
        ADD_FAILURE() << "no error";
    } catch (const RenderError& e) {
        EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
    }
}

TEST(ImageTest, ReadsRgb8AsOpaque) {
    test::TempDir dir;
    const png_byte rows[2 * 6] = {255, 0, 0, 0, 255, 0, 0, 0, 255, 10, 20, 30};
    writeRaw(dir.file("rgb.png"), {.width = 2, .height = 2, .rows = rows, .rowBytes = 6});
    const Image image = readPng(dir.file("rgb.png"));
    ASSERT_EQ(image.width, 2u);
    ASSERT_EQ(image.height, 2u);
    const float* p = image.pixel(1, 1);
    EXPECT_EQ(p[0], 10.0f / 255.0f);
    EXPECT_EQ(p[1], 20.0f / 255.0f);
    EXPECT_EQ(p[2], 30.0f / 255.0f);
    EXPECT_EQ(p[3], 1.0f);
    EXPECT_EQ(image.pixel(0, 0)[0], 1.0f);
    EXPECT_EQ(image.pixel(1, 0)[1], 1.0f);
}

TEST(ImageTest, InterlacedPngReadsLikeAPlainOne) {
    test::TempDir dir;
    std::vector<png_byte> rows(13 * 9 * 3);
    for (std::size_t i = 0; i < rows.size(); ++i)
        rows[i] = png_byte(i * 7);
    RawPng raw{.width = 13, .height = 9, .rows = rows.data(), .rowBytes = 13 * 3};
    writeRaw(dir.file("plain.png"), raw);
    raw.interlace = PNG_INTERLACE_ADAM7;
    writeRaw(dir.file("adam7.png"), raw);
    EXPECT_EQ(readPng(dir.file("adam7.png")).rgba, readPng(dir.file("plain.png")).rgba);
}

TEST(ImageTest, ReadsGrayAndGrayAlphaAsEqualRgb) {
    test::TempDir dir;
    const png_byte gray[3] = {0, 128, 255};
    writeRaw(
        dir.file("g.png"),
        {.width = 3, .height = 1, .colourType = PNG_COLOR_TYPE_GRAY, .rows = gray, .rowBytes = 3});
    const Image g = readPng(dir.file("g.png"));
    for (std::uint32_t x = 0; x < 3; ++x)
        for (int c = 0; c < 4; ++c)
            EXPECT_EQ(g.pixel(x, 0)[c], c == 3 ? 1.0f : float(gray[x]) / 255.0f);
    const png_byte grayAlpha[4] = {200, 50, 7, 255};
    writeRaw(dir.file("ga.png"), {.width = 2,
                                  .height = 1,
                                  .colourType = PNG_COLOR_TYPE_GRAY_ALPHA,
                                  .rows = grayAlpha,
                                  .rowBytes = 4});
    const Image ga = readPng(dir.file("ga.png"));
    EXPECT_EQ(ga.pixel(0, 0)[1], 200.0f / 255.0f);
    EXPECT_EQ(ga.pixel(0, 0)[3], 50.0f / 255.0f);
    EXPECT_EQ(ga.pixel(1, 0)[2], 7.0f / 255.0f);
    EXPECT_EQ(ga.pixel(1, 0)[3], 1.0f);
}

TEST(ImageTest, ReadsLowBitDepthGrayAsFullRange) {
    test::TempDir dir;
    const png_byte bits[1] = {0b10100000}; // 1-bit gray: 1, 0, 1, 0
    writeRaw(dir.file("g1.png"), {.width = 4,
                                  .height = 1,
                                  .colourType = PNG_COLOR_TYPE_GRAY,
                                  .bitDepth = 1,
                                  .rows = bits,
                                  .rowBytes = 1});
    const Image image = readPng(dir.file("g1.png"));
    for (std::uint32_t x = 0; x < 4; ++x)
        EXPECT_EQ(image.pixel(x, 0)[0], x % 2 ? 0.0f : 1.0f);
}

TEST(ImageTest, Reads16BitSamplesAsValueOver65535) {
    test::TempDir dir;
    const std::uint16_t values[8] = {0, 1, 32768, 65535, 12345, 65534, 256, 40000};
    png_byte rows[16];
    for (int i = 0; i < 8; ++i)
        putBigEndian16(rows + 2 * i, values[i]);
    writeRaw(dir.file("rgba16.png"), {.width = 2,
                                      .height = 1,
                                      .colourType = PNG_COLOR_TYPE_RGBA,
                                      .bitDepth = 16,
                                      .rows = rows,
                                      .rowBytes = 16});
    const Image rgba = readPng(dir.file("rgba16.png"));
    for (int i = 0; i < 8; ++i)
        EXPECT_EQ(rgba.rgba[i], float(values[i] / 65535.0)) << i;
    writeRaw(dir.file("g16.png"), {.width = 3,
                                   .height = 1,
                                   .colourType = PNG_COLOR_TYPE_GRAY,
                                   .bitDepth = 16,
                                   .rows = rows,
                                   .rowBytes = 6});
    const Image gray = readPng(dir.file("g16.png"));
    for (std::uint32_t x = 0; x < 3; ++x) {
        EXPECT_EQ(gray.pixel(x, 0)[2], float(values[x] / 65535.0)) << x;
        EXPECT_EQ(gray.pixel(x, 0)[3], 1.0f);
    }
}

TEST(ImageTest, ReadsPaletteWithTransparency) {
    test::TempDir dir;
    const png_color palette[3] = {{255, 0, 0}, {0, 128, 0}, {1, 2, 3}};
    const png_byte alpha[2] = {0, 100}; // entry 2 is opaque
    const png_byte indices[3] = {2, 1, 0};
    writeRaw(dir.file("p.png"), {.width = 3,
                                 .height = 1,
                                 .colourType = PNG_COLOR_TYPE_PALETTE,
                                 .rows = indices,
                                 .rowBytes = 3,
                                 .palette = palette,
                                 .paletteSize = 3,
                                 .paletteAlpha = alpha,
                                 .paletteAlphaSize = 2});
    const Image image = readPng(dir.file("p.png"));
    EXPECT_EQ(image.pixel(0, 0)[2], 3.0f / 255.0f);
    EXPECT_EQ(image.pixel(0, 0)[3], 1.0f);
    EXPECT_EQ(image.pixel(1, 0)[1], 128.0f / 255.0f);
    EXPECT_EQ(image.pixel(1, 0)[3], 100.0f / 255.0f);
    EXPECT_EQ(image.pixel(2, 0)[0], 1.0f);
    EXPECT_EQ(image.pixel(2, 0)[3], 0.0f);
}

TEST(ImageTest, MissingEmptyAndNonPngFilesThrowNamingTheFile) {
    test::TempDir dir;
    expectInputError(dir.file("missing.png"), "open");
    test::writeFile(dir.file("empty.png"), "");
    expectInputError(dir.file("empty.png"), "signature");
    test::writeFile(dir.file("gif.png"), "GIF89a\x01\x00\x01\x00 not a png at all");
    expectInputError(dir.file("gif.png"), "signature");
    test::writeFile(dir.file("short.png"), "\x89PNG");
    expectInputError(dir.file("short.png"), "signature");
}

TEST(ImageTest, TruncatedPngThrowsWhereverItIsCut) {
    test::TempDir dir;
    writePng(dir.file("full.png"), randomImage(40, 30, 4));
    const auto bytes = test::readFile(dir.file("full.png"));
    // In IHDR, just after IHDR, in the image data, and inside the final IEND chunk.
    for (std::size_t keep :
         {std::size_t(20), std::size_t(33), bytes.size() / 2, bytes.size() - 1}) {
        const std::string path = dir.file("cut" + std::to_string(keep) + ".png");
        test::writeFile(path, bytes.data(), keep);
        expectInputError(path, keep <= 33 ? "IHDR" : "data");
    }
}

TEST(ImageTest, CorruptImageDataThrows) {
    test::TempDir dir;
    writePng(dir.file("ok.png"), randomImage(40, 30, 5));
    auto bytes = test::readFile(dir.file("ok.png"));
    bytes[bytes.size() / 2] ^= 0x5a; // inside IDAT: the chunk CRC no longer matches
    test::writeFile(dir.file("bad.png"), bytes.data(), bytes.size());
    expectInputError(dir.file("bad.png"), "data");
}

TEST(ImageTest, HugeDeclaredSizeIsRejectedBeforeAllocating) {
    test::TempDir dir;
    writePng(dir.file("small.png"), randomImage(2, 2, 6));
    auto bytes = test::readFile(dir.file("small.png"));
    // IHDR data starts at 16 (8 signature + 4 length + 4 type); its CRC follows 13 bytes on.
    putBigEndian(bytes.data() + 16, 60000);
    putBigEndian(bytes.data() + 20, 60000);
    putBigEndian(bytes.data() + 29, crc32Of(bytes.data() + 12, 17));
    test::writeFile(dir.file("huge.png"), bytes.data(), bytes.size());
    expectInputError(dir.file("huge.png"), "IHDR");
}

} // namespace
} // namespace bc::render
