#pragma once
// What a frame is asked for and what it reports, shared by the GPU raycaster and the CPU
// reference so both follow one optical model (see render/OPTICS.md).
#include "render/Clip.h"
#include "render/Occupancy.h"

#include <array>
#include <cstdint>
#include <optional>
#include <string>

namespace bc::render {

/// Which empty space is skipped: `Bricks` is the first stage (bricks transparent over their
/// value range are never uploaded nor sampled), `All` adds the second (empty nodes of the
/// per-brick octrees are leapt inside bricks, and bricks whose every leaf is empty are
/// skipped too).
enum class SkipMode { None, Bricks, All };

/// "none" | "bricks" | "all" -> SkipMode; std::invalid_argument otherwise.
SkipMode parseSkipMode(const std::string& text);
const char* toString(SkipMode mode);

/// What a ray makes of its samples (render/MODES.md). `Composite`: emission and absorption
/// through the transfer function, front to back. The projections keep one value of the ray's
/// samples and map it through the transfer function's colour and opacity as authored (per
/// unit step, not corrected for the step): `Maximum` (MIP) the largest, `Minimum` (MinIP)
/// the smallest, `Average` their mean. `Isosurface`: the first point along the ray where the
/// value reaches RenderOptions::isoValue, refined between the two samples around it, drawn
/// opaque in the transfer function's colour there and shaded by the gradient.
enum class BlendMode { Composite, Maximum, Minimum, Average, Isosurface };

/// "composite" | "mip" | "minip" | "average" | "iso" -> BlendMode; std::invalid_argument
/// naming the choices otherwise.
BlendMode parseBlendMode(const std::string& text);
const char* toString(BlendMode mode);
/// Maximum, Minimum or Average: a ray keeps one value, mapped through the table at the end.
inline bool isProjection(BlendMode mode) {
    return mode == BlendMode::Maximum || mode == BlendMode::Minimum || mode == BlendMode::Average;
}
/// Maximum or Minimum: besides its lattice, a ray samples the two ends of the segment it keeps
/// (the box's or the cut's entry and exit; render/MODES.md), where the lattice leaves up to a
/// step unseen. Only a ray with a sample of its lattice has them (one that crosses less than
/// half a step of the volume draws nothing, as before).
inline bool samplesEnds(BlendMode mode) {
    return mode == BlendMode::Maximum || mode == BlendMode::Minimum;
}

/// Occlusion-frustum ray starts (render/OCCLUSION.md).
struct OcclusionConfig {
    std::uint32_t blockPixels = 4; ///< k: occlusion blocks of k x k pixels
    /// Policy, measured: a frame with frustums that takes longer than the last frame without
    /// them switches them off for `offFrames` frames (random jumps on dense data do not pay);
    /// the second frame of a scene, and one frame after every `probeEvery` frames with them,
    /// is drawn without them to measure the plain cost.
    std::uint32_t offFrames = 8;
    std::uint32_t probeEvery = 16;
    void validate() const;
};

/// A rectangle of an image's pixels (row 0 at the top); width 0 means the whole image.
struct PixelRect {
    std::uint32_t x = 0, y = 0, width = 0, height = 0;
    bool whole() const { return width == 0; }
    std::uint64_t pixels() const { return std::uint64_t(width) * height; }
    bool operator==(const PixelRect&) const = default;
};

/// The pixels a frame drawn at RenderOptions::stride s takes: (s i + s / 2, s j + s / 2), one
/// at the middle of each s x s cell (s = 1: every pixel). Lattice pixel (i, j) is image pixel
/// (pixel(i), pixel(j)).
struct PixelLattice {
    std::uint32_t stride = 1;

    std::uint32_t pixel(std::uint32_t i) const { return i * stride + stride / 2; }
    /// The first lattice index whose pixel is at or after image pixel p; at p = an image's edge,
    /// how many lattice pixels lie across it.
    std::uint32_t first(std::uint32_t p) const {
        const std::uint32_t o = stride / 2;
        return p <= o ? 0 : (p - o + stride - 1) / stride;
    }
    /// The lattice pixels inside image rectangle `r` (not whole), as a rectangle of lattice
    /// indices; nullopt when none is.
    std::optional<PixelRect> of(const PixelRect& r) const {
        const std::uint32_t x0 = first(r.x), x1 = first(r.x + r.width);
        const std::uint32_t y0 = first(r.y), y1 = first(r.y + r.height);
        if (x1 <= x0 || y1 <= y0) return std::nullopt;
        return PixelRect{x0, y0, x1 - x0, y1 - y0};
    }
};

struct RenderOptions {
    std::uint32_t width = 256;
    std::uint32_t height = 256;
    /// Only these pixels are drawn, each exactly as in the whole frame, and the image returned
    /// is the region's size. Renderers whose kind says `regions` honour it (every built-in
    /// one); others would refuse a region that is not the whole image (Renderer::checkView).
    /// How the daemon draws a long frame in slices.
    PixelRect region;
    double stepVoxels = 1.0; ///< sample distance in units of the smallest spacing
    bool earlyTermination = true;
    double ertThreshold = 0.99; ///< stop a ray once its opacity reaches this
    SkipMode skip = SkipMode::All;
    /// Under skipping, a maximum or minimum also leaves out the bricks and octree leaves whose
    /// values cannot pass the ray's value so far (render/MODES.md). The same image either way;
    /// false keeps only the skipping by the transfer function.
    bool runningSkip = true;
    BlendMode mode = BlendMode::Composite;
    /// BlendMode::Isosurface: the value whose surface is drawn, in the volume's units (the
    /// transfer function's domain); it must lie within the volume's values.
    double isoValue = 0.0;
    /// The crop box and clip planes (render/Clip.h): the raycasters and the reference honour
    /// them; the splatters refuse a clip.
    Clip clip;
    bool shading = true;      ///< Blinn-Phong from central-difference gradients
    std::int32_t level = 0;   ///< pyramid level; see `interactive`
    bool interactive = false; ///< may draw a coarser level when level 0 exceeds the GPU budget
    /// GPU only: one filtered texture fetch per sample instead of 8 exact ones. Faster, but
    /// the hardware's 8-bit interpolation weights cost accuracy and make a sample depend on
    /// its brick's place in the pool (so skipping no longer gives bit-identical images).
    bool hardwareFilter = false;
    /// CPU raycaster only: take each ray's samples a vector at a time (Highway, the host's
    /// widest instruction set; render/detail/CpuMarchSimd.cpp). The same image as the scalar
    /// loop, bit for bit; false draws with the scalar loop.
    bool simd = true;
    /// With simd: march a vector of rays at a time, one sample per lane (packets of 4x4
    /// pixels, render/detail/CpuMarchSimd.h) instead of a vector of one ray's consecutive
    /// samples. The same image, bit for bit. Pre-integration marches with the scalar loop.
    bool packets = true;
    /// Start each ray's samples at a per-pixel offset of [0, 1) step from the box entry
    /// instead of half a step (rayJitter()): the fixed lattice's wood-grain rings become fine
    /// noise (render/OPTICS.md). Deterministic per pixel, so skipping, slices and repeated
    /// frames keep their images exactly. The raycasters and the reference honour it.
    bool jitter = false;
    /// Classify each sample's segment (from the previous sample to it) through the
    /// pre-integrated transfer function instead of the sample's value alone
    /// (PreintegratedTable, render/OPTICS.md): thin features of the function between two
    /// samples' values are no longer missed, so a coarser step reaches a given error. The CPU
    /// raycaster and the reference honour it; other renderers refuse it.
    bool preintegrate = false;
    OccupancyConfig octree; ///< second-stage traversal (SkipMode::All)
    /// CPU raycaster with the octrees (SkipMode::All): leap by per-brick distance maps over
    /// cells of this many voxels (a power of two below the leaf: 1, 2 or 4 for 8-voxel leaves),
    /// built from the drawn bricks' voxels (render/FineOccupancy.h), so rays leap the empty
    /// space inside non-empty leaves. The same image, bit for bit; 0 leaps by the octree alone.
    std::uint32_t cellVoxels = 2;
    /// Start rays at the previous frame's occlusion frustums (same raycaster, same scene).
    bool occlusionFrustums = true;
    OcclusionConfig occlusion;
    /// Ray-guided residency (render/RESIDENCY.md). GPU: bricks the last frame of the same
    /// scene planned but no unsaturated ray entered are not uploaded while the pool lacks them;
    /// a ray that reaches one stops there and goes on in a further pass once it is loaded. CPU
    /// raycaster: the bricks to load come in smaller batches, and a batch's bricks that no ray
    /// still marching meets are not loaded. Images are those without it; only loads, uploads
    /// and passes change.
    bool rayGuided = true;
    /// Sort-last scale-out (render/Partition.h, render/SCALEOUT.md): with parts > 1, draw only
    /// the samples that lie in bricks of part `part` of the level's brick grid split into
    /// `parts` (Partition::ofLevel), each ray from zero opacity: the frame is that part's
    /// premultiplied segment of every ray (early termination within the segment; colour not
    /// clamped to 1, which a shaded segment may exceed: the composited frame is), which
    /// compositeFrontToBack (render/Composite.h) lays with the other parts' in their
    /// Partition::frontToBack order. Sample positions do not move: the parts' samples are
    /// exactly the one-part frame's. The CPU raycaster draws parts; other renderers refuse.
    std::uint32_t parts = 1;
    std::uint32_t part = 0;
    /// CPU raycaster: bytes of bricks this frame's earlier slices kept in the host cache
    /// (their FrameStats::hostKeptBytes summed; 0 for a whole frame or its first slice). A
    /// frame keeps the bricks it pins at the back of the eviction order until it has kept the
    /// budget less two batches of loads, and lets the later ones go first: when its bricks
    /// outgrow the budget, the next pass over the view then starts on resident bricks instead
    /// of evicting each just before it is wanted (render/RESIDENCY.md).
    std::uint64_t hostKeptBefore = 0;
    /// Draw only every stride-th pixel along each axis, the pixels of PixelLattice{stride},
    /// each exactly as in the whole frame; the image returned is the lattice's pixels of the
    /// region (PixelLattice::of), which must hold one. A sparse frame at low cost: the daemon's
    /// check of the first refinement pass at rest (render/RefinementEstimate.h), drawn in bands
    /// of rows like a frame in slices. With one part only. Renderers whose kind says `strided`
    /// honour it (the CPU raycaster); others refuse a stride above 1 (Renderer::checkView).
    std::uint32_t stride = 1;

    /// Throws std::invalid_argument naming the field when a value is out of range.
    void validate() const;
    /// The pixels to draw: `region`, or the whole image when it is empty (under a stride, the
    /// lattice's pixels of it).
    PixelRect drawn() const { return region.whole() ? PixelRect{0, 0, width, height} : region; }
    PixelLattice lattice() const { return {stride}; }
};

/// Whether a frame of `o` skips by the ray's value so far (RenderOptions::runningSkip): a
/// maximum or minimum under skipping. The GPU raycaster also needs its own filtering in the
/// shader (not RenderOptions::hardwareFilter, whose rounding the bounds do not cover).
inline bool runsSkip(const RenderOptions& o) {
    return o.runningSkip && o.skip != SkipMode::None &&
           (o.mode == BlendMode::Maximum || o.mode == BlendMode::Minimum);
}

/// Whether a frame of `o` draws the faces its cuts make (Clip::cap, render/MODES.md
/// "Capping"): a crop or a plane, in composite or isosurface mode.
inline bool capsCuts(const RenderOptions& o) {
    return o.clip.cap && o.clip.any() &&
           (o.mode == BlendMode::Composite || o.mode == BlendMode::Isosurface);
}

/// Where pixel (x, y) of the frame (y from the top) starts its samples under
/// RenderOptions::jitter, in steps past the box entry, in [0, 1): the R2 low-discrepancy
/// dither (Roberts 2018, fract(x a1 + y a2) with a1, a2 from the plastic number) in 32-bit
/// fixed point, so that the shader computes the same float bit for bit.
float rayJitter(std::uint32_t x, std::uint32_t y);

/// How an isosurface's crossing is refined between the sample below the iso value and the
/// first at or above it: this many bisections of that step, the hit at the middle of what is
/// left (within step / 2^(kBisections + 1) of a crossing).
struct IsoModel {
    static constexpr int kBisections = 12;
};

/// Shading constants (headlight Blinn-Phong; the light sits at the eye).
struct ShadingModel {
    static constexpr double kAmbient = 0.3;
    static constexpr double kDiffuse = 0.7;
    static constexpr double kSpecular = 0.25;
    static constexpr double kShininess = 24.0;
    /// Gradients (TF-domain units per voxel of the smallest spacing) below this fade to
    /// unshaded colour, so flat regions have no noisy normals and nothing divides by zero.
    static constexpr double kGradientFade = 2e-3;
};

/// Per-frame statistics (DESIGN.md: every frame carries them).
struct FrameStats {
    std::uint32_t level = 0;   ///< pyramid level drawn
    std::uint64_t samples = 0; ///< volume samples classified
    /// CPU reference only: samples with non-zero opacity before the ray reaches the early
    /// termination threshold: the least any skipping renderer must take (the "oracle").
    std::uint64_t oracleSamples = 0;
    std::uint64_t bricksTotal = 0;    ///< bricks of the level
    std::uint64_t bricksCulled = 0;   ///< outside the view frustum
    std::uint64_t bricksSkipped = 0;  ///< transparent under the TF (never uploaded nor sampled)
    std::uint64_t bricksVisited = 0;  ///< drawn: sampled from the pool or constant
    std::uint64_t bricksConstant = 0; ///< of those, one value throughout (drawn without a texture)
    std::uint64_t bricksUploaded = 0; ///< host -> GPU uploads this frame
    std::uint64_t bytesUploaded = 0;
    std::uint32_t batches = 0; ///< front-to-back passes (> 1 when the budget is short)
    /// Ray-guided residency (RenderOptions::rayGuided): bricks unsaturated rays entered (the
    /// frame's true working set); planned bricks left unloaded because the last frame found
    /// them hidden; of those, the ones loaded later in the frame (rays reached them, or a
    /// frame out of request rounds loaded the rest); passes that continued rays stopped at one;
    /// and whether the deferral did not fit the pool so the frame was drawn in batches.
    std::uint64_t bricksEntered = 0;
    std::uint64_t bricksDeferred = 0;
    std::uint64_t bricksRequested = 0;
    std::uint32_t resumePasses = 0;
    bool guidedFallback = false;
    /// CPU raycaster, rayGuided: planned bricks not loaded because no ray of their footprint
    /// was still marching when their batch came (each had terminated early, left the volume or
    /// been drawn); they would not have been sampled.
    std::uint64_t bricksUnreached = 0;
    /// CPU raycaster: bytes of the bricks it pinned that it left at the back of the host
    /// cache's eviction order (RenderOptions::hostKeptBefore); the others went to the front.
    std::uint64_t hostKeptBytes = 0;
    std::uint64_t octreeLeaps = 0; ///< empty octree nodes leapt by rays
    /// CPU raycaster, maximum and minimum projections: samples that raised a ray's maximum or
    /// lowered its minimum (the samples that made the image; `samples` over this is the march's
    /// overhead).
    std::uint64_t samplesRaising = 0;
    std::uint64_t octreeBricksRebuilt = 0; ///< octrees rebuilt for this frame's TF (0: reused)
    double octreeRebuildMs = 0.0;
    /// CPU raycaster, RenderOptions::cellVoxels: drawn bricks whose cells below the leaves this
    /// frame built from their voxels (FineOccupancy; 0 once every drawn brick has them), the
    /// time that took (summed over threads), and the drawn bricks that leap by cells.
    std::uint64_t cellBricksBuilt = 0;
    double cellBuildMs = 0.0;
    std::uint64_t cellBricks = 0;
    bool occlusionUsed = false;           ///< ray starts came from occlusion frustums
    const char* occlusionReason = "off";  ///< why not, when not used ("" when used)
    std::uint64_t occlusionFrustums = 0;  ///< non-empty blocks extruded
    std::uint64_t occlusionTriangles = 0; ///< of the frustums and the outside pieces
    double occlusionBuildMs = 0.0;
    std::uint64_t samplesSavedByStart = 0; ///< samples before the ray starts (not taken)
    double uploadMs = 0.0;
    double renderMs = 0.0;
    double readbackMs = 0.0;
    double totalMs = 0.0;
    /// The registry's name of the renderer that drew the frame and why it was chosen
    /// (RendererChoice: "auto: cpu (GL_RENDERER '...' is a software rasteriser)", "asked for
    /// gpu"). Set by whoever chose the renderer (the daemon, the CLI), not by the renderer;
    /// empty when nobody did.
    std::string renderer, rendererChoice;
};

/// Adds to `frame` the statistics of `slice`: a further region of the same frame, drawn by
/// another call of the same renderer (the daemon draws long frames in slices). Work adds up
/// (samples, loads, uploads, deferrals, passes, leaps, frustums, times); each slice plans the
/// bricks its own rays reach, so a count of bricks (visited, skipped, constant, entered, cells)
/// is the largest of one slice, a lower bound of the frame's (slices share bricks), and culled
/// the smallest; a flag holds when it held for any slice.
void addSlice(FrameStats& frame, const FrameStats& slice);

} // namespace bc::render
