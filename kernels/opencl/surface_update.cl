/* Coupled mesh, per frame (paper Section 5; host reference: host/src/embed/deform_surface.cpp).
 * Compiled only with -DCOROFEM_SURFACE (DESIGN: no surface kernel without a surface mesh), so the
 * file adds nothing to the solver's program, which concatenates every .cl file of kernels/opencl.
 *
 * Three passes, one work-item per vertex or triangle, no atomics: the normals are gathered per
 * vertex over its incident triangles in the fixed (ascending) CSR order built on the host, so two
 * runs give the same bits.
 *   1 surface_positions     x_v = sum_k w_vk x_{n_vk}                      (k = 0..3)
 *   2 surface_face_vectors  f_t = (x_b - x_a) x (x_c - x_a),  |f_t| = 2 area(t)
 *   3 surface_normals       n_v = normalise(sum_{t at v} f_t)  (area-weighted mean of face normals),
 *                           written with x_v + c as 6 floats per vertex (renderer vertex buffer).
 * The node positions may be relative to an offset c (the OpenCL backend keeps them relative to the
 * body's centroid so that float keeps its accuracy far from the origin): the weights sum to 1, so
 * sum_k w_vk (x_{n_vk} - c) + c = x_v. Passes 1-2 work on the relative positions (the face vectors
 * are differences, c cancels); pass 3 adds c to the position it writes. c = 0 for absolute input.
 */
#ifdef COROFEM_SURFACE
#ifndef COROFEM_EMBEDDED
#include "../shared/corofem_layout.h"
#endif

/* nodes: 4 node indices per vertex; weights: 4 barycentric coordinates per vertex (sum 1; negative
 * ones extrapolate for vertices outside the tet mesh); x: 3 reals per tet node; pos: 3 per vertex. */
__kernel void surface_positions(const uint vertexCount, __global const uint4* restrict nodes,
                                __global const real4* restrict weights, __global const real* restrict x,
                                __global real* restrict pos) {
  const uint v = (uint)get_global_id(0);
  if (v >= vertexCount) return;
  const uint4 n = nodes[v];
  const real4 w = weights[v];
  for (uint a = 0; a < 3; ++a)
    pos[3 * v + a] = w.x * x[3 * n.x + a] + w.y * x[3 * n.y + a] + w.z * x[3 * n.z + a] + w.w * x[3 * n.w + a];
}

/* triangles: 3 vertex indices per triangle; faces: 3 reals per triangle. */
__kernel void surface_face_vectors(const uint triangleCount, __global const uint* restrict triangles,
                                   __global const real* restrict pos, __global real* restrict faces) {
  const uint t = (uint)get_global_id(0);
  if (t >= triangleCount) return;
  const uint a = triangles[3 * t], b = triangles[3 * t + 1], c = triangles[3 * t + 2];
  const real3 xa = (real3)(pos[3 * a], pos[3 * a + 1], pos[3 * a + 2]);
  const real3 e1 = (real3)(pos[3 * b], pos[3 * b + 1], pos[3 * b + 2]) - xa;
  const real3 e2 = (real3)(pos[3 * c], pos[3 * c + 1], pos[3 * c + 2]) - xa;
  faces[3 * t] = e1.y * e2.z - e1.z * e2.y;
  faces[3 * t + 1] = e1.z * e2.x - e1.x * e2.z;
  faces[3 * t + 2] = e1.x * e2.y - e1.y * e2.x;
}

/* offsets/incident: CSR vertex -> incident triangles (ascending). out: 6 floats per vertex
 * (position + c, unit normal); the normal of a vertex without a non-degenerate triangle is 0.
 * The offset c of the node positions (0 for absolute positions) comes as c = chi + clo, both in the
 * device precision: in float, chi = (float)c and clo = (float)(c - chi), so that the small relative
 * position takes clo first and the sum rounds once, at the output's magnitude (half an ulp of |x|)
 * instead of twice (c itself rounded to float, then the sum). In double, clo = 0. */
__kernel void surface_normals(const uint vertexCount, __global const uint* restrict offsets,
                              __global const uint* restrict incident, __global const real* restrict faces,
                              __global const real* restrict pos, __global float* restrict out,
                              const real chix, const real chiy, const real chiz, const real clox,
                              const real cloy, const real cloz) {
  const uint v = (uint)get_global_id(0);
  if (v >= vertexCount) return;
  real3 n = (real3)(0, 0, 0);
  const uint end = offsets[v + 1];
  for (uint q = offsets[v]; q < end; ++q) {
    const uint t = incident[q];
    n += (real3)(faces[3 * t], faces[3 * t + 1], faces[3 * t + 2]);
  }
  const real length = sqrt(n.x * n.x + n.y * n.y + n.z * n.z);
  const real scale = length > (real)0 ? (real)1 / length : (real)0;
  __global float* dst = out + 6 * (size_t)v;
  dst[0] = (float)((pos[3 * v] + clox) + chix);
  dst[1] = (float)((pos[3 * v + 1] + cloy) + chiy);
  dst[2] = (float)((pos[3 * v + 2] + cloz) + chiz);
  dst[3] = (float)(n.x * scale);
  dst[4] = (float)(n.y * scale);
  dst[5] = (float)(n.z * scale);
}
#endif /* COROFEM_SURFACE */
