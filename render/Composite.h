#pragma once
// Sort-last compositing (render/SCALEOUT.md): the parts of a Partition each draw
// their own segment of every ray as premultiplied RGBA over their footprint; laid front to
// back with the over operator they give the frame one renderer draws (within float rounding,
// and early termination's bound when it is on).
#include "render/Image.h"
#include "render/RenderTypes.h"

#include <optional>
#include <span>

namespace bc::render {

struct TransferFunctionTable;

/// How parts' segments of a ray combine (render/SCALEOUT.md). `Over`, front to back: composite,
/// and the isosurface (opaque where hit, so the front-most part's hit is the ray's first).
/// The projections' raw pixels (value, count, 0, 0; resolveProjections) combine by the larger
/// value (`Maximum`), the smaller (`Minimum`), or the sums of values and counts (`Sum`), in
/// any order; a pixel without samples (count 0) takes the other's.
enum class PartsCombine { Over, Maximum, Minimum, Sum };
PartsCombine combineFor(BlendMode mode);

/// A projecting frame's raw pixels (value, or the values' sum for Average, then the sample
/// count, 0, 0) as colours: the value (the mean for Average) mapped through `table` as the
/// CPU raycaster classifies a sample (float, the same lerp), premultiplied; transparent where
/// the count is 0. `mode` is Maximum, Minimum or Average.
void resolveProjections(Image& image, BlendMode mode, const TransferFunctionTable& table);

/// One part's segment image: premultiplied RGBA (alpha = 1 - transmittance) over `rect` of
/// the frame.
struct PartialImage {
    PixelRect rect;
    Image image; ///< rect.width x rect.height
};

/// The pixels two rects share; nullopt when none.
std::optional<PixelRect> overlap(const PixelRect& a, const PixelRect& b);

/// Clamps every channel to [0, 1], as a renderer's frame is (partial images are not).
void clampToUnit(Image& image);

/// Lays `back` under `frame` (everything in `frame` so far lies in front of it): per pixel
/// of back.rect, c = c + (1 - a) c_back and a = a + (1 - a) a_back, rgb and alpha alike.
/// `frameRect` is where `frame` lies in the whole image (`back` is clipped to it).
/// @throw std::invalid_argument when an image is not its rect's size.
void compositeUnder(Image& frame, const PixelRect& frameRect, const PartialImage& back);
/// compositeUnder for `how`: Over is compositeUnder; the others combine raw projection pixels.
void combineUnder(Image& frame, const PixelRect& frameRect, const PartialImage& back,
                  PartsCombine how);

/// The frame of `width` x `height` from partial images listed front to back (transparent
/// black where none covers a pixel), clamped to [0, 1] as a renderer's frame is: partial
/// images are not (a shaded segment's premultiplied colour may exceed 1).
Image compositeFrontToBack(std::uint32_t width, std::uint32_t height,
                           std::span<const PartialImage> frontToBack);
/// The same for `how`: under Over as above; otherwise the raw projection pixels combined (not
/// clamped), for resolveProjections.
Image compositeFrontToBack(std::uint32_t width, std::uint32_t height,
                           std::span<const PartialImage> frontToBack, PartsCombine how);

} // namespace bc::render
