#pragma once
// Renderers by name: the daemon, the command-line tools and the benchmarks create them here
// instead of switching over the kinds they know (OSPRay's renderer factory). "auto", the
// default of the programs, is not a kind: resolveRenderer (RendererChoice.h) turns it into
// "gpu" or "cpu" once, before a renderer is created here.
#include "render/Renderer.h"

#include <functional>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

namespace bc::render {

/// One kind of renderer.
struct RendererKind {
    std::string name;
    std::string description;
    bool needsGl = false; ///< needs a current EglContext to be created and to draw
    /// Holds nothing of one viewer (no previous frame, no camera path): one instance may serve
    /// every viewer of a volume (the reference, which holds the volume's voxels).
    bool sharedPerVolume = false;
    /// Draws RenderOptions::region alone, at a cost that follows what the region shows (the
    /// raycasters by its pixels; the splatters by the bricks that reach it): the daemon draws
    /// long frames of these in slices. Every built-in renderer does.
    bool regions = false;
    /// Its cost follows the voxels it projects (the splatters), not pixels x samples per ray.
    bool objectOrder = false;
    /// Draws RenderOptions::parts (one part of the brick grid, render/SCALEOUT.md): the
    /// daemon's MPI ranks draw its frames together (the raycasters).
    bool parts = false;
    /// Draws RenderOptions::stride, every stride-th pixel (the CPU raycaster): the daemon
    /// checks its first refinement pass at rest against a sparse frame at twice its step.
    bool strided = false;
    std::function<std::unique_ptr<Renderer>()> create;
};

class RendererRegistry {
  public:
    /// The built-in renderers: gpu, cpu, reference, splat, splat-gpu.
    static const RendererRegistry& builtin();

    void add(RendererKind kind);
    /// The kind named `name`, or nullptr.
    const RendererKind* find(std::string_view name) const;
    /// A new renderer of kind `name`. @throw std::invalid_argument naming the kinds when there
    /// is none; what its constructor throws (RenderError without a GL context).
    std::unique_ptr<Renderer> create(std::string_view name) const;
    std::vector<std::string> names() const;

  private:
    std::vector<RendererKind> mKinds;
};

} // namespace bc::render
