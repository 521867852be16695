#version 450 core
// Quads over pixel rectangles; GL window row = image row (row 0 at the top of the image is
// row 0 of the target), so the read-back needs no flip.
layout(location = 0) in vec4 aRect;
layout(location = 1) in vec4 aColour;
layout(location = 2) in vec4 aShape;
uniform vec2 uViewport;
flat out vec4 vColour;
flat out vec4 vShape;
void main() {
    vec2 corner = vec2(float(gl_VertexID & 1), float(gl_VertexID >> 1));
    vec2 pixel = mix(aRect.xy, aRect.zw + 1.0, corner);
    gl_Position = vec4(pixel / uViewport * 2.0 - 1.0, 0.0, 1.0);
    vColour = aColour;
    vShape = aShape;
}
