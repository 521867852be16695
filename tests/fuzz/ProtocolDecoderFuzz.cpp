// libFuzzer target of the protocol decoder (scripts/fuzz.sh protocol_decoder builds and runs it).
//
// Input: byte 0 = n (mod 8), then n chunk sizes (1..256 each, used in turn), then the byte
// stream, fed into one Decoder in those chunks. Every decoded message must re-encode, and
// decoding the re-encoding must give an equal message; errors must be well-formed and a fatal
// one must stick. The stream read as one type byte and a payload must be refused or re-encode
// to the same bytes. Any broken property aborts.
//
// With BC_FUZZ_SEED_DIR set in the environment, the binary first writes a few seeds (valid
// encoded messages in that input format) into that folder, which should be its corpus.
#include "protocol/Decoder.h"
#include "protocol/Messages.h"

#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <span>
#include <string>
#include <vector>

namespace {

using namespace bc::protocol;

void require(bool ok, const char* what) {
    if (ok) return;
    std::fprintf(stderr, "ProtocolDecoderFuzz: %s\n", what);
    std::abort();
}

/// Re-encodes m; decoding that must give m back (bit for bit: a NaN counter is not equal to
/// itself, so equality is required only of messages that are equal to themselves).
void checkRoundTrip(const Message& m, std::uint32_t request) {
    std::vector<std::uint8_t> bytes;
    try {
        bytes = encode(m, request);
    } catch (const std::exception& e) {
        std::fprintf(stderr, "%s\n", e.what());
        require(false, "a decoded message does not encode");
    }
    Decoder again(kDefaultMaxServerPayloadBytes);
    again.feed(bytes);
    const Decoder::Result r = again.next();
    require(r.status == Decoder::Status::Message, "a re-encoded message does not decode");
    require(r.request == request, "the request id changed");
    require(r.message == m || !(m == m), "the re-decoded message differs");
    require(encode(r.message, request) == bytes, "the second encoding differs");
    require(again.next().status == Decoder::Status::NeedMore, "bytes left after one message");
}

/// An error must be sendable as it is: printable, within the Error message limit.
void checkError(const DecodeError& e, std::uint32_t request) {
    require(e.request == request, "the error's request id differs from the result's");
    require(e.message.size() <= kMaxErrorMessageBytes, "error message too long");
    for (char c : e.message)
        require(c >= 0x20 && c < 0x7F, "error message not printable ASCII");
    encode(Error{e.code, e.fatal, e.type, e.message}, request);
}

/// Read as a type byte and a payload, the stream must either be refused or be the exact
/// encoding of what it decodes to: the encoding is canonical (bools 0/1, reserved 0, nothing
/// left over), so nothing the decoder accepts can be altered by a re-encode.
void checkCanonical(std::span<const std::uint8_t> bytes) {
    if (bytes.empty()) return;
    const auto decoded = decodePayload(bytes[0], 0, bytes.subspan(1));
    const auto* m = std::get_if<Message>(&decoded);
    if (!m) return;
    const std::vector<std::uint8_t> again = encode(*m);
    require(std::equal(again.begin() + kHeaderBytes, again.end(), bytes.begin() + 1, bytes.end()),
            "an accepted payload is not the encoding of its message");
}

/// Takes every result the decoder has; returns false once it has failed.
bool drain(Decoder& decoder) {
    for (;;) {
        const Decoder::Result r = decoder.next();
        switch (r.status) {
        case Decoder::Status::NeedMore:
            require(!decoder.failed(), "NeedMore from a failed decoder");
            return true;
        case Decoder::Status::Message:
            checkRoundTrip(r.message, r.request);
            break;
        case Decoder::Status::Error:
            checkError(r.error, r.request);
            require(r.error.fatal == decoder.failed(), "fatal flag and failed() disagree");
            if (!r.error.fatal) break;
            require(decoder.next().error == r.error, "a fatal error did not stick");
            return false;
        }
    }
}

} // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    std::span<const std::uint8_t> input(data, size);
    if (input.empty()) return 0;
    const std::size_t splitCount = std::min<std::size_t>(input[0] % 8, input.size() - 1);
    const auto splits = input.subspan(1, splitCount);
    auto stream = input.subspan(1 + splitCount);
    checkCanonical(stream);

    Decoder decoder(kMaxClientPayloadBytes);
    std::size_t chunk = 0;
    while (!stream.empty()) {
        const std::size_t n = splits.empty() ? stream.size() : splits[chunk++ % splits.size()] + 1u;
        const auto piece = stream.first(std::min(n, stream.size()));
        stream = stream.subspan(piece.size());
        decoder.feed(piece);
        require(decoder.buffered() <= kHeaderBytes + kMaxClientPayloadBytes + piece.size(),
                "the decoder holds more than one message and the last feed");
        if (!drain(decoder)) {
            decoder.feed(stream); // dropped
            require(decoder.buffered() == 0 && !decoder.midMessage(), "a failed decoder buffers");
            return 0;
        }
    }
    return 0;
}

namespace {

std::vector<std::vector<Message>> seedMessages() {
    SetCamera camera;
    camera.eye = {0, -4, 0};
    SetTransferFunction points;
    points.kind = TfKind::Points;
    points.shadingSource = ShadingSource::Message;
    points.points = {{Placement::Percentile, 50, {1, 0.5f, 0.25f, 0.1f}}};
    Frame frame;
    frame.header.width = frame.header.height = 2;
    frame.image.assign(16, 0x80);
    Hello hello;
    hello.codecs = {Codec::Raw, Codec::Jpeg};
    hello.software = "seed";
    VolumeInfo volume{"cthead", {256, 256, 113}, {1, 1, 2}, VoxelType::U16, 4, 0, 4095, 1};
    SetModeAndClip cut;
    cut.mode = BlendMode::Isosurface;
    cut.isoValue = 600;
    cut.cropped = true;
    cut.cropMax = {256, 256, 226};
    cut.planes = {ClipPlane{{1, 0, 0}, -10}, ClipPlane{{0, 0.5, -1}, 100}};
    cut.cap = true; // the optional cutFlags byte
    return {
        {hello, Auth{"token"}, ListVolumes{}},
        {OpenVolume{"cthead"}, camera, SetRenderOptions{}, RequestFrame{FrameMode::ContinuousOn}},
        {points, SetTransferFunction{}, RequestStats{}, Bye{}},
        {cut, SetModeAndClip{}, SetFrameBudget{66, 40}},
        {VolumeList{{volume}}, VolumeOpened{volume}, AuthOk{}},
        {frame, Stats{{{"frames", 3}}}, Error{ErrorCode::OutOfRange, false, 10, "width"}},
        // The shapes of the adversarial passes: replies asked for and never read, a guessed
        // token, a Hello that never gets to Auth.
        std::vector<Message>(64, RequestStats{}),
        std::vector<Message>(64, RequestHistogram{}),
        {hello, Auth{std::string(256, 'g')}, Auth{"guess"}},
        {hello, hello, ListVolumes{}},
    };
}

void writeSeed(const std::string& folder, std::size_t i, const std::vector<std::uint8_t>& bytes) {
    std::ofstream out(folder + "/seed-" + std::to_string(i), std::ios::binary | std::ios::trunc);
    out.write(reinterpret_cast<const char*>(bytes.data()), std::streamsize(bytes.size()));
    require(bool(out), "cannot write a seed file");
}

void writeSeeds(const std::string& folder) {
    const auto seeds = seedMessages();
    for (std::size_t i = 0; i < seeds.size(); ++i) {
        // Byte 0 picks the chunking: one feed for even seeds, chunks of 7 and 31 for odd ones.
        std::vector<std::uint8_t> bytes =
            i % 2 ? std::vector<std::uint8_t>{2, 6, 30} : std::vector<std::uint8_t>{0};
        for (const Message& m : seeds[i])
            encode(m, std::uint32_t(i + 1), bytes);
        writeSeed(folder, i, bytes);
    }
    // Type byte and payload, for checkCanonical.
    std::size_t i = seeds.size();
    for (const auto& group : seeds)
        for (const Message& m : group) {
            const std::vector<std::uint8_t> wire = encode(m);
            std::vector<std::uint8_t> bytes = {0, wire[5]};
            bytes.insert(bytes.end(), wire.begin() + kHeaderBytes, wire.end());
            writeSeed(folder, i++, bytes);
        }
}

} // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
    if (const char* folder = std::getenv("BC_FUZZ_SEED_DIR")) writeSeeds(folder);
    return 0;
}
