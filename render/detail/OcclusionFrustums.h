#pragma once
// Occlusion frustums (Mensmann, Ropinski, Hinrichs 2008) as ray-start proxies: the
// raycaster writes a first-hit image (the ray parameter of each ray's first sample in an
// occupied leaf or brick); blocks of k x k pixels keep their nearest first hit; each
// non-empty block becomes a frustum extruded away from that frame's eye; the volume box
// minus that frame's view frustum is added. Rendering the union's nearest faces from the
// next frame's camera gives each of its rays a start. Built on the GPU (a compute shader
// reduces the blocks, a geometry shader extrudes them: render/shaders/occlusion_*.glsl). Render
// thread only; needs a current EglContext. Design and policy: render/OCCLUSION.md.
#include "render/Camera.h"
#include "render/RenderTypes.h"
#include "render/detail/Gl.h"

#include <cstdint>
#include <vector>

namespace bc::render::detail {

class OcclusionFrustums {
  public:
    OcclusionFrustums();

    /// Before a frame: builds the ray-start texture for `view` from the last captured frame,
    /// if that frame had the same `sceneKey` and size and the policy allows. `cellMm` is the
    /// occupancy cell edge (leaf or brick) and `stepMm` the sample distance: both bound what
    /// can hide between the last frame's rays.
    /// Fills stats.occlusion*; returns true when the ray-start texture is to be used.
    bool prepare(const ViewBasis& view, std::uint32_t width, std::uint32_t height, const Box& box,
                 std::uint64_t sceneKey, double cellMm, double stepMm,
                 const OcclusionConfig& config, FrameStats& stats);
    /// The ray-start texture (ray parameter in mm, +huge where no proxy), valid after a
    /// prepare() that returned true.
    GLuint startTexture() const { return mStart.get(); }
    /// The first-hit image the raycaster writes this frame (r32f, cleared by beginFrame).
    GLuint firstHitTexture() const { return mFirstHit.get(); }
    /// Clears the first-hit image for a frame of this size.
    void beginFrame(std::uint32_t width, std::uint32_t height);
    /// After a frame: keeps its first-hit image, reduced to blocks, for the next frame, and
    /// what the frame cost with or without proxies (for the policy).
    void capture(const ViewBasis& view, std::uint64_t sceneKey, double frameMs, bool proxiesUsed,
                 const OcclusionConfig& config);
    /// Forgets the last frame (the next frame uses the plain box).
    void invalidate() { mValid = false; }

  private:
    void ensureTargets(std::uint32_t width, std::uint32_t height);
    std::uint32_t drawOutsidePieces(const ViewBasis& view, const Box& box);

    gl::Program mReduce, mFrustum, mPieces;
    gl::VertexArray mVao;
    gl::Texture mFirstHit, mStart;
    gl::Framebuffer mStartFbo;
    gl::Buffer mBlocks, mPieceVertices;
    std::uint32_t mWidth = 0, mHeight = 0, mBlocksX = 0, mBlocksY = 0, mBlockPixels = 0;
    std::vector<float> mBlockDepth; ///< the last capture's blocks (eye-space depth, mm)
    ViewBasis mView;                ///< the last captured frame's camera
    std::uint64_t mSceneKey = 0;
    bool mValid = false;
    std::uint32_t mOffFor = 0;  ///< policy: frames left without proxies
    std::uint32_t mUsedRun = 0; ///< frames with proxies since the last plain one
    double mPlainMs = -1.0;     ///< the last comparable frame without proxies
    bool mComparable = false;   ///< this frame's refusal leaves it comparable
};

} // namespace bc::render::detail
