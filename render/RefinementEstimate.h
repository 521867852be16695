#pragma once
// The error of a frame at rest, estimated as it is refined. A frame at rest is
// refined by halving the step: the session's step, then half of it, a quarter... Each pass
// after the first is compared with the one before, and that difference estimates the pass's
// own error against the converged image (render/ConvergedReference.h): where halving the step
// halves the error (first-order quadrature: e(s) = 2 e(s/2)), |f(s) - f(s/2)| = e(s/2), so the
// PSNR of the pass against the previous one is the pass's own PSNR; the estimate adds 6.02 dB
// (a factor of 2) since on the shared scans each halving gains 7-10 dB while far from
// converged, which keeps the estimate on the safe side of the truth. Near convergence the
// 8-bit frames stop improving (the CPU raycaster's frames agree with the converged image to
// 52-67 dB at their finest steps on the shared scans), so no estimate exceeds kMaxEstimateDb.
//
// The first pass needs a pass before it. Where the renderer draws a stride (RenderOptions::
// stride, the CPU raycaster) and the frame is large enough, the daemon draws the first pass at
// half the session's step and checks it against a sparse frame at the session's step: the
// pixels of a lattice of about kCheckPixels (checkStride()), each exactly as the whole frame at
// that step would have it. The estimate is then the same formula over the lattice's pixels, a
// sample of the frame's. The sparse frame costs about kCheckPixels rays, where the whole frame
// at the session's step cost a ray per pixel (a 512^2 frame: a sixteenth).
// What was measured: docs/benchmarks/budgets.md; the test: tests/render/RefinementEstimateTest.
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

namespace bc::render {

/// The highest PSNR an estimate claims, and so the highest bound a client may ask for.
inline constexpr double kMaxEstimateDb = 50.0;
/// No refinement pass samples finer than this (voxels).
inline constexpr double kFinestRefinementStep = 1.0 / 16.0;
/// The fewest pixels of the sparse frame a first pass is checked against (checkStride()).
inline constexpr std::uint64_t kCheckPixels = 128 * 128;

/// PSNR (dB) of `a` against `b`, both 8-bit RGBA of the same size, over R, G and B (the
/// colours composited over black when premultiplied); +infinity when they are equal.
/// @throw std::invalid_argument when the sizes differ or are not whole pixels.
double psnrRgb8(std::span<const std::uint8_t> a, std::span<const std::uint8_t> b);

/// What a halving of the step is taken to gain beyond the difference it makes (the 6.02 dB
/// above): composite and the projections. Not the isosurface: a surface thinner than the step
/// is missed between samples until a step resolves it, so its error falls slower than the
/// halvings' differences say (the measurement that showed it: docs/benchmarks/modes.md, "each
/// mode under load").
inline constexpr double kHalvingGainDb = 6.020599913279624; ///< 20 log10(2): a factor of 2

/// The estimated PSNR against the converged image of refinement pass `finer`, given the pass
/// before it at twice its step, `coarser`: psnrRgb8(finer, coarser) + `gainDb`, at most
/// kMaxEstimateDb.
double estimatedPsnrDb(std::span<const std::uint8_t> finer, std::span<const std::uint8_t> coarser,
                       double gainDb = kHalvingGainDb);

/// The stride of the lattice a first pass of width x height is checked against: the largest
/// whose lattice (PixelLattice) holds kCheckPixels pixels or more; 1 when the frame is too
/// small for a sparse check (under 256 x 256), and its first pass is drawn at the session's step.
std::uint32_t checkStride(std::uint32_t width, std::uint32_t height);

/// The pixels of PixelLattice{stride} of a width x height 8-bit RGBA frame, as a frame of the
/// lattice's size (what RenderOptions::stride draws).
/// @throw std::invalid_argument when the frame is not width x height pixels.
std::vector<std::uint8_t> latticeOf(std::span<const std::uint8_t> rgba8, std::uint32_t width,
                                    std::uint32_t height, std::uint32_t stride);

/// The step of refinement pass `pass` (0: the session's `step`): step / 2^pass.
double refinementStep(double step, std::uint32_t pass);

/// Whether a pass at `step` that reached `estimateDb` (negative: no estimate yet, the first
/// pass) is followed by another at half the step under a bound of `boundDb` dB (> 0).
bool refineFurther(double estimateDb, double boundDb, double step);

} // namespace bc::render
