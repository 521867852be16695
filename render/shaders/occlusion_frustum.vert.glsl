#version 450 core
// One point per block of the captured frame: the geometry shader reads its block by index.
flat out int vIndex;
void main() { vIndex = gl_VertexID; gl_Position = vec4(0.0); }
