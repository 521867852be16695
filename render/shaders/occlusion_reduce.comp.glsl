#version 450 core
// One invocation per k x k block: the nearest eye-space depth of the block's first hits and
// those of the one-pixel ring around it (so an occluder between two blocks' rays counts).
layout(local_size_x = 8, local_size_y = 8) in;
layout(binding = 0) uniform sampler2D uFirstHit;   // ray parameter (mm); >= 1e37: no hit
layout(std430, binding = 3) writeonly buffer Blocks { float blockDepth[]; };
uniform ivec2 uSize, uBlocks;
uniform int uK;
uniform vec3 uForward, uRight, uUp;
uniform bool uOrtho;
void main() {
    ivec2 b = ivec2(gl_GlobalInvocationID.xy);
    if (b.x >= uBlocks.x || b.y >= uBlocks.y) return;
    ivec2 lo = max(b * uK - 1, ivec2(0)), hi = min((b + 1) * uK + 1, uSize);
    float z = 3.0e38;
    for (int y = lo.y; y < hi.y; ++y)
        for (int x = lo.x; x < hi.x; ++x) {
            float t = texelFetch(uFirstHit, ivec2(x, y), 0).r;
            if (t >= 1.0e37) continue;
            vec2 s = 2.0 * (vec2(x, y) + 0.5) / vec2(uSize) - 1.0;
            float c = uOrtho ? 1.0 : dot(normalize(uForward + s.x * uRight + s.y * uUp), uForward);
            z = min(z, t * c);
        }
    blockDepth[b.y * uBlocks.x + b.x] = z;
}
