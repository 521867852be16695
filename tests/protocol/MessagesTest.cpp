// Golden bytes of every message type of protocol/PROTOCOL.md, written by hand from the tables
// there (not produced by the encoder): encode(struct) must give the bytes and decoding the
// bytes must give the struct back. Plus the encoder's refusals.
#include "protocol/Messages.h"
#include "protocol/Decoder.h"
#include "protocol/Error.h"

#include <gtest/gtest.h>

#include <cstdint>
#include <string>
#include <vector>

namespace bc::protocol {
namespace {

using Bytes = std::vector<std::uint8_t>;

/// Decodes exactly one message from `bytes` (which must hold nothing else).
Decoder::Result decodeOne(const Bytes& bytes) {
    Decoder decoder(kDefaultMaxServerPayloadBytes);
    decoder.feed(bytes);
    Decoder::Result r = decoder.next();
    EXPECT_EQ(r.status, Decoder::Status::Message) << r.error.message;
    EXPECT_EQ(decoder.next().status, Decoder::Status::NeedMore);
    EXPECT_EQ(decoder.buffered(), 0u);
    return r;
}

void expectGolden(const Message& m, std::uint32_t request, const Bytes& golden) {
    EXPECT_EQ(encode(m, request), golden);
    const Decoder::Result r = decodeOne(golden);
    EXPECT_EQ(r.request, request);
    EXPECT_TRUE(r.message == m);
    EXPECT_EQ(typeOf(r.message), typeOf(m));
}

// The golden arrays are laid out one field per line, as in PROTOCOL.md.
// clang-format off

// Bytes of the header: magic "BCST", version 1, then type, flags 0, length, request.
#define BC_HEADER(type, length, request)                                                       \
    0x42, 0x43, 0x53, 0x54, 0x01, type, 0x00, 0x00, (length) & 0xFF, ((length) >> 8) & 0xFF,   \
        0x00, 0x00, (request) & 0xFF, 0x00, 0x00, 0x00

TEST(Messages, HelloGoldenBytesRoundTrip) {
    Hello m;
    m.capabilities = kCapCpuRenderer | kCapGpuRenderer | kCapContinuous;
    m.codecs = {Codec::Raw, Codec::Zstd, Codec::ZstdDelta, Codec::Jpeg};
    m.software = "bc-0.1";
    const Bytes golden = {
        BC_HEADER(0x01, 21, 0),
        0x01, 0x00,                               // versionMin 1
        0x01, 0x00,                               // versionMax 1
        0x0E, 0x00, 0x00, 0x00,                   // capabilities: cpu, gpu, continuous
        0x04,                                     // codecCount
        0x00, 0x01, 0x02, 0x03,                   // raw, zstd, zstd delta, JPEG
        0x06, 0x00, 'b', 'c', '-', '0', '.', '1', // software
    };
    expectGolden(m, 0, golden);
}

TEST(Messages, AuthGoldenBytesRoundTrip) {
    const Bytes golden = {
        BC_HEADER(0x02, 8, 1),
        0x06, 0x00, 's', '3', 'c', 'r', 'e', 't', // token
    };
    expectGolden(Auth{"s3cret"}, 1, golden);
}

TEST(Messages, AuthOkGoldenBytesRoundTrip) {
    expectGolden(AuthOk{}, 1, Bytes{BC_HEADER(0x03, 0, 1)});
}

TEST(Messages, ListVolumesGoldenBytesRoundTrip) {
    expectGolden(ListVolumes{}, 2, Bytes{BC_HEADER(0x04, 0, 2)});
}

TEST(Messages, VolumeListGoldenBytesRoundTrip) {
    VolumeInfo v{"cthead", {256, 256, 113}, {1.0, 1.0, 2.0}, VoxelType::U16, 4, 0.0, 4095.0,
                 14811136};
    const Bytes golden = {
        BC_HEADER(0x05, 72, 2),
        0x01, 0x00,                                     // count 1
        0x06, 0x00, 'c', 't', 'h', 'e', 'a', 'd',       // name
        0x00, 0x01, 0x00, 0x00,                         // dims[0] 256
        0x00, 0x01, 0x00, 0x00,                         // dims[1] 256
        0x71, 0x00, 0x00, 0x00,                         // dims[2] 113
        0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0xF0, 0x3F, // spacingMm[0] 1.0
        0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0xF0, 0x3F, // spacingMm[1] 1.0
        0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x40, // spacingMm[2] 2.0
        0x01,                                           // voxelType u16
        0x04,                                           // levels
        0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, // valueMin 0.0
        0x00, 0x00, 0x00, 0x00, 0x00, 0xFE, 0xAF, 0x40, // valueMax 4095.0
        0x00, 0x00, 0xE2, 0x00, 0x00, 0x00, 0x00, 0x00, // storedBytes 14811136
    };
    expectGolden(VolumeList{{v}}, 2, golden);
}

TEST(Messages, EmptyVolumeListGoldenBytesRoundTrip) {
    expectGolden(VolumeList{}, 2, Bytes{BC_HEADER(0x05, 2, 2), 0x00, 0x00 /* count 0 */});
}

TEST(Messages, OpenVolumeGoldenBytesRoundTrip) {
    const Bytes golden = {
        BC_HEADER(0x06, 8, 3),
        0x06, 0x00, 'c', 't', 'h', 'e', 'a', 'd', // name
    };
    expectGolden(OpenVolume{"cthead"}, 3, golden);
}

TEST(Messages, VolumeOpenedGoldenBytesRoundTrip) {
    VolumeInfo v{"CT_AVM", {512, 512, 160}, {0.5, 0.5, 1.0}, VoxelType::I16, 5, -1024.0, 3071.0,
                 1u << 20};
    const Bytes golden = {
        BC_HEADER(0x07, 70, 3),
        0x06, 0x00, 'C', 'T', '_', 'A', 'V', 'M',       // name
        0x00, 0x02, 0x00, 0x00,                         // dims[0] 512
        0x00, 0x02, 0x00, 0x00,                         // dims[1] 512
        0xA0, 0x00, 0x00, 0x00,                         // dims[2] 160
        0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0xE0, 0x3F, // spacingMm[0] 0.5
        0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0xE0, 0x3F, // spacingMm[1] 0.5
        0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0xF0, 0x3F, // spacingMm[2] 1.0
        0x02,                                           // voxelType i16
        0x05,                                           // levels
        0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x90, 0xC0, // valueMin -1024.0
        0x00, 0x00, 0x00, 0x00, 0x00, 0xFE, 0xA7, 0x40, // valueMax 3071.0
        0x00, 0x00, 0x10, 0x00, 0x00, 0x00, 0x00, 0x00, // storedBytes 1 MiB
    };
    expectGolden(VolumeOpened{v}, 3, golden);
}

TEST(Messages, SetCameraGoldenBytesRoundTrip) {
    SetCamera m;
    m.cameraId = 7;
    m.eye = {0.0, -4.0, 0.0};
    m.target = {0.0, 0.0, 0.0};
    m.up = {0.0, 0.0, 1.0};
    m.fovYDeg = 30.0;
    m.orthographic = false;
    m.orthoHeight = 2.0;
    const Bytes golden = {
        BC_HEADER(0x08, 93, 4),
        0x07, 0x00, 0x00, 0x00,                         // cameraId 7
        0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, // eye.x 0
        0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x10, 0xC0, // eye.y -4
        0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, // eye.z 0
        0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, // target.x 0
        0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, // target.y 0
        0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, // target.z 0
        0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, // up.x 0
        0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, // up.y 0
        0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0xF0, 0x3F, // up.z 1
        0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x3E, 0x40, // fovYDeg 30
        0x00,                                           // orthographic false
        0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x40, // orthoHeight 2
    };
    expectGolden(m, 4, golden);
}

TEST(Messages, SetTransferFunctionPresetGoldenBytesRoundTrip) {
    SetTransferFunction m;
    m.kind = TfKind::Preset;
    m.shading = true;
    m.shadingSource = ShadingSource::Preset;
    m.preset = "ct-bone";
    const Bytes golden = {
        BC_HEADER(0x09, 12, 5),
        0x00,                                          // kind preset
        0x01,                                          // shading
        0x01,                                          // shadingSource: the preset's
        0x07, 0x00, 'c', 't', '-', 'b', 'o', 'n', 'e', // preset
    };
    expectGolden(m, 5, golden);
}

TEST(Messages, SetTransferFunctionPointsGoldenBytesRoundTrip) {
    SetTransferFunction m;
    m.kind = TfKind::Points;
    m.shading = false;
    m.shadingSource = ShadingSource::Message;
    m.points = {{Placement::Value, 100.0, {1.0f, 0.5f, 0.25f, 0.0f}},
                {Placement::Fraction, 0.5, {1.0f, 1.0f, 1.0f, 0.75f}}};
    const Bytes golden = {
        BC_HEADER(0x09, 55, 5),
        0x01,                                           // kind points
        0x00,                                           // shading off
        0x00,                                           // shadingSource: this message
        0x02, 0x00,                                     // count 2
        0x00,                                           // [0] placement value
        0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x59, 0x40, // [0] position 100
        0x00, 0x00, 0x80, 0x3F,                         // [0] r 1
        0x00, 0x00, 0x00, 0x3F,                         // [0] g 0.5
        0x00, 0x00, 0x80, 0x3E,                         // [0] b 0.25
        0x00, 0x00, 0x00, 0x00,                         // [0] a 0
        0x01,                                           // [1] placement fraction
        0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0xE0, 0x3F, // [1] position 0.5
        0x00, 0x00, 0x80, 0x3F,                         // [1] r 1
        0x00, 0x00, 0x80, 0x3F,                         // [1] g 1
        0x00, 0x00, 0x80, 0x3F,                         // [1] b 1
        0x00, 0x00, 0x40, 0x3F,                         // [1] a 0.75
    };
    expectGolden(m, 5, golden);
}

TEST(Messages, SetRenderOptionsGoldenBytesRoundTrip) {
    RenderOptions o;
    o.width = 640;
    o.height = 480;
    o.stepVoxels = 0.5f;
    o.techniques = kTechAll;
    o.ertThreshold = 0.99f;
    o.renderer = Renderer::CpuRaycaster;
    o.quality = Quality::Refined;
    o.codec = Codec::Jpeg;
    o.codecQuality = 90;
    o.level = kLevelAutomatic;
    const Bytes golden = {
        BC_HEADER(0x0A, 24, 6),
        0x80, 0x02,             // width 640
        0xE0, 0x01,             // height 480
        0x00, 0x00, 0x00, 0x3F, // stepVoxels 0.5
        0x7F, 0x00, 0x00, 0x00, // techniques: all seven
        0xA4, 0x70, 0x7D, 0x3F, // ertThreshold 0.99f
        0x01,                   // renderer: CPU raycaster
        0x01,                   // quality: always refined
        0x03,                   // codec: JPEG
        0x5A,                   // codecQuality 90
        0xFF,                   // level: automatic
        0x00,                   // reserved
        0x00, 0x00,             // reserved
    };
    expectGolden(SetRenderOptions{o}, 6, golden);
}

// Renderer 5 (auto, since 2026-12-03) is the default: the server picks the GPU raycaster on a
// hardware GPU and the CPU raycaster otherwise.
TEST(Messages, SetRenderOptionsDefaultsToTheAutoRendererGoldenBytesRoundTrip) {
    const Bytes golden = {
        BC_HEADER(0x0A, 24, 8),
        0x00, 0x01,             // width 256
        0x00, 0x01,             // height 256
        0x00, 0x00, 0x80, 0x3F, // stepVoxels 1
        0x7F, 0x00, 0x00, 0x00, // techniques: all seven
        0xA4, 0x70, 0x7D, 0x3F, // ertThreshold 0.99f
        0x05,                   // renderer: auto
        0x00,                   // quality: adaptive
        0x01,                   // codec: zstd
        0x00,                   // codecQuality: the codec's default
        0xFF,                   // level: automatic
        0x00,                   // refinedCodec: none
        0x00, 0x00,             // flags
    };
    expectGolden(SetRenderOptions{}, 8, golden);
    EXPECT_EQ(RenderOptions{}.renderer, Renderer::Auto);
}

TEST(Messages, RequestFrameGoldenBytesRoundTrip) {
    expectGolden(RequestFrame{FrameMode::ContinuousOn}, 7,
                 Bytes{BC_HEADER(0x0B, 1, 7), 0x01 /* mode: continuous on */});
}

TEST(Messages, FrameGoldenBytesRoundTrip) {
    Frame m;
    FrameHeader& h = m.header;
    h.frameId = 42;
    h.cameraId = 7;
    h.width = 2;
    h.height = 1;
    h.codec = Codec::Raw;
    h.level = 1;
    h.refined = true;
    h.keyframe = false;
    h.queueMs = 0.5f;
    h.renderMs = 12.5f;
    h.encodeMs = 0.25f;
    h.samples = 1000;
    h.bricksDrawn = 3;
    h.bricksSkipped = 5;
    h.bytesUploaded = 65536;
    h.occlusionUsed = true;
    h.cached = true;
    h.scale = 3;
    h.estimatedPsnrDb = 41;
    m.image = {0xFF, 0x00, 0x00, 0xFF, 0x00, 0x80, 0x00, 0x80};
    const Bytes golden = {
        BC_HEADER(0x0C, 68, 7),
        0x2A, 0x00, 0x00, 0x00,                         // frameId 42
        0x07, 0x00, 0x00, 0x00,                         // cameraId 7
        0x02, 0x00,                                     // width 2
        0x01, 0x00,                                     // height 1
        0x00,                                           // codec raw
        0x01,                                           // level 1
        0x01,                                           // refined
        0x00,                                           // keyframe
        0x00, 0x00, 0x00, 0x3F,                         // queueMs 0.5
        0x00, 0x00, 0x48, 0x41,                         // renderMs 12.5
        0x00, 0x00, 0x80, 0x3E,                         // encodeMs 0.25
        0xE8, 0x03, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, // samples 1000
        0x03, 0x00, 0x00, 0x00,                         // bricksDrawn 3
        0x05, 0x00, 0x00, 0x00,                         // bricksSkipped 5
        0x00, 0x00, 0x01, 0x00, 0x00, 0x00, 0x00, 0x00, // bytesUploaded 65536
        0x01,                                           // occlusionUsed
        0x01,                                           // cached
        0x03, 0x29,                                     // scale 3, estimatedPsnrDb 41
        0x08, 0x00, 0x00, 0x00,                         // imageBytes 8
        0xFF, 0x00, 0x00, 0xFF, 0x00, 0x80, 0x00, 0x80, // 2 x 1 RGBA pixels
    };
    expectGolden(m, 7, golden);
}

TEST(Messages, RequestStatsGoldenBytesRoundTrip) {
    expectGolden(RequestStats{}, 8, Bytes{BC_HEADER(0x0D, 0, 8)});
}

TEST(Messages, StatsGoldenBytesRoundTrip) {
    Stats m{{{"frames", 12.0}, {"hits", 0.75}}};
    const Bytes golden = {
        BC_HEADER(0x0E, 32, 8),
        0x02, 0x00,                                     // count 2
        0x06, 0x00, 'f', 'r', 'a', 'm', 'e', 's',       // [0] name
        0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x28, 0x40, // [0] value 12
        0x04, 0x00, 'h', 'i', 't', 's',                 // [1] name
        0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0xE8, 0x3F, // [1] value 0.75
    };
    expectGolden(m, 8, golden);
}

TEST(Messages, ErrorGoldenBytesRoundTrip) {
    Error m{ErrorCode::OutOfRange, false, 0x0A, "bad width"};
    const Bytes golden = {
        BC_HEADER(0x0F, 15, 6),
        0x06, 0x00,                                              // code OutOfRange
        0x00,                                                    // fatal false
        0x0A,                                                    // offendingType SetRenderOptions
        0x09, 0x00, 'b', 'a', 'd', ' ', 'w', 'i', 'd', 't', 'h', // message
    };
    expectGolden(m, 6, golden);
}

TEST(Messages, SetRenderOptionsWithARefinedCodecGoldenBytesRoundTrip) {
    RenderOptions o;
    o.codec = Codec::Jpeg;
    o.codecQuality = 80;
    Bytes golden = encode(SetRenderOptions{o}, 9);
    EXPECT_EQ(golden[kHeaderBytes + 21], 0x00) << "no refined codec: as codec";
    golden[kHeaderBytes + 21] = 0x05; // refinedCodec: PNG (4) + 1
    o.refinedCodec = Codec::Png;
    expectGolden(SetRenderOptions{o}, 9, golden);
    o.refinedCodec = Codec::Raw; // 0 + 1: raw is a refined codec too, not "none"
    EXPECT_EQ(encode(SetRenderOptions{o}, 9)[kHeaderBytes + 21], 0x01);
    o.flags = kFlagUnscaledInteractive;
    golden[kHeaderBytes + 21] = 0x01;
    golden[kHeaderBytes + 22] = 0x01; // flags: unscaled interactive
    expectGolden(SetRenderOptions{o}, 9, golden);
}

TEST(Messages, RequestHistogramGoldenBytesRoundTrip) {
    expectGolden(RequestHistogram{}, 4, Bytes{BC_HEADER(0x11, 0, 4)});
}

TEST(Messages, HistogramGoldenBytesRoundTrip) {
    Histogram m{-1024.0, 3071.0, {7, 0x0102030405}};
    const Bytes golden = {
        BC_HEADER(0x12, 34, 4),
        0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x90, 0xC0, // valueMin -1024
        0x00, 0x00, 0x00, 0x00, 0x00, 0xFE, 0xA7, 0x40, // valueMax 3071
        0x02, 0x00,                                     // bins 2
        0x07, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, // [0] 7
        0x05, 0x04, 0x03, 0x02, 0x01, 0x00, 0x00, 0x00, // [1] 0x0102030405
    };
    expectGolden(m, 4, golden);
}

TEST(Messages, SetFrameBudgetGoldenBytesRoundTrip) {
    expectGolden(SetFrameBudget{66, 40}, 4,
                 Bytes{BC_HEADER(0x13, 3, 4), 0x42, 0x00 /* interactiveMs 66 */, 0x28 /* 40 dB */});
}

TEST(Messages, SetModeAndClipGoldenBytesRoundTrip) {
    SetModeAndClip m;
    m.mode = BlendMode::Maximum;
    m.cropped = true;
    m.cropMin = {0, 10, 20};
    m.cropMax = {100, 110, 120};
    m.planes = {ClipPlane{{1, 0, 0}, -50}};
    expectGolden(m, 7,
                 Bytes{BC_HEADER(0x14, 91, 7),
                       0x01 /* mode: maximum */,
                       0, 0, 0, 0, 0, 0, 0, 0 /* isoValue 0 */,
                       0x01 /* cropped */,
                       0, 0, 0, 0, 0, 0, 0, 0 /* cropMin 0 */,
                       0, 0, 0, 0, 0, 0, 0x24, 0x40 /* 10 */,
                       0, 0, 0, 0, 0, 0, 0x34, 0x40 /* 20 */,
                       0, 0, 0, 0, 0, 0, 0x59, 0x40 /* cropMax 100 */,
                       0, 0, 0, 0, 0, 0x80, 0x5b, 0x40 /* 110 */,
                       0, 0, 0, 0, 0, 0, 0x5e, 0x40 /* 120 */,
                       0x01 /* planeCount */,
                       0, 0, 0, 0, 0, 0, 0xf0, 0x3f /* normal 1 */,
                       0, 0, 0, 0, 0, 0, 0, 0 /* 0 */,
                       0, 0, 0, 0, 0, 0, 0, 0 /* 0 */,
                       0, 0, 0, 0, 0, 0, 0x49, 0xc0 /* offset -50 */});
    Bytes plain{BC_HEADER(0x14, 59, 1)};
    plain.resize(plain.size() + 59, 0); // composite, iso 0, no crop, no planes
    expectGolden(SetModeAndClip{}, 1, plain);
    // The same cut capped in composite: the optional cutFlags byte at the end.
    SetModeAndClip capped = m;
    capped.mode = BlendMode::Composite;
    capped.cap = true;
    Bytes cappedBytes = encode(m, 7);
    cappedBytes[8] = 92;                 // the payload's length
    cappedBytes[kHeaderBytes] = 0x00;    // mode: composite
    cappedBytes.push_back(0x01);         // cutFlags: cap
    expectGolden(capped, 7, cappedBytes);
}

TEST(Messages, ByeGoldenBytesRoundTrip) {
    expectGolden(Bye{ByeReason::IdleTimeout}, 0,
                 Bytes{BC_HEADER(0x10, 2, 0), 0x02, 0x00 /* reason: idle timeout */});
}

// clang-format on

TEST(Messages, RequestIdIsCarriedInTheHeader) {
    const Bytes bytes = encode(ListVolumes{}, 0x01020304);
    ASSERT_EQ(bytes.size(), kHeaderBytes);
    EXPECT_EQ(Bytes(bytes.begin() + 12, bytes.end()), (Bytes{0x04, 0x03, 0x02, 0x01}));
}

TEST(Messages, EncodeAppendsToTheBuffer) {
    Bytes out = {0xAA};
    encode(AuthOk{}, 1, out);
    encode(RequestStats{}, 2, out);
    ASSERT_EQ(out.size(), 1 + 2 * kHeaderBytes);
    EXPECT_EQ(out[0], 0xAA);
    EXPECT_EQ(out[1 + 5], 0x03);
    EXPECT_EQ(out[1 + kHeaderBytes + 5], 0x0D);
}

TEST(Messages, TypeOfNamesEveryAlternative) {
    EXPECT_EQ(typeOf(Hello{}), MessageType::Hello);
    EXPECT_EQ(typeOf(SetCamera{}), MessageType::SetCamera);
    EXPECT_EQ(typeOf(Frame{}), MessageType::Frame);
    EXPECT_EQ(typeOf(Bye{}), MessageType::Bye);
    EXPECT_EQ(typeOf(Histogram{}), MessageType::Histogram);
    EXPECT_EQ(typeOf(SetFrameBudget{}), MessageType::SetFrameBudget);
    EXPECT_STREQ(typeName(0x13), "SetFrameBudget");
    EXPECT_EQ(typeOf(SetModeAndClip{}), MessageType::SetModeAndClip);
    EXPECT_STREQ(typeName(0x14), "SetModeAndClip");
    EXPECT_STREQ(typeName(0x11), "RequestHistogram");
    EXPECT_STREQ(typeName(0x0A), "SetRenderOptions");
    EXPECT_STREQ(typeName(0x42), "unknown");
    EXPECT_STREQ(errorName(6), "OutOfRange");
    EXPECT_STREQ(errorName(99), "unknown");
}

// ---- what the encoder refuses ------------------------------------------------------------

/// encode(m) throws ProtocolError whose text contains `field`, and leaves the buffer alone.
void expectRefused(const Message& m, const std::string& field) {
    Bytes out = {1, 2, 3};
    try {
        encode(m, 1, out);
        ADD_FAILURE() << "encoded a message naming " << field;
    } catch (const ProtocolError& e) {
        EXPECT_NE(std::string(e.what()).find(field), std::string::npos) << e.what();
    }
    EXPECT_EQ(out, (Bytes{1, 2, 3}));
}

TEST(Messages, EncodeRefusesStringsOverTheirLimits) {
    expectRefused(Auth{std::string(kMaxTokenBytes + 1, 't')}, "Auth.token");
    expectRefused(Auth{""}, "Auth.token");
    expectRefused(OpenVolume{std::string(kMaxVolumeNameBytes + 1, 'v')}, "OpenVolume.name");
    expectRefused(OpenVolume{"../etc"}, "OpenVolume.name");
    expectRefused(Error{ErrorCode::Internal, true, 0, std::string(1025, 'e')}, "Error.message");
    expectRefused(Stats{{{std::string(129, 's'), 1.0}}}, "Stats.counters[0].name");
    Hello hello;
    hello.software = std::string(65, 's');
    expectRefused(hello, "Hello.software");
}

TEST(Messages, EncodeRefusesInvalidUtf8) {
    expectRefused(Error{ErrorCode::Internal, true, 0, "caf\xC3"}, "Error.message");
}

TEST(Messages, EncodeRefusesTooManyOrNoPoints) {
    SetTransferFunction tf;
    tf.kind = TfKind::Points;
    tf.shadingSource = ShadingSource::Message;
    tf.points.assign(kMaxTfPoints + 1, TfPoint{});
    expectRefused(tf, "SetTransferFunction.points");
    tf.points.clear();
    expectRefused(tf, "SetTransferFunction.points");
    tf.points.assign(1, TfPoint{});
    tf.preset = "ct-bone";
    expectRefused(tf, "SetTransferFunction.preset");
}

TEST(Messages, EncodeRefusesImageEdgesOutsideTheLimit) {
    SetRenderOptions o;
    o.options.width = 0;
    expectRefused(o, "SetRenderOptions.width");
    o.options.width = 4097;
    expectRefused(o, "SetRenderOptions.width");
    Frame f;
    f.header.width = 1;
    f.header.height = 0;
    expectRefused(f, "Frame.height");
}

TEST(Messages, EncodeRefusesARawFrameOfTheWrongSize) {
    Frame f;
    f.header.width = 2;
    f.header.height = 2;
    f.image.assign(15, 0);
    expectRefused(f, "Frame.imageBytes");
}

TEST(Messages, EncodeRefusesAFrameOverTheServerPayloadLimit) {
    Frame f;
    f.header.width = 4096;
    f.header.height = 4096;
    f.header.codec = Codec::Zstd;
    f.image.assign(kDefaultMaxServerPayloadBytes - kFrameHeaderBytes + 1, 0);
    expectRefused(f, "Frame.imageBytes");
    f.image.pop_back();
    EXPECT_EQ(encode(f).size(), kHeaderBytes + kDefaultMaxServerPayloadBytes);
}

TEST(Messages, EncodeRefusesMoreThanTheLimitOfListEntries) {
    VolumeList list;
    list.volumes.assign(kMaxVolumes + 1, VolumeInfo{"v", {1, 1, 1}, {1, 1, 1}});
    expectRefused(list, "VolumeList.volumes");
    Stats stats;
    stats.counters.assign(kMaxStats + 1, {"n", 0.0});
    expectRefused(stats, "Stats.counters");
    Hello hello;
    hello.codecs.assign(kMaxCodecs + 1, Codec::Raw);
    expectRefused(hello, "Hello.codecs");
}

TEST(Messages, EncodeRefusesAnInvalidCamera) {
    SetCamera c;
    c.eye = {0, 0, 5};
    expectRefused(c, "SetCamera.up"); // looking down the z axis with up = +z
    c.up = {0, 1, 0};
    c.fovYDeg = 180;
    expectRefused(c, "SetCamera.fovYDeg");
}

TEST(Messages, FitTextCutsAtACharacterBoundaryAndReplacesInvalidBytes) {
    EXPECT_EQ(fitText("abc", 10), "abc");
    EXPECT_EQ(fitText("abcdef", 3), "abc");
    EXPECT_EQ(fitText("ab\xC3\xA9", 3), "ab"); // never half of "é"
    EXPECT_EQ(fitText("ab\xC3\xA9", 4), "ab\xC3\xA9");
    EXPECT_EQ(fitText("a\xFF"
                      "b",
                      10),
              "a?b");
    EXPECT_EQ(fitText("\xED\xA0\x80", 10), "???"); // a surrogate is not UTF-8
    const std::string long_ = fitText(std::string(5000, 'x'), kMaxErrorMessageBytes);
    EXPECT_NO_THROW(encode(Error{ErrorCode::Internal, true, 0, long_}));
}

} // namespace
} // namespace bc::protocol
