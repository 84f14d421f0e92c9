#version 450
// The deformed surface straight from corofem's buffer: per vertex 6 float32, position then unit
// normal (Simulation::surfaceBuffer, the interleaved layout), bound as vertex buffer 0.
layout(location = 0) in vec3 position;
layout(location = 1) in vec3 normal;
layout(push_constant) uniform Push {
  mat4 mvp;    // world to Vulkan clip space (y down, depth 0..1)
  vec4 light;  // unit direction towards the light, world space
} pc;
layout(location = 0) out vec3 worldNormal;
void main() {
  worldNormal = normal;
  gl_Position = pc.mvp * vec4(position, 1.0);
}
