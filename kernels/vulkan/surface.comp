#version 450
/* The coupled mesh per frame (paper Section 5; host reference: host/src/embed/deform_surface.cpp;
 * the OpenCL version: kernels/opencl/surface_update.cl), for the surfaces of one or more bodies of a
 * device, one vertex per invocation, two dispatches with a barrier between them:
 *   mode 0  x_v = sum_k w_vk x_{n_vk}  (k = 0..3) into `scratch` (3 reals per vertex), from the
 *           device's positions (binding 7, the same buffer as common.glsl's, relative to the body's
 *           centroid c; the weights sum to 1, so c can be added afterwards).
 *   mode 1  n_v = normalise( sum_i (x_{r_i} - x_v) x (x_{r_{i+1 mod L}} - x_v) ) over the vertex's
 *           one-ring r_0..r_{L-1} (host/src/embed/one_ring.hpp: the sum of the face vectors of its
 *           triangles, the area-weighted normal of deformSurface; 0 for a vertex without a
 *           non-degenerate triangle), written with x_v + c as float32: 6 per vertex (position,
 *           normal), or with flag 1 (separate streams) 3 per vertex into `outv` and 3 into `nout`.
 * c = chi + clo, both in the shader's precision (float: chi = (float)c, clo = (float)(c - chi)), so
 * that the small relative position takes clo first and rounds once at the output's magnitude.
 * No atomics and a fixed order: two runs give the same bits.
 *
 * It uses the shared descriptor-set layout's first ten bindings (binding 7 being the device's
 * positions); the host binds a placeholder at the others. */
#extension GL_GOOGLE_include_directive : require
#include "precision.glsl"

layout(local_size_x = 64) in;

layout(std430, binding = 0) readonly buffer SurfNodes { uint nodes[]; };          /* 4 device nodes per vertex */
layout(std430, binding = 1) readonly buffer SurfWeights { real weights[]; };      /* 4 per vertex */
layout(std430, binding = 2) readonly buffer RingStart { uint ringStart[]; };      /* vertex count + 1 */
layout(std430, binding = 3) readonly buffer RingEntry { uint ringEntry[]; };      /* vertices of the rings */
layout(std430, binding = 4) readonly buffer VertexMember { uint vertexMember[]; };  /* the body of each vertex */
layout(std430, binding = 5) readonly buffer MemberOffsets { real memberOffsets[]; };  /* chi xyz, clo xyz */
layout(std430, binding = 6) buffer Scratch { real scratch[]; };                   /* 3 per vertex */
layout(std430, binding = 7) readonly buffer Pos { real pos[]; };                  /* the device's positions */
layout(std430, binding = 8) writeonly buffer Out { float outv[]; };
layout(std430, binding = 9) writeonly buffer NormalOut { float nout[]; };

layout(push_constant) uniform Push {
  uint S;     /* vertex count */
  uint mode;  /* 0 positions, 1 normals */
  uint flags; /* 1: separate streams */
  uint unused0;
  uint unused1;
} pc;

void main() {
  const uint v = gl_GlobalInvocationID.x;
  if (v >= pc.S) return;
  if (pc.mode == 0u) {
    real p[3] = real[3](real(0), real(0), real(0));
    for (uint k = 0u; k < 4u; ++k) {
      const uint n = nodes[4u * v + k];
      const real w = weights[4u * v + k];
      for (uint j = 0u; j < 3u; ++j) p[j] += w * pos[3u * n + j];
    }
    for (uint j = 0u; j < 3u; ++j) scratch[3u * v + j] = p[j];
    return;
  }
  const real xx = scratch[3u * v], xy = scratch[3u * v + 1u], xz = scratch[3u * v + 2u];
  const uint begin = ringStart[v], end = ringStart[v + 1u];
  real nx = real(0), ny = real(0), nz = real(0);
  if (end > begin) {
    uint q = ringEntry[begin];
    const real fx = scratch[3u * q] - xx, fy = scratch[3u * q + 1u] - xy, fz = scratch[3u * q + 2u] - xz;
    real ax = fx, ay = fy, az = fz;
    for (uint i = begin + 1u; i < end; ++i) {
      q = ringEntry[i];
      const real bx = scratch[3u * q] - xx, by = scratch[3u * q + 1u] - xy, bz = scratch[3u * q + 2u] - xz;
      nx += ay * bz - az * by;
      ny += az * bx - ax * bz;
      nz += ax * by - ay * bx;
      ax = bx;
      ay = by;
      az = bz;
    }
    nx += ay * fz - az * fy; /* the closing term (r_{L-1}, r_0) */
    ny += az * fx - ax * fz;
    nz += ax * fy - ay * fx;
  }
  const real length2 = nx * nx + ny * ny + nz * nz;
  const real scale = length2 > real(0) ? real(1) / sqrt(length2) : real(0);
  const uint m = vertexMember[v];
  const real p[3] = real[3]((xx + memberOffsets[6u * m + 3u]) + memberOffsets[6u * m],
                            (xy + memberOffsets[6u * m + 4u]) + memberOffsets[6u * m + 1u],
                            (xz + memberOffsets[6u * m + 5u]) + memberOffsets[6u * m + 2u]);
  const real n[3] = real[3](nx * scale, ny * scale, nz * scale);
  if ((pc.flags & 1u) != 0u) {
    for (uint j = 0u; j < 3u; ++j) {
      outv[3u * v + j] = float(p[j]);
      nout[3u * v + j] = float(n[j]);
    }
  } else {
    for (uint j = 0u; j < 3u; ++j) {
      outv[6u * v + j] = float(p[j]);
      outv[6u * v + 3u + j] = float(n[j]);
    }
  }
}
