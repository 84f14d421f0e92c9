/* Coupled mesh, per frame (paper Section 5; host reference: host/src/embed/deform_surface.cpp).
 * Compiled only with -DCOROFEM_SURFACE (DESIGN: no surface kernel without a surface mesh), so the
 * file adds nothing to the solver's program, which concatenates every .cl file of kernels/opencl.
 *
 * Two passes (and a small third for rare vertices), no atomics, fixed summation order, so two runs
 * give the same bits:
 *   1 surface_positions  x_v = sum_k w_vk x_{n_vk}   (k = 0..3), into a scratch of 3 streams
 *                        (x, y, z, each of stride S >= vertex count: structure of arrays).
 *   2 surface_normals    n_v = normalise( sum_i (x_{r_i} - x_v) x (x_{r_{i+1}} - x_v) ),  i = 0..K-1
 *                        cyclically (r_K = r_0), over the vertex's one-ring r_0..r_{K-1} (K slots,
 *                        stream i at ring + i S), written with x_v + c as 6 floats per vertex.
 *   3 surface_normals_overflow   the same sum over a longer one-ring, for the few vertices whose
 *                        one-ring does not fit in K slots (pass 2 wrote a zero normal for them).
 * Why pass 2 is the area-weighted normal of deformSurface: for a triangle (a, b, c) at v = a the
 * ring holds b, c consecutively and (x_b - x_a) x (x_c - x_a) is its face vector f_t (|f_t| = 2 area);
 * at v = b (or c) the pair is (c, a) (or (a, b)) and the cross product of the edges from v is the
 * same f_t (it is invariant under cyclic relabelling). A closed fan r_0..r_{L-1} of L triangles
 * (v, r_i, r_{i+1}) needs L slots; an open fan, a second fan or a lone triangle is ended by a slot
 * holding v itself, and every term with v in it is exactly 0 (x_v - x_v = 0), as are padding slots
 * (v). The host (device_surface.cpp) builds the rings from the binding's triangles. So per vertex
 * the face vectors are recomputed from the one-ring instead of stored per triangle: no face buffer,
 * no triangle list, no per-triangle pass.
 *
 * Pass 2 works on SURF_W consecutive vertices at once in vector types (lanes = vertices, the
 * structure-of-arrays streams load as vectors). Where one ring slot of those SURF_W vertices holds
 * SURF_W consecutive vertices (a regular mesh numbered row by row, as the benchmark's UV sphere), the
 * neighbours' positions are one vector load; otherwise they are gathered lane by lane. Which slots of
 * a block are such runs, and where each starts, is found once on the host (blockRuns), so the kernel
 * compares no ring entries per slot (one bit says which way) and reads none for such a slot (a
 * row-by-row mesh then streams SURF_K + 1 words per block instead of SURF_K per vertex). Both paths
 * read the same values, so the result does not depend on which ran. SURF_W = 1 (GPUs) is one vertex per
 * work-item in scalars: there the lanes are the work-items of a warp, whose loads of consecutive
 * vertices coalesce, and 16-wide vectors per work-item would only cost registers and occupancy.
 *
 * The node positions may be relative to an offset c (the OpenCL backend keeps them relative to the
 * body's centroid so that float keeps its accuracy far from the origin): the weights sum to 1, so
 * sum_k w_vk (x_{n_vk} - c) + c = x_v. The edge vectors are differences (c cancels); pass 2 adds c to
 * the position it writes.
 *
 * Build options: SURF_K ring slots per vertex, SURF_W vertices per vector (1, 8 or 16), SURF_VPW
 * vertices per work-item in pass 1, SURF_BPW blocks of SURF_W vertices per work-item in pass 2
 * (several per work-item amortise PoCL's per-work-item cost on a CPU; 1 on a GPU).
 */
#ifdef COROFEM_SURFACE
#ifndef COROFEM_EMBEDDED
#include "../shared/corofem_layout.h"
#endif

#ifndef SURF_K
#define SURF_K 6
#endif
#ifndef SURF_W
#define SURF_W 16
#endif
#ifndef SURF_VPW
#define SURF_VPW 1
#endif
#ifndef SURF_BPW
#define SURF_BPW 1
#endif

/* nodes: 4 node indices per vertex; weights: 4 barycentric coordinates per vertex (sum 1; negative
 * ones extrapolate for vertices outside the tet mesh); xAll: 3 reals per tet node, the body's nodes
 * from node firstNode on (a batch keeps many bodies in one buffer); pos: the scratch, component a
 * of vertex v at pos[a * S + v]. */
__kernel void surface_positions(const uint vertexCount, const uint S, __global const uint4* restrict nodes,
                                __global const real4* restrict weights, __global const real* restrict xAll,
                                __global real* restrict pos, const uint firstNode) {
  __global const real* restrict x = xAll + 3 * (size_t)firstNode;  /* the body's nodes in a shared buffer */
  const uint v0 = (uint)get_global_id(0) * SURF_VPW;
  const uint v1 = min(v0 + SURF_VPW, vertexCount);
  for (uint v = v0; v < v1; ++v) {
    const uint4 n = nodes[v];
    const real4 w = weights[v];
    const real3 p = w.x * vload3(n.x, x) + w.y * vload3(n.y, x) + w.z * vload3(n.z, x) + w.w * vload3(n.w, x);
    pos[v] = p.x;
    pos[S + v] = p.y;
    pos[2 * S + v] = p.z;
  }
}

/* Vector types of SURF_W lanes. */
#define SURF_CAT2(a, b) a##b
#define SURF_CAT(a, b) SURF_CAT2(a, b)
#if SURF_W == 1
typedef real realW;
typedef uint uintW;
typedef float floatW;
#define VLOADW(p) (*(p))
#define CONVERT_FLOATW(x) ((float)(x))
#define GATHERW(p, i) ((p)[(i)])
#define SURF_INV_LENGTH(l2) ((l2) > (realW)0 ? (realW)1 / sqrt(l2) : (realW)0)
#else
#ifdef COROFEM_DOUBLE
typedef SURF_CAT(double, SURF_W) realW;
#else
typedef SURF_CAT(float, SURF_W) realW;
#endif
typedef SURF_CAT(uint, SURF_W) uintW;
typedef SURF_CAT(float, SURF_W) floatW;
#define VLOADW(p) SURF_CAT(vload, SURF_W)(0, (p))
#define CONVERT_FLOATW SURF_CAT(convert_float, SURF_W)
#define SURF_INV_LENGTH(l2) select((realW)0, (realW)1 / sqrt(l2), (l2) > (realW)0)
#endif

#if SURF_W == 1
/* one vertex per work-item: no lane helpers */
#elif SURF_W == 8
#define GATHERW(p, i) ((realW)((p)[(i).s0], (p)[(i).s1], (p)[(i).s2], (p)[(i).s3], (p)[(i).s4], (p)[(i).s5], \
                               (p)[(i).s6], (p)[(i).s7]))
#elif SURF_W == 16
#define GATHERW(p, i) ((realW)((p)[(i).s0], (p)[(i).s1], (p)[(i).s2], (p)[(i).s3], (p)[(i).s4], (p)[(i).s5], \
                               (p)[(i).s6], (p)[(i).s7], (p)[(i).s8], (p)[(i).s9], (p)[(i).sa], (p)[(i).sb], \
                               (p)[(i).sc], (p)[(i).sd], (p)[(i).se], (p)[(i).sf]))
#else
#error "SURF_W must be 1, 8 or 16"
#endif

#if SURF_W > 1
/* The first `count` (< SURF_W) lanes' (a, b, c), lane l at d + l * stride (the last, partial block). */
inline void surf_store_partial(__global float* d, uint stride, uint count, floatW a, floatW b, floatW c) {
  const float* pa = (const float*)&a;
  const float* pb = (const float*)&b;
  const float* pc = (const float*)&c;
  for (uint l = 0; l < count; ++l) {
    d[stride * l] = pa[l];
    d[stride * l + 1] = pb[l];
    d[stride * l + 2] = pc[l];
  }
}
#endif

/* Interleaves 8 vertices' (a, b, c) into 24 floats at d (one separate stream). */
inline void surf_store8x3(__global float* d, float8 a, float8 b, float8 c) {
  vstore8((float8)(a.s0, b.s0, c.s0, a.s1, b.s1, c.s1, a.s2, b.s2), 0, d);
  vstore8((float8)(c.s2, a.s3, b.s3, c.s3, a.s4, b.s4, c.s4, a.s5), 0, d + 8);
  vstore8((float8)(b.s5, c.s5, a.s6, b.s6, c.s6, a.s7, b.s7, c.s7), 0, d + 16);
}

/* Interleaves 8 vertices' position (ox, oy, oz) and normal (mx, my, mz) into 48 floats at d. */
inline void surf_store8(__global float* d, float8 ox, float8 oy, float8 oz, float8 mx, float8 my, float8 mz) {
  vstore8((float8)(ox.s0, oy.s0, oz.s0, mx.s0, my.s0, mz.s0, ox.s1, oy.s1), 0, d);
  vstore8((float8)(oz.s1, mx.s1, my.s1, mz.s1, ox.s2, oy.s2, oz.s2, mx.s2), 0, d + 8);
  vstore8((float8)(my.s2, mz.s2, ox.s3, oy.s3, oz.s3, mx.s3, my.s3, mz.s3), 0, d + 16);
  vstore8((float8)(ox.s4, oy.s4, oz.s4, mx.s4, my.s4, mz.s4, ox.s5, oy.s5), 0, d + 24);
  vstore8((float8)(oz.s5, mx.s5, my.s5, mz.s5, ox.s6, oy.s6, oz.s6, mx.s6), 0, d + 32);
  vstore8((float8)(my.s6, mz.s6, ox.s7, oy.s7, oz.s7, mx.s7, my.s7, mz.s7), 0, d + 40);
}

/* The positions (x, y, z) of ring slot i of the SURF_W vertices v.., relative to theirs (xx, xy, xz).
 * runMask = runs[0] (from the host, per block) has bit i set when the slot holds SURF_W consecutive
 * vertices q, q + 1, .. (a mesh numbered row by row), and then runs[1 + i] = q: the neighbours are vector
 * loads and the slot's ring entries are not read at all. Otherwise the entries are read and the
 * neighbours gathered lane by lane. Both read the same positions. */
#if SURF_W == 1
#define SURF_NEIGHBOUR(i, bx, by, bz)           \
  {                                             \
    const uint q = ring[(i) * S + v];           \
    bx = px[q] - xx;                            \
    by = py[q] - xy;                            \
    bz = pz[q] - xz;                            \
  }
#else
#define SURF_NEIGHBOUR(i, bx, by, bz)                     \
  if ((runMask >> (i)) & 1u) {                            \
    const uint q = runs[1 + (i)];                         \
    bx = VLOADW(px + q) - xx;                             \
    by = VLOADW(py + q) - xy;                             \
    bz = VLOADW(pz + q) - xz;                             \
  } else {                                                \
    const uintW r = VLOADW(ring + (i) * S + v);           \
    bx = GATHERW(px, r) - xx;                             \
    by = GATHERW(py, r) - xy;                             \
    bz = GATHERW(pz, r) - xz;                             \
  }
#endif

/* ring: SURF_K streams of stride S (slot i of vertex v at ring[i * S + v]; entries of the padding
 * vertices v >= vertexCount hold v). out: 6 floats per vertex (position + c, unit normal); with
 * SURF_SEPARATE (DeviceSurfaceOptions::separateStreams) two streams of 3 floats per vertex instead,
 * the positions in out and the normals in nout (not read otherwise). The normal of a vertex without a
 * non-degenerate triangle is 0. The offset c of the node positions (0 for
 * absolute positions) comes as c = chi + clo, both in the device precision: in float, chi = (float)c
 * and clo = (float)(c - chi), so that the small relative position takes clo first and the sum rounds
 * once, at the output's magnitude (half an ulp of |x|) instead of twice (c itself rounded to float,
 * then the sum). In double, clo = 0. S is a multiple of SURF_W; the scratch's padding is zero.
 * blockRuns: per block of SURF_W vertices SURF_K + 1 words: which ring slots hold SURF_W consecutive
 * vertices (bit i), then each such slot's first vertex (SURF_NEIGHBOUR); not read with SURF_W = 1.
 * SURF_MULTI (many bodies' surfaces in one set of launches, each body's vertices starting at a block
 * boundary): the offset of the block's body, blockBody[v / SURF_W], is read from bodyOffsets (chi xyz,
 * clo xyz per body) instead of the scalar arguments; not read otherwise. */
__kernel void surface_normals(const uint vertexCount, const uint S, __global const uint* restrict ring,
                              __global const real* restrict pos, __global float* restrict out, const real chix,
                              const real chiy, const real chiz, const real clox, const real cloy, const real cloz,
                              __global const uint* restrict blockRuns, __global float* restrict nout,
                              __global const uint* restrict blockBody, __global const real* restrict bodyOffsets) {
  __global const real* px = pos;
  __global const real* py = pos + S;
  __global const real* pz = pos + 2 * S;
  for (uint blk = 0; blk < SURF_BPW; ++blk) {
    const uint v = ((uint)get_global_id(0) * SURF_BPW + blk) * SURF_W;
    if (v >= vertexCount) return;
    const realW xx = VLOADW(px + v), xy = VLOADW(py + v), xz = VLOADW(pz + v);
#if SURF_W > 1
    __global const uint* runs = blockRuns + (v / SURF_W) * (SURF_K + 1);
    const uint runMask = runs[0];
#endif
    realW fx, fy, fz;
    SURF_NEIGHBOUR(0, fx, fy, fz)
    realW ax = fx, ay = fy, az = fz, nx = 0, ny = 0, nz = 0;
    for (uint i = 1; i < SURF_K; ++i) {
      realW bx, by, bz;
      SURF_NEIGHBOUR(i, bx, by, bz)
      nx += ay * bz - az * by;
      ny += az * bx - ax * bz;
      nz += ax * by - ay * bx;
      ax = bx;
      ay = by;
      az = bz;
    }
    nx += ay * fz - az * fy;  /* the closing term (r_{K-1}, r_0) */
    ny += az * fx - ax * fz;
    nz += ax * fy - ay * fx;
    const realW length2 = nx * nx + ny * ny + nz * nz;
    const realW scale = SURF_INV_LENGTH(length2);
#ifdef SURF_MULTI
    __global const real* c = bodyOffsets + 6 * blockBody[v / SURF_W];
    const real hx = c[0], hy = c[1], hz = c[2], lx = c[3], ly = c[4], lz = c[5];
#else
    const real hx = chix, hy = chiy, hz = chiz, lx = clox, ly = cloy, lz = cloz;
#endif
    const floatW ox = CONVERT_FLOATW((xx + lx) + hx), oy = CONVERT_FLOATW((xy + ly) + hy),
                 oz = CONVERT_FLOATW((xz + lz) + hz);
    const floatW mx = CONVERT_FLOATW(nx * scale), my = CONVERT_FLOATW(ny * scale), mz = CONVERT_FLOATW(nz * scale);
    /* position and normal of vertex v at pdst and ndst; vertex v + l at + l * SURF_STRIDE */
#ifdef SURF_SEPARATE
#define SURF_STRIDE 3u
    __global float* pdst = out + 3 * (size_t)v;
    __global float* ndst = nout + 3 * (size_t)v;
#else
#define SURF_STRIDE 6u
    __global float* pdst = out + 6 * (size_t)v;
    __global float* ndst = pdst + 3;
#endif
#if SURF_W == 1
    pdst[0] = ox;
    pdst[1] = oy;
    pdst[2] = oz;
    ndst[0] = mx;
    ndst[1] = my;
    ndst[2] = mz;
#else
    if (v + SURF_W <= vertexCount) {
#if defined(SURF_SEPARATE) && SURF_W == 8
      surf_store8x3(pdst, ox, oy, oz);
      surf_store8x3(ndst, mx, my, mz);
#elif defined(SURF_SEPARATE)
      surf_store8x3(pdst, ox.lo, oy.lo, oz.lo);
      surf_store8x3(pdst + 24, ox.hi, oy.hi, oz.hi);
      surf_store8x3(ndst, mx.lo, my.lo, mz.lo);
      surf_store8x3(ndst + 24, mx.hi, my.hi, mz.hi);
#elif SURF_W == 8
      surf_store8(pdst, ox, oy, oz, mx, my, mz);
#else
      surf_store8(pdst, ox.lo, oy.lo, oz.lo, mx.lo, my.lo, mz.lo);
      surf_store8(pdst + 48, ox.hi, oy.hi, oz.hi, mx.hi, my.hi, mz.hi);
#endif
    } else {  /* the last, partial block */
      surf_store_partial(pdst, SURF_STRIDE, vertexCount - v, ox, oy, oz);
      surf_store_partial(ndst, SURF_STRIDE, vertexCount - v, mx, my, mz);
    }
#endif
  }
}

/* The vertices whose one-ring does not fit in SURF_K slots (pass 2 wrote their position and a zero
 * normal): vertex verts[k]'s ring is sequence[offsets[k] .. offsets[k + 1]), same rules, summed in
 * the same cyclic order. */
__kernel void surface_normals_overflow(const uint count, __global const uint* restrict verts,
                                       __global const uint* restrict offsets, __global const uint* restrict sequence,
                                       const uint S, __global const real* restrict pos,
                                       __global float* restrict out, __global float* restrict nout) {
  const uint k = (uint)get_global_id(0);
  if (k >= count) return;
  const uint v = verts[k];
  const real3 xv = (real3)(pos[v], pos[S + v], pos[2 * S + v]);
  const uint begin = offsets[k], end = offsets[k + 1];
  uint q = sequence[begin];
  const real3 first = (real3)(pos[q], pos[S + q], pos[2 * S + q]) - xv;
  real3 a = first, n = (real3)(0, 0, 0);
  for (uint i = begin + 1; i < end; ++i) {
    q = sequence[i];
    const real3 b = (real3)(pos[q], pos[S + q], pos[2 * S + q]) - xv;
    n += (real3)(a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x);
    a = b;
  }
  n += (real3)(a.y * first.z - a.z * first.y, a.z * first.x - a.x * first.z, a.x * first.y - a.y * first.x);
  const real length2 = n.x * n.x + n.y * n.y + n.z * n.z;
  const real scale = length2 > (real)0 ? (real)1 / sqrt(length2) : (real)0;
#ifdef SURF_SEPARATE
  __global float* dst = nout + 3 * (size_t)v;
#else
  __global float* dst = out + 6 * (size_t)v + 3;
#endif
  dst[0] = (float)(n.x * scale);
  dst[1] = (float)(n.y * scale);
  dst[2] = (float)(n.z * scale);
}
#endif /* COROFEM_SURFACE */
