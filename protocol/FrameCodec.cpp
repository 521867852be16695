#include "protocol/FrameCodec.h"

#include "protocol/Error.h"
#include "protocol/detail/PngImage.h"

#include <chrono>
#include <string>
#include <turbojpeg.h>
#include <zstd.h>

namespace bc::protocol {
namespace {

using Clock = std::chrono::steady_clock;
using Bytes = std::vector<std::uint8_t>;

struct CCtxDeleter {
    void operator()(ZSTD_CCtx* c) const { ZSTD_freeCCtx(c); }
};
struct DCtxDeleter {
    void operator()(ZSTD_DCtx* d) const { ZSTD_freeDCtx(d); }
};
struct TjDeleter {
    void operator()(void* h) const { tjDestroy(h); }
};
using TjHandle = std::unique_ptr<void, TjDeleter>;

std::size_t zstdCheck(std::size_t code, const std::string& what) {
    if (ZSTD_isError(code)) throw ProtocolError(what + ": " + ZSTD_getErrorName(code));
    return code;
}

void tjCheck(int rc, void* handle, const std::string& what) {
    if (rc != 0) throw ProtocolError(what + ": " + tjGetErrorStr2(handle));
}

std::string sizeText(std::uint16_t width, std::uint16_t height) {
    return std::to_string(width) + "x" + std::to_string(height);
}

/// Bytes of a width x height RGBA image. @throw ProtocolError on an edge outside 1..4096.
std::size_t imageBytes(std::uint16_t width, std::uint16_t height, const char* who) {
    if (width == 0 || height == 0 || width > kMaxImageEdge || height > kMaxImageEdge)
        throw ProtocolError(std::string(who) + ": image " + sizeText(width, height) +
                            ": each edge must be 1.." + std::to_string(kMaxImageEdge));
    return std::size_t{width} * height * 4;
}

const char* codecName(Codec codec) {
    switch (codec) {
    case Codec::Raw:
        return "raw";
    case Codec::Zstd:
        return "zstd";
    case Codec::ZstdDelta:
        return "zstd delta";
    case Codec::Jpeg:
        return "JPEG";
    case Codec::Png:
        return "PNG";
    }
    return nullptr;
}

/// The zstd level or JPEG quality that codecQuality stands for. @throw ProtocolError
int effectiveQuality(Codec codec, std::uint8_t quality) {
    if (!codecName(codec))
        throw ProtocolError("frame encoder: unknown codec " +
                            std::to_string(static_cast<unsigned>(codec)));
    if (codec == Codec::Raw) return 0;
    if (codec == Codec::Png) {
        if (quality > 1)
            throw ProtocolError("frame encoder: PNG quality " + std::to_string(quality) +
                                " is neither 0 (fast) nor 1 (small)");
        return quality;
    }
    const bool jpeg = codec == Codec::Jpeg;
    const int max = jpeg ? 100 : kMaxZstdLevel;
    if (quality > max)
        throw ProtocolError(std::string("frame encoder: ") + codecName(codec) + " quality " +
                            std::to_string(quality) + " is outside 1.." + std::to_string(max) +
                            " (0 = default)");
    if (quality != 0) return quality;
    return jpeg ? kDefaultJpegQuality : kDefaultZstdLevel;
}

TjHandle makeTj(bool compress) {
    TjHandle h(compress ? tjInitCompress() : tjInitDecompress());
    if (!h) throw ProtocolError(std::string("turbojpeg init: ") + tjGetErrorStr2(nullptr));
    return h;
}

} // namespace

// ---------------------------------------------------------------------------------------
// Encoder

struct FrameEncoder::Impl {
    std::unique_ptr<ZSTD_CCtx, CCtxDeleter> cctx{ZSTD_createCCtx()};
    TjHandle tj;
    Bytes base; ///< the previous ZstdDelta frame, valid when hasBase
    Bytes diff;
    std::uint16_t baseWidth = 0, baseHeight = 0;
    bool hasBase = false;

    Bytes zstd(std::span<const std::uint8_t> src, int level);
    Bytes delta(std::span<const std::uint8_t> src, std::uint16_t w, std::uint16_t h, int level,
                bool& keyframe);
    Bytes jpeg(std::span<const std::uint8_t> src, std::uint16_t w, std::uint16_t h, int quality);
};

Bytes FrameEncoder::Impl::zstd(std::span<const std::uint8_t> src, int level) {
    if (!cctx) throw ProtocolError("zstd: cannot create a compression context");
    zstdCheck(ZSTD_CCtx_setParameter(cctx.get(), ZSTD_c_compressionLevel, level), "zstd level");
    Bytes out(ZSTD_compressBound(src.size()));
    // compress2 knows the source size, so the frame declares it (the decoder relies on it).
    out.resize(zstdCheck(ZSTD_compress2(cctx.get(), out.data(), out.size(), src.data(), src.size()),
                         "zstd compress"));
    return out;
}

Bytes FrameEncoder::Impl::delta(std::span<const std::uint8_t> src, std::uint16_t w, std::uint16_t h,
                                int level, bool& keyframe) {
    keyframe = !hasBase || baseWidth != w || baseHeight != h;
    hasBase = false; // until this frame is encoded: an exception leaves no half-updated base
    std::span<const std::uint8_t> payload = src;
    if (keyframe) {
        base.assign(src.begin(), src.end());
    } else {
        diff.resize(src.size());
        for (std::size_t i = 0; i < src.size(); ++i) {
            diff[i] = static_cast<std::uint8_t>(src[i] - base[i]);
            base[i] = src[i];
        }
        payload = diff;
    }
    Bytes out = zstd(payload, level);
    baseWidth = w;
    baseHeight = h;
    hasBase = true;
    return out;
}

Bytes FrameEncoder::Impl::jpeg(std::span<const std::uint8_t> src, std::uint16_t w, std::uint16_t h,
                               int quality) {
    if (!tj) tj = makeTj(true);
    const int subsamp = quality >= kJpegFullChromaQuality ? TJSAMP_444 : TJSAMP_420;
    Bytes out(tjBufSize(w, h, subsamp));
    unsigned char* buf = out.data();
    unsigned long size = out.size();
    // Premultiplied RGB with alpha dropped is the image composited over black (PROTOCOL.md).
    tjCheck(tjCompress2(tj.get(), src.data(), w, w * 4, h, TJPF_RGBA, &buf, &size, subsamp, quality,
                        TJFLAG_NOREALLOC),
            tj.get(), "JPEG compress");
    out.resize(size);
    return out;
}

FrameEncoder::FrameEncoder() : mImpl(std::make_unique<Impl>()) {}
FrameEncoder::~FrameEncoder() = default;
FrameEncoder::FrameEncoder(FrameEncoder&&) noexcept = default;
FrameEncoder& FrameEncoder::operator=(FrameEncoder&&) noexcept = default;

FrameEncoder::Encoded FrameEncoder::encode(std::span<const std::uint8_t> rgba8, std::uint16_t width,
                                           std::uint16_t height, Codec codec,
                                           std::uint8_t quality) {
    const auto start = Clock::now();
    const std::size_t n = imageBytes(width, height, "frame encoder");
    if (rgba8.size() != n)
        throw ProtocolError("frame encoder: " + std::to_string(rgba8.size()) +
                            " RGBA bytes for a " + sizeText(width, height) + " image, expected " +
                            std::to_string(n));
    const int q = effectiveQuality(codec, quality);
    Encoded e;
    if (codec != Codec::ZstdDelta) resetDelta();
    switch (codec) {
    case Codec::Raw:
        e.bytes.assign(rgba8.begin(), rgba8.end());
        break;
    case Codec::Zstd:
        e.bytes = mImpl->zstd(rgba8, q);
        break;
    case Codec::ZstdDelta:
        e.bytes = mImpl->delta(rgba8, width, height, q, e.keyframe);
        break;
    case Codec::Jpeg:
        e.bytes = mImpl->jpeg(rgba8, width, height, q);
        break;
    case Codec::Png:
        e.bytes = detail::encodePng(rgba8, width, height, q == 1);
        break;
    }
    e.encodeMs = std::chrono::duration<double, std::milli>(Clock::now() - start).count();
    return e;
}

void FrameEncoder::resetDelta() {
    mImpl->hasBase = false;
}

// ---------------------------------------------------------------------------------------
// Decoder

struct FrameImageDecoder::Impl {
    std::unique_ptr<ZSTD_DCtx, DCtxDeleter> dctx{ZSTD_createDCtx()};
    TjHandle tj;
    Bytes base; ///< the previous ZstdDelta frame, valid when hasBase
    std::uint16_t baseWidth = 0, baseHeight = 0;
    bool hasBase = false;

    Bytes decode(Codec codec, std::uint16_t w, std::uint16_t h, bool keyframe,
                 std::span<const std::uint8_t> bytes);
    Bytes unzstd(std::span<const std::uint8_t> bytes, std::uint16_t w, std::uint16_t h,
                 const std::string& who);
    Bytes undelta(std::span<const std::uint8_t> bytes, std::uint16_t w, std::uint16_t h,
                  bool keyframe);
    Bytes unjpeg(std::span<const std::uint8_t> bytes, std::uint16_t w, std::uint16_t h);
};

Bytes FrameImageDecoder::Impl::unzstd(std::span<const std::uint8_t> bytes, std::uint16_t w,
                                      std::uint16_t h, const std::string& who) {
    const std::size_t n = std::size_t{w} * h * 4;
    // The declared size is checked before anything is allocated from it.
    const unsigned long long declared = ZSTD_getFrameContentSize(bytes.data(), bytes.size());
    if (declared == ZSTD_CONTENTSIZE_ERROR)
        throw ProtocolError(who + ": not a zstd frame (bad magic or truncated header)");
    if (declared == ZSTD_CONTENTSIZE_UNKNOWN)
        throw ProtocolError(who + ": the zstd frame does not declare its content size");
    if (declared != n)
        throw ProtocolError(who + ": the zstd frame declares " + std::to_string(declared) +
                            " content bytes, a " + sizeText(w, h) + " image has " +
                            std::to_string(n));
    const std::size_t frame = zstdCheck(ZSTD_findFrameCompressedSize(bytes.data(), bytes.size()),
                                        who + ": truncated or corrupt zstd frame");
    if (frame != bytes.size())
        throw ProtocolError(who + ": " + std::to_string(bytes.size() - frame) +
                            " bytes after the zstd frame");
    if (!dctx) throw ProtocolError(who + ": cannot create a zstd decompression context");
    Bytes out(n);
    const std::size_t got =
        zstdCheck(ZSTD_decompressDCtx(dctx.get(), out.data(), n, bytes.data(), bytes.size()),
                  who + ": corrupt zstd frame");
    if (got != n)
        throw ProtocolError(who + ": the zstd frame holds " + std::to_string(got) +
                            " bytes, it declared " + std::to_string(n));
    return out;
}

Bytes FrameImageDecoder::Impl::undelta(std::span<const std::uint8_t> bytes, std::uint16_t w,
                                       std::uint16_t h, bool keyframe) {
    const bool haveBase = hasBase && baseWidth == w && baseHeight == h;
    hasBase = false;
    if (!keyframe && !haveBase)
        throw ProtocolError("zstd delta frame " + sizeText(w, h) +
                            ": not a keyframe and there is no previous delta frame of this size "
                            "to apply it to (ask for a keyframe)");
    Bytes out = unzstd(bytes, w, h, "zstd delta frame");
    if (!keyframe)
        for (std::size_t i = 0; i < out.size(); ++i)
            out[i] = static_cast<std::uint8_t>(out[i] + base[i]);
    base = out;
    baseWidth = w;
    baseHeight = h;
    hasBase = true;
    return out;
}

Bytes FrameImageDecoder::Impl::unjpeg(std::span<const std::uint8_t> bytes, std::uint16_t w,
                                      std::uint16_t h) {
    if (!tj) tj = makeTj(false);
    int jw = 0, jh = 0, subsamp = 0, colorspace = 0;
    tjCheck(
        tjDecompressHeader3(tj.get(), bytes.data(), bytes.size(), &jw, &jh, &subsamp, &colorspace),
        tj.get(), "JPEG frame: not a JPEG image");
    if (jw != w || jh != h)
        throw ProtocolError("JPEG frame: the image is " + std::to_string(jw) + "x" +
                            std::to_string(jh) + ", the frame header says " + sizeText(w, h));
    Bytes out(std::size_t{w} * h * 4);
    // Warnings (a truncated scan) are errors too: a frame either decodes fully or not at all.
    tjCheck(tjDecompress2(tj.get(), bytes.data(), bytes.size(), out.data(), w, w * 4, h, TJPF_RGBA,
                          TJFLAG_STOPONWARNING | TJFLAG_LIMITSCANS),
            tj.get(), "JPEG frame: corrupt image");
    return out;
}

Bytes FrameImageDecoder::Impl::decode(Codec codec, std::uint16_t w, std::uint16_t h, bool keyframe,
                                      std::span<const std::uint8_t> bytes) {
    const std::size_t n = imageBytes(w, h, "frame image");
    if (codec != Codec::ZstdDelta) hasBase = false;
    switch (codec) {
    case Codec::Raw:
        if (bytes.size() != n)
            throw ProtocolError("raw frame: " + std::to_string(bytes.size()) + " bytes, a " +
                                sizeText(w, h) + " image has " + std::to_string(n));
        return Bytes(bytes.begin(), bytes.end());
    case Codec::Zstd:
        return unzstd(bytes, w, h, "zstd frame");
    case Codec::ZstdDelta:
        return undelta(bytes, w, h, keyframe);
    case Codec::Jpeg:
        return unjpeg(bytes, w, h);
    case Codec::Png:
        return detail::decodePng(bytes, w, h);
    }
    throw ProtocolError("frame image: unknown codec " +
                        std::to_string(static_cast<unsigned>(codec)));
}

FrameImageDecoder::FrameImageDecoder() : mImpl(std::make_unique<Impl>()) {}
FrameImageDecoder::~FrameImageDecoder() = default;
FrameImageDecoder::FrameImageDecoder(FrameImageDecoder&&) noexcept = default;
FrameImageDecoder& FrameImageDecoder::operator=(FrameImageDecoder&&) noexcept = default;

std::vector<std::uint8_t> FrameImageDecoder::decode(Codec codec, std::uint16_t width,
                                                    std::uint16_t height, bool keyframe,
                                                    std::span<const std::uint8_t> bytes) {
    try {
        return mImpl->decode(codec, width, height, keyframe, bytes);
    } catch (...) {
        mImpl->hasBase = false;
        throw;
    }
}

} // namespace bc::protocol
