#version 450 core
// The slab as one layer: summed coverage clamped to 1, coverage-weighted colour.
layout(binding = 1) uniform sampler2D uSlab;
out vec4 outColor;
void main() {
    vec4 s = texelFetch(uSlab, ivec2(gl_FragCoord.xy), 0);
    if (!(s.a > 0.0)) discard;
    float a = min(s.a, 1.0);
    outColor = vec4(s.rgb * (a / s.a), a);
}
