// libFuzzer target of the frame image codecs a client decodes (protocol/FrameCodec.h: raw,
// zstd, zstd delta, JPEG, PNG); scripts/fuzz.sh frame_codec builds and runs it.
//
// Input: up to 8 frames, each [codec u8][width u16][height u16][keyframe u8][length u16]
// [length bytes] (little endian), decoded in turn by one FrameImageDecoder as a client would
// (the delta base carries over). A ProtocolError is the expected refusal; a decoded image
// must be width*height*4 bytes, with alpha 255 for JPEG. Then the input's bytes, as the pixels
// of a small image, must survive encode -> decode: exactly for raw, zstd and a zstd delta
// chain (keyframe then delta), at the right size and opaque for JPEG.
//
// With BC_FUZZ_SEED_DIR set, the binary first writes seeds there: frames of every codec made
// by FrameEncoder from a gradient and from a slice of a real scan (BC_SHARED_DATA_DIR), and a
// zstd delta chain.
#include "protocol/Error.h"
#include "protocol/FrameCodec.h"
#include "tests/fuzz/FuzzSupport.h"

#include <algorithm>
#include <cstring>

namespace {

using namespace bc;
using namespace bc::protocol;
using fuzz::Bytes;
using fuzz::require;

constexpr std::size_t kFrameHeaderBytes = 8;
constexpr int kMaxFrames = 8;

struct FrameInput {
    std::uint8_t codec;
    std::uint16_t width, height;
    bool keyframe;
    std::span<const std::uint8_t> bytes;
};

/// The next frame of the input; false when too few bytes are left.
bool nextFrame(std::span<const std::uint8_t>& rest, FrameInput& f) {
    if (rest.size() < kFrameHeaderBytes) return false;
    f.codec = rest[0];
    f.width = std::uint16_t(rest[1] | rest[2] << 8);
    f.height = std::uint16_t(rest[3] | rest[4] << 8);
    f.keyframe = rest[5] & 1;
    const std::size_t length = std::min<std::size_t>(rest[6] | rest[7] << 8, rest.size() - 8);
    f.bytes = rest.subspan(kFrameHeaderBytes, length);
    rest = rest.subspan(kFrameHeaderBytes + length);
    return true;
}

void decodeFrames(std::span<const std::uint8_t> input) {
    FrameImageDecoder decoder;
    FrameInput f{};
    for (int i = 0; i < kMaxFrames && nextFrame(input, f); ++i) {
        std::vector<std::uint8_t> image;
        try {
            image = decoder.decode(Codec(f.codec), f.width, f.height, f.keyframe, f.bytes);
        } catch (const ProtocolError&) {
            continue;
        }
        require(image.size() == std::size_t(f.width) * f.height * 4,
                "a decoded image is not width*height*4 bytes");
        if (Codec(f.codec) == Codec::Jpeg || Codec(f.codec) == Codec::Png)
            for (std::size_t p = 3; p < image.size(); p += 4)
                require(image[p] == 255, "a JPEG or PNG frame decoded with alpha other than 255");
    }
}

/// The input's bytes tiled into a width x height RGBA image (edges 1..32 from bytes 0, 1).
Bytes imageFrom(std::span<const std::uint8_t> input, std::uint16_t& width, std::uint16_t& height) {
    width = std::uint16_t(input[0] % 32 + 1);
    height = std::uint16_t(input[1 % input.size()] % 32 + 1);
    Bytes image(std::size_t(width) * height * 4);
    for (std::size_t i = 0; i < image.size(); ++i)
        image[i] = input[i % input.size()];
    return image;
}

void checkRoundTrips(std::span<const std::uint8_t> input) {
    if (input.empty()) return;
    std::uint16_t w = 0, h = 0;
    const Bytes image = imageFrom(input, w, h);
    FrameEncoder encoder;
    FrameImageDecoder decoder;
    // ZstdDelta last: a frame of another codec ends a delta chain (on both sides).
    for (Codec codec : {Codec::Raw, Codec::Zstd, Codec::Jpeg, Codec::Png, Codec::ZstdDelta}) {
        const auto encoded = encoder.encode(image, w, h, codec, 0);
        const Bytes back = decoder.decode(codec, w, h, encoded.keyframe, encoded.bytes);
        require(back.size() == image.size(), "a round trip changed the image size");
        if (codec == Codec::Jpeg) continue;
        bool same = true; // PNG is lossless in colour and drops alpha (255)
        for (std::size_t i = 0; i < image.size(); ++i)
            same &= back[i] == (codec == Codec::Png && i % 4 == 3 ? 255 : image[i]);
        require(same, "a lossless round trip changed pixels");
    }
    // A delta chain: the second frame (every byte plus one) is decoded against the first.
    Bytes next = image;
    for (auto& b : next)
        b = std::uint8_t(b + 1);
    const auto delta = encoder.encode(next, w, h, Codec::ZstdDelta, 0);
    require(!delta.keyframe, "the second frame of a delta chain is a keyframe");
    require(decoder.decode(Codec::ZstdDelta, w, h, false, delta.bytes) == next,
            "a zstd delta frame decoded wrong");
}

void appendFrame(Bytes& out, Codec codec, std::uint16_t w, std::uint16_t h, bool keyframe,
                 const Bytes& bytes) {
    const std::size_t n = std::min<std::size_t>(bytes.size(), 0xFFFF);
    const std::uint8_t header[kFrameHeaderBytes] = {
        std::uint8_t(codec),  std::uint8_t(w),        std::uint8_t(w >> 8), std::uint8_t(h),
        std::uint8_t(h >> 8), std::uint8_t(keyframe), std::uint8_t(n),      std::uint8_t(n >> 8)};
    out.insert(out.end(), std::begin(header), std::end(header));
    out.insert(out.end(), bytes.begin(), bytes.begin() + std::ptrdiff_t(n));
}

/// Every codec's frame of `image`, then a delta chain of it and a changed copy.
Bytes seedOf(const Bytes& image, std::uint16_t w, std::uint16_t h) {
    FrameEncoder encoder;
    Bytes out;
    for (Codec codec : {Codec::Raw, Codec::Zstd, Codec::Jpeg, Codec::Png, Codec::ZstdDelta}) {
        const auto e = encoder.encode(image, w, h, codec, 0);
        appendFrame(out, codec, w, h, e.keyframe, e.bytes);
    }
    Bytes changed = image;
    for (std::size_t i = 0; i < changed.size(); i += 7)
        changed[i] ^= 0x55;
    const auto e = encoder.encode(changed, w, h, Codec::ZstdDelta, 0);
    appendFrame(out, Codec::ZstdDelta, w, h, e.keyframe, e.bytes);
    return out;
}

void writeSeeds(const std::string& seeds) {
    const std::uint16_t w = 24, h = 16;
    Bytes gradient(std::size_t(w) * h * 4);
    for (std::size_t i = 0; i < gradient.size(); ++i)
        gradient[i] = i % 4 == 3 ? 255 : std::uint8_t((i / 4 % w) * 10 + (i / 4 / w) * 3);
    fuzz::writeSeed(seeds, "gradient", seedOf(gradient, w, h));
    const std::string data = fuzz::sharedData();
    if (data.empty()) return;
    // 64x64 grey pixels from slice 40 of the tiny CT head (u16, high byte), as opaque RGBA.
    const Bytes head = fuzz::readPrefix(data + "/vtk_headsq_quarter_64x64x93_uint16.raw",
                                        std::size_t(64) * 64 * 2 * 41);
    if (head.size() < std::size_t(64) * 64 * 2 * 41) return;
    Bytes ct(std::size_t(64) * 64 * 4, 255);
    for (std::size_t p = 0; p < std::size_t(64) * 64; ++p) {
        const std::uint8_t v = head[(std::size_t(64) * 64 * 40 + p) * 2 + 1];
        ct[p * 4] = ct[p * 4 + 1] = ct[p * 4 + 2] = std::uint8_t(v * 16);
    }
    fuzz::writeSeed(seeds, "ct-slice", seedOf(ct, 64, 64));
}

} // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    decodeFrames({data, size});
    checkRoundTrips({data, size});
    return 0;
}

extern "C" int LLVMFuzzerInitialize(int*, char***) {
    if (const std::string seeds = fuzz::envFolder("BC_FUZZ_SEED_DIR"); !seeds.empty())
        writeSeeds(seeds);
    return 0;
}
