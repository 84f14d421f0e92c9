#version 450
// Two-sided Lambert shading of the interpolated smooth normal, a warm tissue colour.
layout(location = 0) in vec3 worldNormal;
layout(push_constant) uniform Push {
  mat4 mvp;
  vec4 light;
} pc;
layout(location = 0) out vec4 colour;
void main() {
  const vec3 n = normalize(worldNormal);
  const float lambert = abs(dot(n, pc.light.xyz));
  const vec3 base = vec3(0.72, 0.25, 0.22);
  colour = vec4(base * (0.25 + 0.75 * lambert), 1.0);
}
