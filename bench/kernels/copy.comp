// Streaming copy of 16-byte words that bench_vulkan times as the yardstick of the device's memory
// rate (the Vulkan counterpart of bandwidth.cl): each invocation copies every total-th word from
// its own index, so any buffer size runs in a fixed number of work-groups.
#version 450
layout(local_size_x = 256) in;
layout(std430, set = 0, binding = 0) readonly buffer Src { uvec4 src[]; };
layout(std430, set = 0, binding = 1) writeonly buffer Dst { uvec4 dst[]; };
layout(push_constant) uniform Push { uint count; } push;

void main() {
  const uint total = gl_NumWorkGroups.x * gl_WorkGroupSize.x;
  for (uint i = gl_GlobalInvocationID.x; i < push.count; i += total) dst[i] = src[i];
}
