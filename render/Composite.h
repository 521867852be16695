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

/// The frame of `width` x `height` from partial images listed front to back (transparent
/// black where none covers a pixel), clamped to [0, 1] as a renderer's frame is: partial
/// images are not (a shaded segment's premultiplied colour may exceed 1).
Image compositeFrontToBack(std::uint32_t width, std::uint32_t height,
                           std::span<const PartialImage> frontToBack);

} // namespace bc::render
