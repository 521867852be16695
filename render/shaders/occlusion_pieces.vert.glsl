#version 450 core
// The volume box outside the captured frame's view, as triangles in world space.
layout(location = 0) in vec3 aPosition;
uniform mat4 uViewProj;
out vec3 vWorld;
void main() { vWorld = aPosition; gl_Position = uViewProj * vec4(aPosition, 1.0); }
