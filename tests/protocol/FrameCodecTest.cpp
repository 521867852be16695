// Frame image codecs (PROTOCOL.md "Frame images"): lossless round trips over a changing
// sequence, delta against plain zstd, JPEG error on a smooth image, and every bad input.
#include "protocol/FrameCodec.h"
#include "protocol/Error.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <memory>
#include <random>
#include <string>
#include <zstd.h>

namespace bc::protocol {
namespace {

using Bytes = std::vector<std::uint8_t>;

/// A raycaster-like premultiplied frame: transparent black around a textured, shaded slab
/// (smooth gradient plus a fixed fine-grained texture) and an opaque disc that moves with t.
Bytes renderLikeFrame(int w, int h, double t) {
    Bytes img(std::size_t(w) * h * 4, 0);
    std::mt19937 texture(7); // the same texture every frame: it belongs to the volume
    const double cx = w * (0.3 + 0.004 * t), cy = h * (0.5 + 0.002 * t), r = w * 0.15;
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            std::uint8_t* p = &img[(std::size_t(y) * w + x) * 4];
            const int grain = int(texture() % 7) - 3;
            if (x < w / 10 || x >= w * 9 / 10) continue; // empty space: transparent black
            const double a = 0.55 + 0.4 * y / h;         // straight alpha of the slab
            const double shade = 0.3 + 0.6 * x / w;
            auto premul = [&](double c) { return std::uint8_t(std::lround(c * a * 255)); };
            p[0] = std::uint8_t(std::clamp(premul(shade) + grain, 0, 255));
            p[1] = premul(0.8 * shade);
            p[2] = premul(0.5);
            p[3] = std::uint8_t(std::lround(a * 255));
            if (std::hypot(x - cx, y - cy) < r) p[0] = p[1] = p[2] = p[3] = 250;
        }
    return img;
}

/// A smooth opaque image (two gradients and a soft ripple) for the JPEG error bound.
Bytes smoothFrame(int w, int h) {
    Bytes img(std::size_t(w) * h * 4);
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            std::uint8_t* p = &img[(std::size_t(y) * w + x) * 4];
            p[0] = std::uint8_t(255.0 * x / (w - 1));
            p[1] = std::uint8_t(255.0 * y / (h - 1));
            p[2] = std::uint8_t(128 + 60 * std::sin(x * 0.05) * std::cos(y * 0.04));
            p[3] = 255;
        }
    return img;
}

std::span<const std::uint8_t> span(const Bytes& b) {
    return {b.data(), b.size()};
}

/// Runs f, expects a ProtocolError whose text contains every one of `parts`.
template <class F> void expectError(F&& f, std::initializer_list<const char*> parts) {
    try {
        f();
        ADD_FAILURE() << "no ProtocolError; expected one mentioning " << *parts.begin();
    } catch (const ProtocolError& e) {
        for (const char* part : parts)
            EXPECT_NE(std::string(e.what()).find(part), std::string::npos)
                << "'" << e.what() << "' does not mention '" << part << "'";
    }
}

/// A zstd frame header that declares `contentBytes` and holds nothing else.
Bytes forgedZstdHeader(std::uint64_t contentBytes) {
    // magic, descriptor (8-byte content size, single segment), content size.
    Bytes b = {0x28, 0xB5, 0x2F, 0xFD, 0xE0};
    for (int i = 0; i < 8; ++i)
        b.push_back(std::uint8_t(contentBytes >> (8 * i)));
    return b;
}

TEST(FrameCodecTest, LosslessCodecsRoundTripAChangingSequenceExactly) {
    for (Codec codec : {Codec::Raw, Codec::Zstd, Codec::ZstdDelta}) {
        FrameEncoder enc;
        FrameImageDecoder dec;
        const int sizes[][2] = {{96, 64}, {96, 64}, {96, 64}, {64, 96}, {64, 96}, {96, 64}};
        for (int i = 0; i < 6; ++i) {
            const int w = sizes[i][0], h = sizes[i][1];
            const Bytes img = renderLikeFrame(w, h, i * 3.0);
            auto e = enc.encode(span(img), w, h, codec, 0);
            const bool sizeChanged = i == 0 || sizes[i - 1][0] != w;
            EXPECT_EQ(e.keyframe, codec == Codec::ZstdDelta && sizeChanged) << "frame " << i;
            EXPECT_EQ(dec.decode(codec, w, h, e.keyframe, span(e.bytes)), img)
                << "codec " << int(codec) << " frame " << i;
        }
    }
}

TEST(FrameCodecTest, DeltaIsSmallerThanPlainZstdOnASlowlyChangingSequence) {
    FrameEncoder plain, delta;
    std::size_t plainBytes = 0, deltaBytes = 0;
    for (int i = 0; i < 10; ++i) {
        const Bytes img = renderLikeFrame(256, 256, i);
        auto p = plain.encode(span(img), 256, 256, Codec::Zstd, 0);
        auto d = delta.encode(span(img), 256, 256, Codec::ZstdDelta, 0);
        std::printf("frame %d: zstd %zu B (%.2f ms), delta %zu B (%.2f ms)%s\n", i, p.bytes.size(),
                    p.encodeMs, d.bytes.size(), d.encodeMs, d.keyframe ? " keyframe" : "");
        if (i == 0) continue;
        plainBytes += p.bytes.size();
        deltaBytes += d.bytes.size();
    }
    std::printf("frames 1..9: zstd %zu B, delta %zu B (%.1fx smaller)\n", plainBytes, deltaBytes,
                double(plainBytes) / double(deltaBytes));
    EXPECT_LT(deltaBytes * 3, plainBytes);
}

TEST(FrameCodecTest, JpegOfASmoothImageStaysWithinThreeLevelsOnAverage) {
    const int w = 256, h = 192;
    const Bytes img = smoothFrame(w, h);
    FrameEncoder enc;
    auto e = enc.encode(span(img), w, h, Codec::Jpeg, 85);
    EXPECT_FALSE(e.keyframe);
    const Bytes out = FrameImageDecoder().decode(Codec::Jpeg, w, h, false, span(e.bytes));
    ASSERT_EQ(out.size(), img.size());
    double absSum = 0, sqSum = 0;
    for (std::size_t i = 0; i < img.size(); ++i) {
        if (i % 4 == 3) {
            ASSERT_EQ(out[i], 255) << "alpha of pixel " << i / 4;
            continue;
        }
        const double d = double(out[i]) - double(img[i]);
        absSum += std::abs(d);
        sqSum += d * d;
    }
    const double samples = 3.0 * w * h;
    const double meanAbs = absSum / samples;
    const double psnr = 10 * std::log10(255.0 * 255.0 / (sqSum / samples));
    std::printf("JPEG q85 %dx%d: %zu B, mean abs error %.3f levels, PSNR %.1f dB, %.2f ms\n", w, h,
                e.bytes.size(), meanAbs, psnr, e.encodeMs);
    EXPECT_LT(meanAbs, 3.0);
}

TEST(FrameCodecTest, JpegDropsAlphaSoColourIsCompositedOverBlack) {
    Bytes img(16 * 16 * 4);
    for (std::size_t i = 0; i < img.size(); i += 4)
        img[i] = 100, img[i + 3] = 128;
    FrameEncoder enc;
    auto e = enc.encode(span(img), 16, 16, Codec::Jpeg, 95);
    const Bytes out = FrameImageDecoder().decode(Codec::Jpeg, 16, 16, false, span(e.bytes));
    EXPECT_NEAR(out[0], 100, 2);
    EXPECT_NEAR(out[1], 0, 2);
    EXPECT_EQ(out[3], 255);
}

TEST(FrameCodecTest, PngIsLosslessInColourAndDropsAlphaAsJpegDoes) {
    Bytes img = renderLikeFrame(97, 61, 2.0);
    for (std::size_t i = 3; i < img.size(); i += 4)
        img[i] = std::uint8_t(i * 7); // alpha that must not leak into the colour
    Bytes rgbOnly = img;
    for (std::size_t i = 3; i < rgbOnly.size(); i += 4)
        rgbOnly[i] = 255;
    FrameEncoder enc;
    for (std::uint8_t q : {0, 1}) { // fast, small
        auto e = enc.encode(span(img), 97, 61, Codec::Png, q);
        EXPECT_EQ(FrameImageDecoder().decode(Codec::Png, 97, 61, false, span(e.bytes)), rgbOnly)
            << "quality " << int(q);
        EXPECT_LT(e.bytes.size(), img.size()) << "quality " << int(q);
    }
    expectError([&] { enc.encode(span(img), 97, 61, Codec::Png, 2); }, {"PNG quality 2"});
}

TEST(FrameCodecTest, PngDecoderRefusesOtherSizesAndCorruptData) {
    const Bytes img = renderLikeFrame(32, 32, 0);
    auto e = FrameEncoder().encode(span(img), 32, 32, Codec::Png, 0);
    FrameImageDecoder dec;
    expectError([&] { dec.decode(Codec::Png, 32, 31, false, span(e.bytes)); },
                {"PNG frame", "32x32", "32x31"});
    expectError([&] { dec.decode(Codec::Png, 32, 32, false, span(img)); }, {"not a PNG image"});
    Bytes cut(e.bytes.begin(), e.bytes.begin() + e.bytes.size() / 2);
    expectError([&] { dec.decode(Codec::Png, 32, 32, false, span(cut)); }, {"PNG frame"});
    Bytes flipped = e.bytes;
    flipped[flipped.size() / 2] ^= 0xFF; // the IDAT checksum no longer holds
    expectError([&] { dec.decode(Codec::Png, 32, 32, false, span(flipped)); }, {"PNG frame"});
    // A header that claims a huge image is refused before anything is allocated for it.
    Bytes huge = e.bytes;
    huge[16] = 0x7F; // width's top byte: 0x7F000020 pixels
    expectError([&] { dec.decode(Codec::Png, 32, 32, false, span(huge)); }, {"PNG frame"});
}

TEST(FrameCodecTest, ResetDeltaMakesTheNextDeltaFrameAKeyframe) {
    FrameEncoder enc;
    FrameImageDecoder dec;
    for (int i = 0; i < 4; ++i) {
        if (i == 2) enc.resetDelta();
        const Bytes img = renderLikeFrame(64, 64, i);
        auto e = enc.encode(span(img), 64, 64, Codec::ZstdDelta, 0);
        EXPECT_EQ(e.keyframe, i == 0 || i == 2) << "frame " << i;
        EXPECT_EQ(dec.decode(Codec::ZstdDelta, 64, 64, e.keyframe, span(e.bytes)), img);
    }
}

TEST(FrameCodecTest, AnotherCodecEndsTheDeltaChainOnBothSides) {
    FrameEncoder enc;
    FrameImageDecoder dec;
    const Bytes a = renderLikeFrame(64, 64, 0), b = renderLikeFrame(64, 64, 1);
    auto first = enc.encode(span(a), 64, 64, Codec::ZstdDelta, 0);
    dec.decode(Codec::ZstdDelta, 64, 64, first.keyframe, span(first.bytes));
    auto jpeg = enc.encode(span(a), 64, 64, Codec::Jpeg, 0);
    dec.decode(Codec::Jpeg, 64, 64, false, span(jpeg.bytes));
    auto next = enc.encode(span(b), 64, 64, Codec::ZstdDelta, 0);
    EXPECT_TRUE(next.keyframe);
    // A (forged) non-keyframe after the JPEG frame has no base on the client side.
    expectError([&] { dec.decode(Codec::ZstdDelta, 64, 64, false, span(next.bytes)); },
                {"no previous delta frame"});
}

TEST(FrameCodecTest, QualityZeroAndExplicitLevelsAllDecode) {
    const Bytes img = renderLikeFrame(128, 128, 0);
    for (Codec codec : {Codec::Zstd, Codec::Jpeg})
        for (std::uint8_t q : {0, 1, 19, 90}) {
            if (codec == Codec::Zstd && q > 19) continue;
            FrameEncoder enc;
            auto e = enc.encode(span(img), 128, 128, codec, q);
            auto out = FrameImageDecoder().decode(codec, 128, 128, false, span(e.bytes));
            EXPECT_EQ(out.size(), img.size());
            if (codec == Codec::Zstd) {
                EXPECT_EQ(out, img) << "level " << int(q);
            }
        }
}

// ---- bad input on the encoding side ----

TEST(FrameCodecTest, EncoderRejectsBadSizesQualitiesAndCodecs) {
    FrameEncoder enc;
    const Bytes img = renderLikeFrame(32, 32, 0);
    expectError([&] { enc.encode(span(img), 0, 32, Codec::Raw, 0); }, {"0x32", "1..4096"});
    expectError([&] { enc.encode(span(img), 32, 0, Codec::Zstd, 0); }, {"32x0", "1..4096"});
    expectError([&] { enc.encode({}, 4097, 1, Codec::Raw, 0); }, {"4097x1"});
    expectError([&] { enc.encode(span(img), 32, 31, Codec::Zstd, 0); },
                {"4096 RGBA bytes", "32x31", "expected 3968"});
    expectError([&] { enc.encode(span(img), 32, 32, Codec::Zstd, 20); }, {"quality 20", "1..19"});
    expectError([&] { enc.encode(span(img), 32, 32, Codec::ZstdDelta, 20); }, {"zstd delta"});
    expectError([&] { enc.encode(span(img), 32, 32, Codec::Jpeg, 101); }, {"JPEG", "1..100"});
    expectError([&] { enc.encode(span(img), 32, 32, static_cast<Codec>(9), 0); },
                {"unknown codec 9"});
}

TEST(FrameCodecTest, EncoderErrorLeavesTheDeltaBaseAsItWas) {
    FrameEncoder enc;
    const Bytes img = renderLikeFrame(32, 32, 0);
    enc.encode(span(img), 32, 32, Codec::ZstdDelta, 0);
    EXPECT_THROW(enc.encode(span(img), 32, 32, Codec::ZstdDelta, 99), ProtocolError);
    EXPECT_FALSE(enc.encode(span(img), 32, 32, Codec::ZstdDelta, 0).keyframe);
}

// ---- bad input on the decoding side ----

class FrameDecodeErrorTest : public ::testing::Test {
  protected:
    Bytes img = renderLikeFrame(48, 32, 0);
    Bytes encode(Codec codec) { return FrameEncoder().encode(span(img), 48, 32, codec, 0).bytes; }
    FrameImageDecoder dec;
};

TEST_F(FrameDecodeErrorTest, TruncatedZstdFrame) {
    Bytes z = encode(Codec::Zstd);
    z.resize(z.size() / 2);
    expectError([&] { dec.decode(Codec::Zstd, 48, 32, false, span(z)); },
                {"zstd frame", "truncated or corrupt"});
    Bytes tiny = {0x28, 0xB5};
    expectError([&] { dec.decode(Codec::ZstdDelta, 48, 32, true, span(tiny)); },
                {"not a zstd frame"});
}

TEST_F(FrameDecodeErrorTest, DeclaredSizeOtherThanTheHeaderImage) {
    const Bytes z = encode(Codec::Zstd);
    expectError([&] { dec.decode(Codec::Zstd, 48, 64, false, span(z)); }, {"declares 6144"});
    expectError([&] { dec.decode(Codec::Zstd, 24, 32, false, span(z)); },
                {"declares 6144", "24x32", "3072"});
}

TEST_F(FrameDecodeErrorTest, HugeDeclaredSizeIsRejectedBeforeAllocating) {
    const Bytes forged = forgedZstdHeader(std::uint64_t{1} << 40);
    // Were the declared size allocated, this would be std::bad_alloc, not ProtocolError.
    expectError([&] { dec.decode(Codec::Zstd, 4096, 4096, false, span(forged)); },
                {"declares 1099511627776"});
    expectError([&] { dec.decode(Codec::ZstdDelta, 4096, 4096, true, span(forged)); },
                {"declares 1099511627776"});
}

TEST_F(FrameDecodeErrorTest, MissingContentSize) {
    std::unique_ptr<ZSTD_CCtx, decltype(&ZSTD_freeCCtx)> cctx(ZSTD_createCCtx(), ZSTD_freeCCtx);
    ZSTD_CCtx_setParameter(cctx.get(), ZSTD_c_contentSizeFlag, 0);
    Bytes z(ZSTD_compressBound(img.size()));
    z.resize(ZSTD_compress2(cctx.get(), z.data(), z.size(), img.data(), img.size()));
    expectError([&] { dec.decode(Codec::Zstd, 48, 32, false, span(z)); },
                {"does not declare its content size"});
}

TEST_F(FrameDecodeErrorTest, TrailingBytesAfterTheZstdFrame) {
    Bytes z = encode(Codec::Zstd);
    z.push_back(0);
    expectError([&] { dec.decode(Codec::Zstd, 48, 32, false, span(z)); },
                {"1 bytes after the zstd frame"});
}

TEST_F(FrameDecodeErrorTest, CorruptZstdBlock) {
    Bytes z = encode(Codec::Zstd);
    for (std::size_t i = 12; i < z.size(); i += 3)
        z[i] ^= 0x5A;
    EXPECT_THROW(dec.decode(Codec::Zstd, 48, 32, false, span(z)), ProtocolError);
}

TEST_F(FrameDecodeErrorTest, DeltaWithoutAMatchingBase) {
    FrameEncoder enc;
    const Bytes key = enc.encode(span(img), 48, 32, Codec::ZstdDelta, 0).bytes;
    const Bytes next = enc.encode(span(img), 48, 32, Codec::ZstdDelta, 0).bytes;
    expectError([&] { dec.decode(Codec::ZstdDelta, 48, 32, false, span(next)); },
                {"48x32", "not a keyframe", "no previous delta frame"});
    dec.decode(Codec::ZstdDelta, 48, 32, true, span(key));
    // The base is 48x32: a non-keyframe of another size cannot apply to it.
    const Bytes other = renderLikeFrame(32, 48, 0);
    const Bytes wrong = FrameEncoder().encode(span(other), 32, 48, Codec::Zstd, 0).bytes;
    expectError([&] { dec.decode(Codec::ZstdDelta, 32, 48, false, span(wrong)); },
                {"32x48", "no previous delta frame"});
}

TEST_F(FrameDecodeErrorTest, FailedDecodeDropsTheDeltaBase) {
    FrameEncoder enc;
    const Bytes key = enc.encode(span(img), 48, 32, Codec::ZstdDelta, 0).bytes;
    Bytes next = enc.encode(span(img), 48, 32, Codec::ZstdDelta, 0).bytes;
    dec.decode(Codec::ZstdDelta, 48, 32, true, span(key));
    Bytes cut(next.begin(), next.end() - 1);
    EXPECT_THROW(dec.decode(Codec::ZstdDelta, 48, 32, false, span(cut)), ProtocolError);
    expectError([&] { dec.decode(Codec::ZstdDelta, 48, 32, false, span(next)); },
                {"no previous delta frame"});
}

TEST_F(FrameDecodeErrorTest, JpegOfOtherDimensions) {
    const Bytes j = encode(Codec::Jpeg);
    expectError([&] { dec.decode(Codec::Jpeg, 32, 48, false, span(j)); },
                {"JPEG", "image is 48x32", "header says 32x48"});
}

TEST_F(FrameDecodeErrorTest, TruncatedJpeg) {
    Bytes j = encode(Codec::Jpeg);
    j.resize(j.size() * 2 / 3);
    expectError([&] { dec.decode(Codec::Jpeg, 48, 32, false, span(j)); }, {"JPEG frame"});
}

TEST_F(FrameDecodeErrorTest, GarbageBytes) {
    std::mt19937 rng(3);
    Bytes garbage(2000);
    for (auto& b : garbage)
        b = std::uint8_t(rng());
    expectError([&] { dec.decode(Codec::Zstd, 48, 32, false, span(garbage)); }, {"zstd frame"});
    expectError([&] { dec.decode(Codec::ZstdDelta, 48, 32, true, span(garbage)); },
                {"zstd delta frame"});
    expectError([&] { dec.decode(Codec::Jpeg, 48, 32, false, span(garbage)); },
                {"not a JPEG image"});
    expectError([&] { dec.decode(Codec::Raw, 48, 32, false, span(garbage)); },
                {"raw frame: 2000 bytes", "6144"});
    expectError([&] { dec.decode(Codec::Zstd, 48, 32, false, {}); }, {"not a zstd frame"});
    expectError([&] { dec.decode(Codec::Jpeg, 48, 32, false, {}); }, {"JPEG frame"});
}

TEST_F(FrameDecodeErrorTest, ZeroOrOversizedEdgesAndUnknownCodec) {
    const Bytes z = encode(Codec::Zstd);
    expectError([&] { dec.decode(Codec::Zstd, 0, 32, false, span(z)); }, {"0x32", "1..4096"});
    expectError([&] { dec.decode(Codec::Raw, 48, 0, false, span(z)); }, {"48x0"});
    expectError([&] { dec.decode(Codec::Jpeg, 5000, 32, false, span(z)); }, {"5000x32"});
    expectError([&] { dec.decode(static_cast<Codec>(5), 48, 32, false, span(z)); },
                {"unknown codec 5"});
}

} // namespace
} // namespace bc::protocol
