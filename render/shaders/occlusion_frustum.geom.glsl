#version 450 core
// One point per block in, the block's frustum out: the block's pixel rectangle (enlarged by
// half a pixel, so neighbours overlap and no ray slips between them) extruded from the
// captured frame's eye, from the block's nearest first hit less a margin to beyond the box.
layout(points) in;
layout(triangle_strip, max_vertices = 24) out;
flat in int vIndex[];
layout(std430, binding = 3) readonly buffer Blocks { float blockDepth[]; };
uniform ivec2 uBlocks;
uniform int uK;
uniform vec2 uOldSize;
uniform vec3 uOldEye, uOldForward, uOldRight, uOldUp;
uniform bool uOldOrtho;
uniform float uMargin, uNearMin, uFar;
uniform mat4 uViewProj;
out vec3 vWorld;
vec3 corner(vec2 s, float z) {
    return uOldOrtho ? uOldEye + s.x * uOldRight + s.y * uOldUp + z * uOldForward
                     : uOldEye + z * (uOldForward + s.x * uOldRight + s.y * uOldUp);
}
void emitQuad(vec3 a, vec3 b, vec3 c, vec3 d) {
    vWorld = a; gl_Position = uViewProj * vec4(a, 1.0); EmitVertex();
    vWorld = b; gl_Position = uViewProj * vec4(b, 1.0); EmitVertex();
    vWorld = c; gl_Position = uViewProj * vec4(c, 1.0); EmitVertex();
    vWorld = d; gl_Position = uViewProj * vec4(d, 1.0); EmitVertex();
    EndPrimitive();
}
void main() {
    int i = vIndex[0];
    float zb = blockDepth[i];
    if (zb >= 1.0e37) return;
    ivec2 b = ivec2(i % uBlocks.x, i / uBlocks.x);
    vec2 s0 = 2.0 * (vec2(b * uK) - 0.5) / uOldSize - 1.0;
    vec2 s1 = 2.0 * (vec2((b + 1) * uK) + 0.5) / uOldSize - 1.0;
    float zn = max(zb - uMargin, uNearMin);
    vec3 c[8];
    for (int k = 0; k < 8; ++k)
        c[k] = corner(vec2((k & 1) != 0 ? s1.x : s0.x, (k & 2) != 0 ? s1.y : s0.y),
                      (k & 4) != 0 ? uFar : zn);
    emitQuad(c[0], c[1], c[2], c[3]);
    emitQuad(c[4], c[5], c[6], c[7]);
    emitQuad(c[0], c[2], c[4], c[6]);
    emitQuad(c[1], c[3], c[5], c[7]);
    emitQuad(c[0], c[1], c[4], c[5]);
    emitQuad(c[2], c[3], c[6], c[7]);
}
