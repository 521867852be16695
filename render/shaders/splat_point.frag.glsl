#version 450 core
// A point: its coverage spread over the pixels under its filter (footprint weights), or all
// of it on the nearest pixel when no pixel centre lies under the filter (vShape.w = 1).
#include "footprint.inc.glsl"

flat in vec4 vColour;
flat in vec4 vShape;
out vec4 outColor;
void main() {
    float w = 1.0;
    if (vShape.w == 0.0) {
        float d = length(gl_FragCoord.xy - 0.5 - vShape.xy) * vShape.z;
        if (!(d < 1.0)) discard;
        w = footprint(d);
    }
    float cover = vColour.w * w;
    outColor = vec4(cover * vColour.rgb, cover);
}
