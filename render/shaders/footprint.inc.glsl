// The splat footprint texture, for splat.frag.glsl and splat_point.frag.glsl. Linear between
// neighbouring texels with full-precision weights: filtering hardware may quantise them (8
// bits on many GPUs). GpuSplatter::sampleFootprint is the CPU twin. BC_FOOTPRINT_TEXELS is
// GpuSplatter::kFootprintTexels, defined by the C++ (README.md).
const int kTexels = BC_FOOTPRINT_TEXELS;
layout(binding = 0) uniform sampler1D uFootprint;
float footprint(float d) {
    float u = clamp(d, 0.0, 1.0) * float(kTexels - 1);
    int i = min(int(u), kTexels - 2);
    return mix(texelFetch(uFootprint, i, 0).r, texelFetch(uFootprint, i + 1, 0).r, u - float(i));
}
