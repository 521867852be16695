// Every bad input of protocol/PROTOCOL.md, and the incremental decoder's framing: partial
// feeds, several messages per feed, non-fatal errors that skip one message, fatal errors that
// stick, bounded buffering.
#include "protocol/Decoder.h"
#include "protocol/Error.h"
#include "protocol/Messages.h"

#include <gtest/gtest.h>

#include <bit>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <optional>
#include <string>
#include <vector>

namespace bc::protocol {
namespace {

using Bytes = std::vector<std::uint8_t>;
using Status = Decoder::Status;

constexpr double kNan = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

/// A message with a hand-made header: type, flags and length as given.
Bytes wire(std::uint8_t type, const Bytes& payload, std::uint32_t request = 9,
           std::uint16_t flags = 0, std::optional<std::uint32_t> claimed = std::nullopt) {
    const std::uint32_t length = claimed.value_or(static_cast<std::uint32_t>(payload.size()));
    Bytes b = {0x42, 0x43, 0x53, 0x54, kVersion, type};
    for (int i = 0; i < 2; ++i)
        b.push_back(static_cast<std::uint8_t>(flags >> (8 * i)));
    for (int i = 0; i < 4; ++i)
        b.push_back(static_cast<std::uint8_t>(length >> (8 * i)));
    for (int i = 0; i < 4; ++i)
        b.push_back(static_cast<std::uint8_t>(request >> (8 * i)));
    b.insert(b.end(), payload.begin(), payload.end());
    return b;
}

/// `m` encoded with request 9, then patched: `value` written at payload offset `at`.
template <typename T> Bytes patched(const Message& m, std::size_t at, T value) {
    Bytes b = encode(m, 9);
    const auto raw = std::bit_cast<std::array<std::uint8_t, sizeof(T)>>(value);
    std::memcpy(b.data() + kHeaderBytes + at, raw.data(), raw.size());
    return b;
}

/// The payload of `m` as encoded.
Bytes payloadOf(const Message& m) {
    Bytes b = encode(m);
    return Bytes(b.begin() + kHeaderBytes, b.end());
}

/// Decodes `bytes` (one message) and expects a non-fatal error of `code` whose message
/// contains `text`; the decoder must go on (not failed, nothing left buffered).
void expectRejected(const Bytes& bytes, ErrorCode code, const std::string& text) {
    Decoder decoder(kDefaultMaxServerPayloadBytes);
    decoder.feed(bytes);
    const Decoder::Result r = decoder.next();
    ASSERT_EQ(r.status, Status::Error) << "accepted; expected " << text;
    EXPECT_EQ(r.error.code, code) << r.error.message;
    EXPECT_FALSE(r.error.fatal);
    EXPECT_EQ(r.error.type, bytes[5]);
    EXPECT_EQ(r.error.request, 9u);
    EXPECT_EQ(r.request, 9u);
    EXPECT_NE(r.error.message.find(text), std::string::npos) << r.error.message;
    EXPECT_LE(r.error.message.size(), kMaxErrorMessageBytes);
    EXPECT_FALSE(decoder.failed());
    EXPECT_EQ(decoder.buffered(), 0u);
    EXPECT_EQ(decoder.next().status, Status::NeedMore);
}

void expectAccepted(const Bytes& bytes) {
    Decoder decoder(kDefaultMaxServerPayloadBytes);
    decoder.feed(bytes);
    const Decoder::Result r = decoder.next();
    EXPECT_EQ(r.status, Status::Message) << r.error.message;
}

/// Feeds `bytes` and expects the fatal error `code`.
void expectFatal(Decoder& decoder, const Bytes& bytes, ErrorCode code) {
    decoder.feed(bytes);
    const Decoder::Result r = decoder.next();
    ASSERT_EQ(r.status, Status::Error);
    EXPECT_EQ(r.error.code, code) << r.error.message;
    EXPECT_TRUE(r.error.fatal);
    EXPECT_TRUE(decoder.failed());
    EXPECT_EQ(decoder.buffered(), 0u);
}

VolumeInfo sampleVolume() {
    return VolumeInfo{"cthead", {256, 256, 113}, {1, 1, 2}, VoxelType::U16, 4, 0, 4095, 1000};
}

SetCamera sampleCamera() {
    SetCamera c;
    c.eye = {0, -4, 0};
    return c;
}

SetTransferFunction samplePoints() {
    SetTransferFunction tf;
    tf.kind = TfKind::Points;
    tf.shadingSource = ShadingSource::Message;
    tf.points = {{Placement::Value, 10, {1, 1, 1, 0.5f}}, {Placement::Percentile, 90, {}}};
    return tf;
}

Frame sampleFrame() {
    Frame f;
    f.header.width = 2;
    f.header.height = 2;
    f.image.assign(16, 0x7F);
    return f;
}

std::vector<Message> sampleMessages() {
    Hello hello;
    hello.codecs = {Codec::Zstd};
    hello.software = "test";
    return {hello,
            Auth{"token"},
            AuthOk{},
            ListVolumes{},
            VolumeList{{sampleVolume(), sampleVolume()}},
            OpenVolume{"cthead"},
            VolumeOpened{sampleVolume()},
            sampleCamera(),
            samplePoints(),
            SetRenderOptions{},
            RequestFrame{FrameMode::ContinuousOff},
            sampleFrame(),
            RequestStats{},
            Stats{{{"a", 1}, {"b", kInf}}},
            Error{ErrorCode::Busy, true, 0, "busy"},
            Bye{}};
}

// ---- framing ------------------------------------------------------------------------------

TEST(Decoder, LengthOverTheLimitIsFatalTooLargeFromTheHeaderAlone) {
    Decoder decoder(kMaxClientPayloadBytes);
    const Bytes header = wire(0x08, {}, 9, 0, kMaxClientPayloadBytes + 1);
    ASSERT_EQ(header.size(), kHeaderBytes);
    expectFatal(decoder, header, ErrorCode::TooLarge);
    EXPECT_EQ(decoder.next().error.request, 9u);
}

TEST(Decoder, LengthAllOnesIsFatalTooLargeFromTheHeaderAlone) {
    Decoder decoder(kDefaultMaxServerPayloadBytes);
    const Bytes header = wire(0x0C, {}, 9, 0, 0xFFFFFFFF);
    ASSERT_EQ(header.size(), kHeaderBytes);
    expectFatal(decoder, header, ErrorCode::TooLarge);
    EXPECT_EQ(decoder.next().error.message,
              "header.length: 4294967295 bytes is over the limit of 83886080");
}

TEST(Decoder, LengthAtTheLimitIsAccepted) {
    Decoder decoder(64);
    decoder.feed(wire(0x42, Bytes(64, 0)));
    EXPECT_EQ(decoder.next().error.code, ErrorCode::UnknownType);
    EXPECT_FALSE(decoder.failed());
}

TEST(Decoder, BadMagicIsFatal) {
    Decoder decoder(kMaxClientPayloadBytes);
    Bytes b = encode(AuthOk{});
    b[3] = 'X';
    expectFatal(decoder, b, ErrorCode::BadMagic);
    Decoder http(kMaxClientPayloadBytes);
    const std::string get = "GET / HTTP/1.1\r\nHost: x\r\n\r\n";
    expectFatal(http, Bytes(get.begin(), get.end()), ErrorCode::BadMagic);
}

TEST(Decoder, BadVersionIsFatalUnsupportedVersion) {
    for (std::uint8_t version : {0, 2, 255}) {
        Decoder decoder(kMaxClientPayloadBytes);
        Bytes b = encode(ListVolumes{});
        b[4] = version;
        expectFatal(decoder, b, ErrorCode::UnsupportedVersion);
    }
}

TEST(Decoder, FatalErrorSticksAndDropsLaterBytes) {
    Decoder decoder(kMaxClientPayloadBytes);
    Bytes b = encode(ListVolumes{});
    b[0] = 0;
    expectFatal(decoder, b, ErrorCode::BadMagic);
    const DecodeError first = decoder.next().error;
    decoder.feed(encode(ListVolumes{}));
    EXPECT_EQ(decoder.buffered(), 0u);
    const Decoder::Result again = decoder.next();
    EXPECT_EQ(again.status, Status::Error);
    EXPECT_EQ(again.error, first);
    EXPECT_FALSE(decoder.midMessage());
}

TEST(Decoder, FatalHeaderStopsBufferingItsPayload) {
    Decoder decoder(16);
    Bytes b = wire(0x0C, Bytes(1000, 0));
    decoder.feed(b);
    EXPECT_TRUE(decoder.failed());
    EXPECT_EQ(decoder.buffered(), 0u);
    EXPECT_EQ(decoder.next().error.code, ErrorCode::TooLarge);
}

TEST(Decoder, UnknownTypeIsSkippedAndTheNextMessageDecodes) {
    Decoder decoder(kMaxClientPayloadBytes);
    decoder.feed(wire(0x42, {1, 2, 3, 4, 5}, 77));
    decoder.feed(wire(0x00, {}, 78));
    decoder.feed(encode(OpenVolume{"cthead"}, 79));
    Decoder::Result r = decoder.next();
    ASSERT_EQ(r.status, Status::Error);
    EXPECT_EQ(r.error.code, ErrorCode::UnknownType);
    EXPECT_FALSE(r.error.fatal);
    EXPECT_EQ(r.error.type, 0x42);
    EXPECT_EQ(r.request, 77u);
    r = decoder.next();
    ASSERT_EQ(r.status, Status::Error);
    EXPECT_EQ(r.error.code, ErrorCode::UnknownType);
    EXPECT_EQ(r.request, 78u);
    r = decoder.next();
    ASSERT_EQ(r.status, Status::Message);
    EXPECT_EQ(r.request, 79u);
    EXPECT_TRUE(r.message == Message(OpenVolume{"cthead"}));
    EXPECT_FALSE(decoder.failed());
}

TEST(Decoder, BadPayloadIsNonFatalAndTheNextMessageDecodes) {
    Decoder decoder(kMaxClientPayloadBytes);
    decoder.feed(wire(0x0B, {7}, 1));
    decoder.feed(encode(RequestFrame{}, 2));
    EXPECT_EQ(decoder.next().error.code, ErrorCode::OutOfRange);
    const Decoder::Result r = decoder.next();
    EXPECT_EQ(r.status, Status::Message);
    EXPECT_EQ(r.request, 2u);
}

TEST(Decoder, TruncatedMessageNeedsMoreThenCompletes) {
    Decoder decoder(kMaxClientPayloadBytes);
    EXPECT_FALSE(decoder.midMessage());
    const Bytes b = encode(sampleCamera(), 5);
    decoder.feed(std::span(b).first(b.size() - 1));
    EXPECT_EQ(decoder.next().status, Status::NeedMore);
    EXPECT_TRUE(decoder.midMessage());
    EXPECT_EQ(decoder.buffered(), b.size() - 1);
    decoder.feed(std::span(b).last(1));
    EXPECT_FALSE(decoder.midMessage()); // complete, waiting to be taken
    const Decoder::Result r = decoder.next();
    ASSERT_EQ(r.status, Status::Message);
    EXPECT_TRUE(r.message == Message(sampleCamera()));
    EXPECT_FALSE(decoder.midMessage());
    EXPECT_EQ(decoder.buffered(), 0u);
}

TEST(Decoder, PartialHeaderIsMidMessage) {
    Decoder decoder(kMaxClientPayloadBytes);
    const Bytes b = encode(AuthOk{});
    decoder.feed(std::span(b).first(3));
    EXPECT_TRUE(decoder.midMessage());
    EXPECT_EQ(decoder.next().status, Status::NeedMore);
}

TEST(Decoder, ByteAtATimeGivesTheSameMessagesAsOneFeed) {
    Bytes stream;
    std::uint32_t request = 100;
    for (const Message& m : sampleMessages())
        encode(m, request++, stream);

    Decoder whole(kDefaultMaxServerPayloadBytes);
    whole.feed(stream);
    Decoder trickle(kDefaultMaxServerPayloadBytes);
    std::size_t decoded = 0;
    for (std::uint8_t byte : stream) {
        trickle.feed(std::span(&byte, 1));
        for (Decoder::Result r = trickle.next(); r.status != Status::NeedMore; r = trickle.next()) {
            ASSERT_EQ(r.status, Status::Message) << r.error.message;
            const Decoder::Result w = whole.next();
            ASSERT_EQ(w.status, Status::Message) << w.error.message;
            EXPECT_EQ(r.request, w.request);
            EXPECT_TRUE(r.message == w.message) << typeName(std::uint8_t(typeOf(r.message)));
            EXPECT_TRUE(r.message == sampleMessages()[decoded]);
            ++decoded;
        }
    }
    EXPECT_EQ(decoded, sampleMessages().size());
    EXPECT_EQ(whole.next().status, Status::NeedMore);
    EXPECT_EQ(trickle.buffered(), 0u);
}

TEST(Decoder, SeveralMessagesInOneFeedComeOutInOrder) {
    Bytes stream;
    encode(Auth{"a"}, 1, stream);
    encode(ListVolumes{}, 2, stream);
    encode(OpenVolume{"v"}, 3, stream);
    const Bytes next = encode(RequestFrame{}, 4);
    stream.insert(stream.end(), next.begin(), next.begin() + 5); // and a part of a fourth
    Decoder decoder(kMaxClientPayloadBytes);
    decoder.feed(stream);
    for (std::uint32_t request = 1; request <= 3; ++request) {
        const Decoder::Result r = decoder.next();
        ASSERT_EQ(r.status, Status::Message);
        EXPECT_EQ(r.request, request);
    }
    EXPECT_EQ(decoder.next().status, Status::NeedMore);
    EXPECT_TRUE(decoder.midMessage());
    EXPECT_EQ(decoder.buffered(), 5u);
    decoder.feed(std::span(next).subspan(5));
    EXPECT_EQ(decoder.next().request, 4u);
}

TEST(Decoder, LargeFrameInSmallFeedsStaysWithinItsSize) {
    Frame f;
    f.header.width = 1024;
    f.header.height = 1024;
    f.image.assign(1024u * 1024u * 4u, 0);
    for (std::size_t i = 0; i < f.image.size(); i += 4093)
        f.image[i] = static_cast<std::uint8_t>(i);
    const Bytes b = encode(f, 3);
    Decoder decoder(kDefaultMaxServerPayloadBytes);
    Decoder::Result r;
    for (std::size_t at = 0; at < b.size(); at += 1000) {
        decoder.feed(std::span(b).subspan(at, std::min<std::size_t>(1000, b.size() - at)));
        EXPECT_LE(decoder.buffered(), b.size());
        r = decoder.next();
        if (r.status != Status::NeedMore) break;
    }
    ASSERT_EQ(r.status, Status::Message);
    EXPECT_TRUE(r.message == Message(f));
    EXPECT_EQ(decoder.buffered(), 0u);
}

TEST(Decoder, DecodePayloadReportsZeroRequest) {
    const auto decoded = decodePayload(0x0B, 0, Bytes{9});
    ASSERT_TRUE(std::holds_alternative<DecodeError>(decoded));
    EXPECT_EQ(std::get<DecodeError>(decoded).request, 0u);
    EXPECT_EQ(std::get<DecodeError>(decoded).message, "RequestFrame.mode: 9 is not one of 0..2");
}

// ---- payload sizes, flags, strings, counts --------------------------------------------------

TEST(DecoderRejects, PayloadShorterOrLongerThanItsFixedSize) {
    for (const Message& m :
         {Message(sampleCamera()), Message(SetRenderOptions{}), Message(RequestFrame{}),
          Message(Bye{}), Message(AuthOk{}), Message(ListVolumes{}), Message(RequestStats{})}) {
        const auto type = std::uint8_t(typeOf(m));
        Bytes p = payloadOf(m);
        Bytes longer = p;
        longer.push_back(0);
        expectRejected(wire(type, longer), ErrorCode::BadPayload, "expected");
        if (p.empty()) continue;
        p.pop_back();
        expectRejected(wire(type, p), ErrorCode::BadPayload, "expected");
    }
}

TEST(DecoderRejects, VariablePayloadsWithBytesLeftOverOrCutShort) {
    for (const Message& m : sampleMessages()) {
        const auto type = std::uint8_t(typeOf(m));
        if (std::holds_alternative<Frame>(m)) continue; // the image takes the rest
        Bytes p = payloadOf(m);
        Bytes longer = p;
        longer.push_back(0);
        expectRejected(wire(type, longer), ErrorCode::BadPayload, typeName(type));
        if (p.empty()) continue;
        p.pop_back();
        expectRejected(wire(type, p), ErrorCode::BadPayload, typeName(type));
    }
}

TEST(DecoderRejects, FlagsTheTypeDoesNotDefine) {
    for (const Message& m : sampleMessages()) {
        const auto type = std::uint8_t(typeOf(m));
        for (std::uint16_t flags : {0x0001, 0x8000})
            expectRejected(wire(type, payloadOf(m), 9, flags), ErrorCode::BadPayload, ".flags");
    }
}

TEST(DecoderRejects, StringWhoseDeclaredLengthExceedsThePayload) {
    expectRejected(wire(0x02, {10, 0, 'a', 'b', 'c'}), ErrorCode::BadPayload, "Auth.token");
    expectRejected(wire(0x06, {0xFF, 0xFF, 'a'}), ErrorCode::BadPayload, "OpenVolume.name");
    expectRejected(wire(0x0F, {5, 0, 0, 0, 40, 0, 'x'}), ErrorCode::BadPayload, "Error.message");
    Bytes hello = payloadOf(Hello{});
    hello[hello.size() - 2] = 1; // software length 1, no bytes
    expectRejected(wire(0x01, hello), ErrorCode::BadPayload, "Hello.software");
}

TEST(DecoderRejects, StringsOverTheirLimits) {
    const auto str = [](std::size_t n) {
        Bytes b(2 + n, 'a');
        b[0] = std::uint8_t(n);
        b[1] = std::uint8_t(n >> 8);
        return b;
    };
    expectRejected(wire(0x02, str(kMaxTokenBytes + 1)), ErrorCode::OutOfRange, "Auth.token");
    expectRejected(wire(0x02, str(0)), ErrorCode::OutOfRange, "Auth.token");
    expectAccepted(wire(0x02, str(kMaxTokenBytes)));
    Bytes error = {1, 0, 1, 0};
    const Bytes message = str(kMaxErrorMessageBytes + 1);
    error.insert(error.end(), message.begin(), message.end());
    expectRejected(wire(0x0F, error), ErrorCode::OutOfRange, "Error.message");
    Bytes tf = {0, 1, 1};
    const Bytes preset = str(kMaxPresetBytes + 1);
    tf.insert(tf.end(), preset.begin(), preset.end());
    expectRejected(wire(0x09, tf), ErrorCode::OutOfRange, "SetTransferFunction.preset");
}

TEST(DecoderRejects, StringsThatAreNotUtf8) {
    expectRejected(wire(0x02, {2, 0, 0xC0, 0xAF}), ErrorCode::BadPayload, "Auth.token");
    expectRejected(wire(0x0F, {5, 0, 0, 0, 1, 0, 0x80}), ErrorCode::BadPayload, "Error.message");
    expectAccepted(wire(0x02, {2, 0, 0xC3, 0xA9}));
}

TEST(DecoderRejects, VolumeNamesOutsideTheCatalogRule) {
    const auto open = [](const std::string& name) {
        Bytes b = {std::uint8_t(name.size()), std::uint8_t(name.size() >> 8)};
        b.insert(b.end(), name.begin(), name.end());
        return wire(0x06, b);
    };
    expectRejected(open("../x"), ErrorCode::OutOfRange,
                   "OpenVolume.name: '../x' has a character outside A-Z a-z 0-9 . _ -");
    expectRejected(open(""), ErrorCode::OutOfRange, "OpenVolume.name");
    expectRejected(open(std::string(kMaxVolumeNameBytes + 1, 'a')), ErrorCode::OutOfRange,
                   "OpenVolume.name");
    expectRejected(open(".hidden"), ErrorCode::OutOfRange, "starts with '.'");
    expectRejected(open("a/b"), ErrorCode::OutOfRange, "OpenVolume.name");
    expectRejected(open("a b"), ErrorCode::OutOfRange, "OpenVolume.name");
    expectRejected(open(std::string("a\0b", 3)), ErrorCode::OutOfRange, "'a\\x00b'");
    expectAccepted(open(std::string(kMaxVolumeNameBytes, 'a')));
    expectAccepted(open("CT_AVM-2.0.x"));
    VolumeInfo v = sampleVolume();
    v.name = "ok";
    Bytes opened = payloadOf(VolumeOpened{v});
    opened[2] = '.';
    expectRejected(wire(0x07, opened), ErrorCode::OutOfRange, "VolumeOpened.info.name");
    Bytes list = payloadOf(VolumeList{{v, v}});
    list[2 + 66 + 3] = '/';
    expectRejected(wire(0x05, list), ErrorCode::OutOfRange, "VolumeList.volumes[1].name");
}

TEST(DecoderRejects, CountsOverTheirLimits) {
    Bytes hello = {1, 0, 1, 0, 0, 0, 0, 0, std::uint8_t(kMaxCodecs + 1)};
    hello.resize(hello.size() + kMaxCodecs + 1, 0);
    hello.insert(hello.end(), {0, 0});
    expectRejected(wire(0x01, hello), ErrorCode::OutOfRange, "Hello.codecs");
    expectRejected(wire(0x05, {0x01, 0x04}), ErrorCode::OutOfRange, "VolumeList.volumes");
    expectRejected(wire(0x0E, {0x01, 0x10}), ErrorCode::OutOfRange, "Stats.counters");
    expectRejected(wire(0x09, {1, 0, 0, 0x01, 0x01}), ErrorCode::OutOfRange,
                   "SetTransferFunction.points");
    expectRejected(wire(0x09, {1, 0, 0, 0, 0}), ErrorCode::OutOfRange,
                   "SetTransferFunction.points: 0 is outside 1..256");
}

TEST(DecoderRejects, CountsExceedingThePayload) {
    expectRejected(wire(0x01, {1, 0, 1, 0, 0, 0, 0, 0, 5, 0, 0}), ErrorCode::BadPayload,
                   "Hello.codecs");
    Bytes list = payloadOf(VolumeList{{sampleVolume()}});
    list[0] = 2;
    expectRejected(wire(0x05, list), ErrorCode::BadPayload, "VolumeList.volumes");
    expectRejected(wire(0x0E, {0xFF, 0x0F}), ErrorCode::BadPayload, "Stats.counters");
    Bytes tf = payloadOf(samplePoints());
    tf[3] = 3;
    expectRejected(wire(0x09, tf), ErrorCode::BadPayload, "SetTransferFunction.points");
}

TEST(DecoderAccepts, ListsAtTheirLimits) {
    VolumeList list;
    list.volumes.assign(kMaxVolumes, sampleVolume());
    expectAccepted(encode(list, 9));
    Stats stats;
    stats.counters.assign(kMaxStats, {std::string(kMaxStatNameBytes, 'n'), 1.0});
    expectAccepted(encode(stats, 9));
    SetTransferFunction tf = samplePoints();
    tf.points.assign(kMaxTfPoints, tf.points[0]);
    const Bytes b = encode(tf, 9);
    EXPECT_LE(b.size() - kHeaderBytes, kMaxClientPayloadBytes);
    expectAccepted(b);
}

// ---- enums and bools ----------------------------------------------------------------------

TEST(DecoderRejects, OutOfRangeValueOfEveryEnumField) {
    Hello hello;
    hello.codecs = {Codec::Raw};
    expectRejected(patched<std::uint8_t>(hello, 9, 5), ErrorCode::OutOfRange, "Hello.codecs[0]");
    VolumeInfo v = sampleVolume(); // name "cthead": fixed fields start at offset 8
    expectRejected(patched<std::uint8_t>(VolumeOpened{v}, 8 + 36, 4), ErrorCode::OutOfRange,
                   "VolumeOpened.info.voxelType");
    expectRejected(patched<std::uint8_t>(SetTransferFunction{}, 0, 2), ErrorCode::OutOfRange,
                   "SetTransferFunction.kind");
    expectRejected(patched<std::uint8_t>(SetTransferFunction{}, 2, 2), ErrorCode::OutOfRange,
                   "SetTransferFunction.shadingSource");
    expectRejected(patched<std::uint8_t>(samplePoints(), 5, 3), ErrorCode::OutOfRange,
                   "SetTransferFunction.points[0].placement");
    expectRejected(patched<std::uint8_t>(SetRenderOptions{}, 16, 6), ErrorCode::OutOfRange,
                   "SetRenderOptions.renderer");
    expectRejected(patched<std::uint8_t>(SetRenderOptions{}, 17, 3), ErrorCode::OutOfRange,
                   "SetRenderOptions.quality");
    expectRejected(patched<std::uint8_t>(SetRenderOptions{}, 18, 5), ErrorCode::OutOfRange,
                   "SetRenderOptions.codec");
    expectRejected(patched<std::uint8_t>(SetRenderOptions{}, 21, 6), ErrorCode::OutOfRange,
                   "SetRenderOptions.refinedCodec");
    expectRejected(patched<std::uint8_t>(RequestFrame{}, 0, 3), ErrorCode::OutOfRange,
                   "RequestFrame.mode");
    expectRejected(patched<std::uint8_t>(sampleFrame(), 12, 5), ErrorCode::OutOfRange,
                   "Frame.codec");
    expectRejected(patched<std::uint16_t>(Error{}, 0, 0), ErrorCode::OutOfRange, "Error.code");
    expectRejected(patched<std::uint16_t>(Error{}, 0, 18), ErrorCode::OutOfRange, "Error.code");
    expectRejected(patched<std::uint16_t>(Bye{}, 0, 3), ErrorCode::OutOfRange, "Bye.reason");
}

TEST(DecoderRejects, PresetShadingSourceWithPoints) {
    expectRejected(patched<std::uint8_t>(samplePoints(), 2, 1), ErrorCode::OutOfRange,
                   "SetTransferFunction.shadingSource");
}

TEST(DecoderRejects, BoolByteTwo) {
    expectRejected(patched<std::uint8_t>(sampleCamera(), 84, 2), ErrorCode::OutOfRange,
                   "SetCamera.orthographic: 2 is not a bool");
    expectRejected(patched<std::uint8_t>(SetTransferFunction{}, 1, 2), ErrorCode::OutOfRange,
                   "SetTransferFunction.shading");
    expectRejected(patched<std::uint8_t>(sampleFrame(), 14, 2), ErrorCode::OutOfRange,
                   "Frame.refined");
    expectRejected(patched<std::uint8_t>(sampleFrame(), 15, 2), ErrorCode::OutOfRange,
                   "Frame.keyframe");
    expectRejected(patched<std::uint8_t>(sampleFrame(), 52, 2), ErrorCode::OutOfRange,
                   "Frame.occlusionUsed");
    expectRejected(patched<std::uint8_t>(sampleFrame(), 53, 2), ErrorCode::OutOfRange,
                   "Frame.cached");
    expectRejected(patched<std::uint8_t>(Error{}, 2, 2), ErrorCode::OutOfRange, "Error.fatal");
}

TEST(DecoderRejects, ReservedBytesThatAreNotZero) {
    expectRejected(patched<std::uint8_t>(SetRenderOptions{}, 22, 2), ErrorCode::OutOfRange,
                   "SetRenderOptions.flags");
    expectRejected(patched<std::uint8_t>(SetRenderOptions{}, 23, 1), ErrorCode::OutOfRange,
                   "SetRenderOptions.flags");
}

TEST(DecoderRejects, FrameScaleAndEstimateOutOfRange) {
    // The two bytes were reserved until 2026-12-06: 0 stays valid (older servers).
    for (const std::uint8_t scale : {0, 1, 8})
        expectAccepted(patched<std::uint8_t>(sampleFrame(), 54, scale));
    expectRejected(patched<std::uint8_t>(sampleFrame(), 54, 9), ErrorCode::OutOfRange,
                   "Frame.scale");
    for (const std::uint8_t db : {0, 20, 50})
        expectAccepted(patched<std::uint8_t>(sampleFrame(), 55, db));
    expectRejected(patched<std::uint8_t>(sampleFrame(), 55, 51), ErrorCode::OutOfRange,
                   "Frame.estimatedPsnrDb");
}

TEST(DecoderRejects, FrameBudgetsOutOfRange) {
    for (const auto& [ms, db] : {std::pair<int, int>{0, 0}, {1, 20}, {10000, 50}, {66, 40}})
        expectAccepted(encode(SetFrameBudget{std::uint16_t(ms), std::uint8_t(db)}, 9));
    expectRejected(patched<std::uint16_t>(SetFrameBudget{}, 0, 10001), ErrorCode::OutOfRange,
                   "SetFrameBudget.interactiveMs");
    for (const std::uint8_t db : {1, 19, 51, 255})
        expectRejected(patched<std::uint8_t>(SetFrameBudget{}, 2, db), ErrorCode::OutOfRange,
                       "SetFrameBudget.restPsnrDb");
    EXPECT_THROW(encode(SetFrameBudget{0, 60}), ProtocolError);
}

// ---- SetModeAndClip ------------------------------------------------------------------------

/// `b` with `value` written at payload offset `at`.
template <typename T> Bytes patchedBytes(Bytes b, std::size_t at, T value) {
    const auto raw = std::bit_cast<std::array<std::uint8_t, sizeof(T)>>(value);
    std::memcpy(b.data() + kHeaderBytes + at, raw.data(), raw.size());
    return b;
}

/// A MIP cropped to a box, with two planes: offsets are mode 0, isoValue 1, cropped 9, cropMin
/// 10, cropMax 34, planeCount 58, planes from 59 (32 bytes each: normal, offset).
SetModeAndClip sampleModeAndClip() {
    SetModeAndClip m;
    m.mode = BlendMode::Maximum;
    m.cropped = true;
    m.cropMin = {0, 0, 0};
    m.cropMax = {10, 20, 30};
    m.planes = {ClipPlane{{1, 0, 0}, -5}, ClipPlane{{0, -1, 1}, 2}};
    return m;
}

TEST(DecoderRejects, ModesAndClipsOutOfRange) {
    expectAccepted(encode(sampleModeAndClip(), 3));
    expectAccepted(encode(SetModeAndClip{}, 3));
    expectRejected(patched<std::uint8_t>(sampleModeAndClip(), 0, 5), ErrorCode::OutOfRange,
                   "SetModeAndClip.mode");
    for (double bad : {kNan, kInf, -kInf}) {
        expectRejected(patched(sampleModeAndClip(), 1, bad), ErrorCode::OutOfRange,
                       "SetModeAndClip.isoValue");
        expectRejected(patched(sampleModeAndClip(), 18, bad), ErrorCode::OutOfRange,
                       "SetModeAndClip.cropMin[1]");
        expectRejected(patched(sampleModeAndClip(), 59 + 8, bad), ErrorCode::OutOfRange,
                       "SetModeAndClip.planes[0].normal[1]");
        expectRejected(patched(sampleModeAndClip(), 59 + 32 + 24, bad), ErrorCode::OutOfRange,
                       "SetModeAndClip.planes[1].offset");
    }
    // An empty or inverted box; a box sent while not cropped; a zero normal.
    expectRejected(patched(sampleModeAndClip(), 42, 0.0), ErrorCode::OutOfRange,
                   "SetModeAndClip.cropMax");
    expectRejected(patched(sampleModeAndClip(), 42, -1.0), ErrorCode::OutOfRange,
                   "SetModeAndClip.cropMax");
    expectRejected(patched<std::uint8_t>(sampleModeAndClip(), 9, 0), ErrorCode::OutOfRange,
                   "SetModeAndClip.cropMin");
    expectRejected(patched<std::uint8_t>(sampleModeAndClip(), 9, 2), ErrorCode::OutOfRange,
                   "SetModeAndClip.cropped");
    Bytes zero = patched(sampleModeAndClip(), 59 + 32, 0.0);
    zero = patchedBytes(zero, 59 + 32 + 8, 0.0);
    zero = patchedBytes(zero, 59 + 32 + 16, 0.0);
    expectRejected(zero, ErrorCode::OutOfRange, "SetModeAndClip.planes[1].normal");
    // Seven planes; a count the payload does not hold.
    SetModeAndClip seven = sampleModeAndClip();
    seven.planes.assign(6, ClipPlane{});
    Bytes tooMany = encode(seven, 9);
    tooMany[kHeaderBytes + 58] = 7;
    tooMany.insert(tooMany.end(), 32, 0);
    const auto length = std::uint32_t(tooMany.size() - kHeaderBytes);
    std::memcpy(tooMany.data() + 8, &length, 4); // little-endian host, as the header is
    expectRejected(tooMany, ErrorCode::OutOfRange, "SetModeAndClip.planes");
    expectRejected(patched<std::uint8_t>(sampleModeAndClip(), 58, 3), ErrorCode::BadPayload,
                   "SetModeAndClip.planes");
    SetModeAndClip nanIso;
    nanIso.mode = BlendMode::Isosurface;
    nanIso.isoValue = kNan;
    EXPECT_THROW(encode(nanIso), ProtocolError);
}

TEST(DecoderRejects, CutFlagsOutOfRange) {
    SetModeAndClip capped = sampleModeAndClip();
    capped.mode = BlendMode::Composite;
    capped.cap = true;
    const Bytes bytes = encode(capped, 9); // the request id expectRejected() expects
    ASSERT_EQ(bytes.size(), encode(sampleModeAndClip(), 9).size() + 1); // cutFlags, last
    expectAccepted(bytes);
    const std::size_t flagsAt = bytes.size() - kHeaderBytes - 1;
    // An unknown bit; a cap in a mode that draws no surface (every projection).
    expectRejected(patchedBytes<std::uint8_t>(bytes, flagsAt, 3), ErrorCode::OutOfRange,
                   "SetModeAndClip.cutFlags");
    for (std::uint8_t mode : {1, 2, 3})
        expectRejected(patchedBytes<std::uint8_t>(bytes, 0, mode), ErrorCode::OutOfRange,
                       "SetModeAndClip.cutFlags");
    expectAccepted(patchedBytes<std::uint8_t>(bytes, 0, 4)); // an isosurface caps
    // A flags byte of 0 is refused: no flags leave the byte out (one encoding per message).
    expectRejected(patchedBytes<std::uint8_t>(bytes, flagsAt, 0), ErrorCode::OutOfRange,
                   "SetModeAndClip.cutFlags");
    SetModeAndClip projection = sampleModeAndClip();
    projection.cap = true;
    EXPECT_THROW(encode(projection), ProtocolError);
}

// ---- SetCamera ----------------------------------------------------------------------------

TEST(DecoderRejects, NanAndInfiniteCameraValues) {
    const std::pair<std::size_t, const char*> fields[] = {
        {4, "SetCamera.eye[0]"},     {20, "SetCamera.eye[2]"},     {28, "SetCamera.target[0]"},
        {44, "SetCamera.target[2]"}, {52, "SetCamera.up[0]"},      {68, "SetCamera.up[2]"},
        {76, "SetCamera.fovYDeg"},   {85, "SetCamera.orthoHeight"}};
    for (const auto& [at, field] : fields)
        for (double bad : {kNan, kInf, -kInf})
            expectRejected(patched(sampleCamera(), at, bad), ErrorCode::OutOfRange,
                           std::string(field) + ": ");
}

/// A SetCamera written field by field, so that invalid cameras (which encode refuses) can be
/// sent.
Bytes cameraWire(const SetCamera& c) {
    Bytes p;
    const auto put = [&p](auto v) {
        const auto raw = std::bit_cast<std::array<std::uint8_t, sizeof(v)>>(v);
        p.insert(p.end(), raw.begin(), raw.end());
    };
    put(c.cameraId);
    for (const auto* v : {&c.eye, &c.target, &c.up})
        for (double x : *v)
            put(x);
    put(c.fovYDeg);
    put(std::uint8_t(c.orthographic));
    put(c.orthoHeight);
    return wire(0x08, p);
}

TEST(DecoderRejects, EyeEqualToTarget) {
    SetCamera c = sampleCamera();
    c.target = c.eye;
    expectRejected(cameraWire(c), ErrorCode::OutOfRange, "SetCamera.eye: (0, -4, 0) equals target");
}

TEST(DecoderRejects, UpZeroOrParallelToTheView) {
    SetCamera c = sampleCamera(); // looking along +y
    c.up = {0, 2, 0};
    expectRejected(cameraWire(c), ErrorCode::OutOfRange,
                   "SetCamera.up: (0, 2, 0) is zero or parallel to the view direction");
    c.up = {0, -1, 1e-12};
    expectRejected(cameraWire(c), ErrorCode::OutOfRange, "SetCamera.up");
    c.up = {0, 0, 0};
    expectRejected(cameraWire(c), ErrorCode::OutOfRange, "SetCamera.up");
    c.up = {0, 1, 1};
    expectAccepted(cameraWire(c));
}

TEST(DecoderRejects, EyeAndTargetTooFarApartToSubtract) {
    SetCamera c = sampleCamera();
    c.eye = {-1e308, 0, 0};
    c.target = {1e308, 0, 0};
    expectRejected(cameraWire(c), ErrorCode::OutOfRange, "SetCamera.target");
}

TEST(DecoderRejects, FieldOfViewOutsideZeroTo180) {
    SetCamera c = sampleCamera();
    for (double fov : {0.0, -1.0, 180.0, 500.0}) {
        c.fovYDeg = fov;
        expectRejected(cameraWire(c), ErrorCode::OutOfRange, "SetCamera.fovYDeg");
    }
    c.fovYDeg = 179.9;
    expectAccepted(cameraWire(c));
}

TEST(DecoderRejects, OrthoHeightNotPositiveWhenOrthographic) {
    SetCamera c = sampleCamera();
    c.orthographic = true;
    for (double h : {0.0, -2.0}) {
        c.orthoHeight = h;
        expectRejected(cameraWire(c), ErrorCode::OutOfRange,
                       "SetCamera.orthoHeight: " + std::string(h == 0 ? "0" : "-2") +
                           " is outside (0, inf)");
    }
    c.orthographic = false; // unused, so any finite value goes
    expectAccepted(cameraWire(c));
}

// ---- SetTransferFunction ------------------------------------------------------------------

TEST(DecoderRejects, TransferFunctionPointValuesOutOfRange) {
    expectRejected(patched(samplePoints(), 6, kNan), ErrorCode::OutOfRange,
                   "SetTransferFunction.points[0].position: nan is not finite");
    expectRejected(patched(samplePoints(), 6, kInf), ErrorCode::OutOfRange,
                   "SetTransferFunction.points[0].position");
    expectRejected(patched(samplePoints(), 25 + 6, 100.5), ErrorCode::OutOfRange,
                   "SetTransferFunction.points[1].position: 100.5 is outside [0, 100]");
    expectRejected(patched(samplePoints(), 25 + 6, -1.0), ErrorCode::OutOfRange,
                   "SetTransferFunction.points[1].position");
    expectRejected(patched(samplePoints(), 14, 1.5f), ErrorCode::OutOfRange,
                   "SetTransferFunction.points[0].rgba[0]: 1.5 is outside [0, 1]");
    expectRejected(patched(samplePoints(), 26, -0.5f), ErrorCode::OutOfRange,
                   "SetTransferFunction.points[0].rgba[3]");
    expectRejected(patched(samplePoints(), 18, std::numeric_limits<float>::quiet_NaN()),
                   ErrorCode::OutOfRange, "SetTransferFunction.points[0].rgba[1]");
    expectAccepted(patched(samplePoints(), 6, -1e9)); // a value may be anything finite
}

// ---- SetRenderOptions ---------------------------------------------------------------------

TEST(DecoderRejects, ViewportZeroOrOver4096) {
    expectRejected(patched<std::uint16_t>(SetRenderOptions{}, 0, 0), ErrorCode::OutOfRange,
                   "SetRenderOptions.width: 0 is outside 1..4096");
    expectRejected(patched<std::uint16_t>(SetRenderOptions{}, 2, 0), ErrorCode::OutOfRange,
                   "SetRenderOptions.height: 0 is outside 1..4096");
    expectRejected(patched<std::uint32_t>(SetRenderOptions{}, 0, 0xFFFFFFFF), ErrorCode::OutOfRange,
                   "SetRenderOptions.width: 65535 is outside 1..4096");
    expectRejected(patched<std::uint16_t>(SetRenderOptions{}, 2, 4097), ErrorCode::OutOfRange,
                   "SetRenderOptions.height");
    expectAccepted(patched<std::uint32_t>(SetRenderOptions{}, 0, 0x10001000));
    expectRejected(patched<std::uint16_t>(sampleFrame(), 8, 0), ErrorCode::OutOfRange,
                   "Frame.width");
    expectRejected(patched<std::uint32_t>(sampleFrame(), 8, 0xFFFFFFFF), ErrorCode::OutOfRange,
                   "Frame.width: 65535");
}

TEST(DecoderRejects, StepOutsideZeroTo64) {
    for (float step : {0.0f, -1.0f, 64.5f, std::numeric_limits<float>::quiet_NaN(),
                       std::numeric_limits<float>::infinity()})
        expectRejected(patched(SetRenderOptions{}, 4, step), ErrorCode::OutOfRange,
                       "SetRenderOptions.stepVoxels");
    expectAccepted(patched(SetRenderOptions{}, 4, 64.0f));
}

TEST(DecoderRejects, EarlyTerminationThresholdOutsideZeroToOne) {
    for (float t : {0.0f, 1.01f, std::numeric_limits<float>::quiet_NaN()})
        expectRejected(patched(SetRenderOptions{}, 12, t), ErrorCode::OutOfRange,
                       "SetRenderOptions.ertThreshold");
    expectAccepted(patched(SetRenderOptions{}, 12, 1.0f));
}

TEST(DecoderRejects, TechniqueBitsUndefinedOrMissingBrickSkipping) {
    expectRejected(patched<std::uint32_t>(SetRenderOptions{}, 8, 1u << 7), ErrorCode::OutOfRange,
                   "SetRenderOptions.techniques: 0x80 has bits outside 0x7f");
    expectAccepted(patched<std::uint32_t>(SetRenderOptions{}, 8, kTechJitter));
    expectRejected(patched<std::uint32_t>(SetRenderOptions{}, 8, kTechOctreeSkipping),
                   ErrorCode::OutOfRange, "SetRenderOptions.techniques: octree");
    expectRejected(patched<std::uint32_t>(SetRenderOptions{}, 8, kTechOcclusionFrustums),
                   ErrorCode::OutOfRange, "SetRenderOptions.techniques: occlusion");
    expectAccepted(patched<std::uint32_t>(SetRenderOptions{}, 8, 0));
    expectAccepted(patched<std::uint32_t>(SetRenderOptions{}, 8, kTechEarlyTermination));
}

TEST(DecoderRejects, LevelOutsideZeroTo15UnlessAutomatic) {
    expectRejected(patched<std::uint8_t>(SetRenderOptions{}, 20, 16), ErrorCode::OutOfRange,
                   "SetRenderOptions.level: 16 is outside 0..15");
    expectRejected(patched<std::uint8_t>(SetRenderOptions{}, 20, 254), ErrorCode::OutOfRange,
                   "SetRenderOptions.level");
    expectAccepted(patched<std::uint8_t>(SetRenderOptions{}, 20, 15));
    expectAccepted(patched<std::uint8_t>(SetRenderOptions{}, 20, 255));
    expectRejected(patched<std::uint8_t>(sampleFrame(), 13, 16), ErrorCode::OutOfRange,
                   "Frame.level");
}

TEST(DecoderRejects, CodecQualityOutsideTheCodecsRange) {
    SetRenderOptions o;
    const auto withCodec = [&](Codec codec, std::uint8_t quality) {
        Bytes b = encode(o, 9);
        b[kHeaderBytes + 18] = std::uint8_t(codec);
        b[kHeaderBytes + 19] = quality;
        return b;
    };
    expectRejected(withCodec(Codec::Raw, 1), ErrorCode::OutOfRange,
                   "SetRenderOptions.codecQuality: 1 is outside 0..0");
    expectRejected(withCodec(Codec::Zstd, 20), ErrorCode::OutOfRange, "codecQuality");
    expectRejected(withCodec(Codec::ZstdDelta, 20), ErrorCode::OutOfRange, "codecQuality");
    expectRejected(withCodec(Codec::Jpeg, 101), ErrorCode::OutOfRange, "codecQuality");
    expectAccepted(withCodec(Codec::Zstd, 19));
    expectAccepted(withCodec(Codec::Jpeg, 100));
    expectAccepted(withCodec(Codec::Jpeg, 0));
}

// ---- Frame, Hello, VolumeInfo -------------------------------------------------------------

TEST(DecoderRejects, FrameWhoseImageBytesDisagreesWithTheRest) {
    const Bytes good = encode(sampleFrame(), 9);
    Bytes more = good;
    more[kHeaderBytes + 56] = 17; // says 17, 16 follow
    expectRejected(more, ErrorCode::BadPayload, "Frame.imageBytes: 17 disagrees with the 16");
    Bytes fewer = good;
    fewer[kHeaderBytes + 56] = 15;
    expectRejected(fewer, ErrorCode::BadPayload, "Frame.imageBytes: 15 disagrees");
    Bytes huge = good;
    huge[kHeaderBytes + 59] = 0xFF;
    expectRejected(huge, ErrorCode::BadPayload, "Frame.imageBytes");
    Bytes shortHeader(good.begin() + kHeaderBytes, good.begin() + kHeaderBytes + 50);
    expectRejected(wire(0x0C, shortHeader), ErrorCode::BadPayload, "Frame.");
}

TEST(DecoderRejects, RawFrameWhoseImageIsNotWidthTimesHeightTimesFour) {
    Frame f = sampleFrame();
    f.header.codec = Codec::Zstd;
    f.image.resize(15);
    Bytes b = encode(f, 9);
    b[kHeaderBytes + 12] = std::uint8_t(Codec::Raw);
    expectRejected(b, ErrorCode::BadPayload, "Frame.imageBytes: 15 is not width x height x 4 = 16");
}

TEST(DecoderAccepts, HelloWithAnyVersionRangeForTheServerToJudge) {
    // Overlap is the server's decision (UnsupportedVersion), not a payload error.
    expectAccepted(patched<std::uint16_t>(Hello{}, 0, 2)); // min 2 > max 1
    expectAccepted(patched<std::uint16_t>(Hello{}, 2, 7));
}

TEST(DecoderRejects, VolumeInfoWithNonFiniteNumbersOrBadLevels) {
    const VolumeInfo v = sampleVolume(); // fixed fields from offset 8
    expectRejected(patched(VolumeOpened{v}, 8 + 12, kNan), ErrorCode::OutOfRange,
                   "VolumeOpened.info.spacingMm[0]");
    expectRejected(patched(VolumeOpened{v}, 8 + 46, kInf), ErrorCode::OutOfRange,
                   "VolumeOpened.info.valueMax");
    expectRejected(patched<std::uint8_t>(VolumeOpened{v}, 8 + 37, 0), ErrorCode::OutOfRange,
                   "VolumeOpened.info.levels");
    expectRejected(patched<std::uint8_t>(VolumeOpened{v}, 8 + 37, 17), ErrorCode::OutOfRange,
                   "VolumeOpened.info.levels");
}

} // namespace
} // namespace bc::protocol
