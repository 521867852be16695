#version 450 core
// The pixel's eye ray against the sphere centre: distance in radii is the footprint index
// after correctedDistance (render/SplatGeometry.h), exact in perspective and orthographic.
#include "footprint.inc.glsl"

uniform vec2 uViewport;
uniform vec3 uForward, uRight, uUp;
uniform float uFocal, uOrthoScale, uInvRadius;
uniform bool uOrtho;
flat in vec4 vColour;
flat in vec4 vShape;
out vec4 outColor;
void main() {
    vec2 p = vec2(gl_FragCoord.x - 0.5 * uViewport.x, 0.5 * uViewport.y - gl_FragCoord.y);
    vec3 rel = vShape.xyz;
    float d;
    if (uOrtho) {
        vec2 q = p / uOrthoScale;
        d = length(cross(rel - q.x * uRight - q.y * uUp, uForward));
    } else {
        vec3 w = normalize(uForward + (p.x / uFocal) * uRight + (p.y / uFocal) * uUp);
        if (!(dot(w, rel) > 0.0)) discard;
        d = length(cross(rel, w));
    }
    d *= uInvRadius;
    if (!(d < 1.0)) discard;
    float a = 1.0 - exp(-vColour.w * footprint(d));
    outColor = vec4(a * vColour.rgb, a);
}
