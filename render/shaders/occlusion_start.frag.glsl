#version 450 core
// The ray parameter of the surface point, for the frame being drawn; blended with MIN.
in vec3 vWorld;
uniform vec3 uEye, uForward;
uniform bool uOrtho;
layout(location = 0) out float outT;
void main() { outT = uOrtho ? dot(vWorld - uEye, uForward) : length(vWorld - uEye); }
