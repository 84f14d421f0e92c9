#version 450
/* The warped smoothed-aggregation multigrid preconditioner ("amg", host/src/precond/amg.hpp): one
 * symmetric V-cycle u = M^-1 r per PCG iteration, the passes of kernels/opencl/amg.cl (which has the
 * derivation) in one shader, pc.mode choosing the pass.
 *
 * Level 0 is the bodies' own dofs (node passes, one invocation per node, work-groups of 64 nodes of
 * one segment; a stopped segment's work-groups return at once); its operator is the current A (the
 * device's matrix-free product, element.comp and gather.comp from d0 into ad0, or from u into ad0)
 * with the inverses of its 3x3 node blocks that pcg.comp formed in minv, scaled per segment by
 * 1 / lambda_max, so that Chebyshev's interval is the same [1/30, 1] for every body. Coarser levels
 * hold every body's rows end to end (host/src/device/device_amg.hpp): the rest operators,
 * prolongations and restrictions in sliced ELLPACK, the dense inverses of the coarsest operators in
 * CSR. The warp turns each node's 3-vector by its aggregate's rotation (9 reals, row-major) before
 * the restriction (R^T) and after the prolongation (R).
 *
 * This shader's bindings differ from common.glsl's where the AMG's data goes; the host binds them
 * in a descriptor set of its own over the shared layout. Packed buffers, parts chosen by push
 * constants (pc.o0 .. pc.o5, in entries):
 *   amgIdx  uint: the ELLPACK slice starts and columns, the CSR starts and columns, the node table
 *   amgVal  real: the ELLPACK values, the coarse inverse diagonals, the per-segment scale, the rotations
 *   amgVec  real: e0 (3 per device node), then per coarse level b, x, res, d, t
 *   amgInv  real: the coarsest inverses' values
 *
 * Chebyshev smoothing of A x = b over [1/30, 1] of the scaled D^-1 A, degree 2:
 *   begin:  res = b - A x (x = 0: res = b), d = D^-1 res / theta, x += d
 *   step:   res -= A d, d = c1 d + c2 D^-1 res, x += d */
#extension GL_GOOGLE_include_directive : require
#include "precision.glsl"

#define COROFEM_GLSL 1
#include "../shared/corofem_layout.h"

layout(local_size_x = 64) in;

layout(std430, binding = 0) readonly buffer SegInfo { uint segInfo[]; };
layout(std430, binding = 1) readonly buffer AmgIdx { uint amgIdx[]; };
layout(std430, binding = 2) readonly buffer AmgVal { real amgVal[]; };
layout(std430, binding = 3) readonly buffer NodeSeg { uint nodeSeg[]; };
layout(std430, binding = 4) buffer AmgVec { real amgVec[]; };
layout(std430, binding = 5) readonly buffer AmgInv { real amgInv[]; };
layout(std430, binding = 6) buffer Res0 { real res0[]; };
layout(std430, binding = 7) buffer D0 { real d0[]; };
layout(std430, binding = 8) readonly buffer Ad0 { real ad0[]; };
layout(std430, binding = 12) readonly buffer Free { real freeDof[]; };
layout(std430, binding = 14) readonly buffer Minv { real minv[]; };
layout(std430, binding = 17) readonly buffer VecB { real bvec[]; };
layout(std430, binding = 19) readonly buffer VecR { real rvec[]; };
layout(std430, binding = 20) buffer VecU { real uvec[]; };
layout(std430, binding = 24) writeonly buffer Partials { real partials[]; };

layout(push_constant) uniform Push {
  uint S, mode, flags, precond, rotation;  /* common.glsl's; mode: kMode* below */
  uint rows;                               /* coarse passes: rows of the level */
  uint o0, o1, o2, o3, o4, o5;             /* offsets (entries) into the packed buffers, per pass */
} pc;

const uint kModeFineBegin = 0u, kModeFineStep = 1u, kModeUnwarp = 2u, kModeWarpAdd = 3u, kModeSpmv = 4u,
           kModeCoarseBegin = 5u, kModeCoarseStep = 6u, kModeCoarseAdd = 7u, kModeCoarsest = 8u;
const uint kFlagZero = 1u;      /* begin passes: x = 0 (res = b) */
const uint kFlagLast = 2u;      /* fine step: the cycle's end, the partial sums for reduce.comp */
const uint kFlagSetup = 4u;     /* fine step's sums: |free b|^2 too (the PCG set-up's) */
const uint kFlagResidual = 8u;  /* spmv: y = b - A x */

/* 1 / theta and the step's c1, c2 for [1/30, 1] (engine_amg.cpp's Chebyshev, computed in double). */
#ifdef COROFEM_DOUBLE
const real kInvTheta = 1.9354838709677418LF, kC1 = 0.7779833487511559LF, kC2 = 3.4412580943570754LF;
#else
const real kInvTheta = 1.9354838709677418, kC1 = 0.7779833487511559, kC2 = 3.4412580943570754;
#endif

shared real s0[64], s1[64], s2[64];

/* Node n's block inverse applied to r. */
void apply_block(uint n, in real r[3], out real z[3]) {
  for (uint i = 0u; i < 3u; ++i)
    z[i] = minv[9u * n + 3u * i] * r[0] + minv[9u * n + 3u * i + 1u] * r[1] + minv[9u * n + 3u * i + 2u] * r[2];
}

/* The level-0 passes: node n of segment s (false where the node is padding). */
bool fine_node(out uint n, out uint s) {
  n = gl_GlobalInvocationID.x;
  s = nodeSeg[gl_WorkGroupID.x];
  return n < segInfo[kSegInfoCount * s + kSegNodeEnd];
}

void main() {
  const uint mode = pc.mode;
  if (mode <= kModeWarpAdd) {
    /* Level 0: whole work-groups of a stopped segment return (its partial sums are not read). */
    if (segInfo[kSegInfoCount * nodeSeg[gl_WorkGroupID.x] + kSegActive] == 0u) return;
    uint n, s;
    const bool node = fine_node(n, s);
    if (mode == kModeFineBegin) {
      if (!node) return;
      /* res = r - ad0 (kFlagZero: res = r, u = 0 before), d = s B^-1 res / theta, u += d. */
      const real sc = amgVal[pc.o0 + s] * kInvTheta;
      real rn[3], zn[3];
      for (uint k = 0u; k < 3u; ++k) rn[k] = (pc.flags & kFlagZero) != 0u ? rvec[3u * n + k] : rvec[3u * n + k] - ad0[3u * n + k];
      apply_block(n, rn, zn);
      for (uint k = 0u; k < 3u; ++k) {
        const uint i = 3u * n + k;
        const real dk = sc * zn[k];
        res0[i] = rn[k];
        d0[i] = dk;
        uvec[i] = (pc.flags & kFlagZero) != 0u ? dk : uvec[i] + dk;
      }
    } else if (mode == kModeFineStep) {
      /* res -= ad0, d = c1 d + c2 s B^-1 res, u += d; kFlagLast: the partial sums r . u, r . r
       * (and |free b|^2 with kFlagSetup) of the node work-group, as pcg.comp leaves them. */
      real ru = real(0), rr = real(0), bb = real(0);
      if (node) {
        const real sc = amgVal[pc.o0 + s] * kC2;
        real rn[3], zn[3];
        for (uint k = 0u; k < 3u; ++k) rn[k] = res0[3u * n + k] - ad0[3u * n + k];
        apply_block(n, rn, zn);
        for (uint k = 0u; k < 3u; ++k) {
          const uint i = 3u * n + k;
          const real dk = kC1 * d0[i] + sc * zn[k];
          const real uk = uvec[i] + dk;
          res0[i] = rn[k];
          d0[i] = dk;
          uvec[i] = uk;
          ru += rvec[i] * uk;
          rr += rvec[i] * rvec[i];
          const real fb = freeDof[i] * bvec[i];
          bb += fb * fb;
        }
      }
      if ((pc.flags & kFlagLast) == 0u) return;
      const uint lid = gl_LocalInvocationID.x;
      s0[lid] = ru;
      s1[lid] = rr;
      s2[lid] = (pc.flags & kFlagSetup) != 0u ? bb : real(0);
      barrier();
      for (uint h = 32u; h > 0u; h >>= 1u) {
        if (lid < h) {
          s0[lid] += s0[lid + h];
          s1[lid] += s1[lid + h];
          s2[lid] += s2[lid + h];
        }
        barrier();
      }
      if (lid == 0u) {
        const uint g = gl_WorkGroupID.x;
        partials[3u * g] = s0[0];
        partials[3u * g + 1u] = s1[0];
        partials[3u * g + 2u] = s2[0];
      }
    } else if (mode == kModeUnwarp) {
      /* e0 = R^T (r - ad0) per node, R its aggregate's rotation (none: R = I). */
      if (!node) return;
      real v[3];
      for (uint k = 0u; k < 3u; ++k) v[k] = rvec[3u * n + k] - ad0[3u * n + k];
      const int a = int(amgIdx[pc.o0 + n]);
      if (a < 0) {
        for (uint k = 0u; k < 3u; ++k) amgVec[3u * n + k] = v[k];
        return;
      }
      const uint R = pc.o1 + 9u * uint(a);
      for (uint k = 0u; k < 3u; ++k)
        amgVec[3u * n + k] = amgVal[R + k] * v[0] + amgVal[R + 3u + k] * v[1] + amgVal[R + 6u + k] * v[2];
    } else {
      /* u += free (R e0). */
      if (!node) return;
      const int a = int(amgIdx[pc.o0 + n]);
      real v[3];
      if (a < 0) {
        for (uint k = 0u; k < 3u; ++k) v[k] = amgVec[3u * n + k];
      } else {
        const uint R = pc.o1 + 9u * uint(a);
        for (uint k = 0u; k < 3u; ++k)
          v[k] = amgVal[R + 3u * k] * amgVec[3u * n] + amgVal[R + 3u * k + 1u] * amgVec[3u * n + 1u] +
                 amgVal[R + 3u * k + 2u] * amgVec[3u * n + 2u];
      }
      for (uint k = 0u; k < 3u; ++k) uvec[3u * n + k] += freeDof[3u * n + k] * v[k];
    }
    return;
  }

  /* Coarse levels: one invocation per row of every body. */
  const uint i = gl_GlobalInvocationID.x;
  if (i >= pc.rows) return;
  if (mode == kModeSpmv) {
    /* y = A x, or b - A x (kFlagResidual); A in slices of 16 rows from amgIdx[o0] (starts relative
     * to o1 / o2), columns at amgIdx[o1], values at amgVal[o2]; x, b, y at amgVec[o3], [o4], [o5].
     * Padding (value 0) is skipped, not multiplied: its column belongs to another body. */
    const uint sl = i / 16u, begin = amgIdx[pc.o0 + sl] + i % 16u, end = amgIdx[pc.o0 + sl + 1u];
    real sum = real(0);
    for (uint j = begin; j < end; j += 16u) {
      const real v = amgVal[pc.o2 + j];
      if (v != real(0)) sum += v * amgVec[pc.o3 + amgIdx[pc.o1 + j]];
    }
    amgVec[pc.o5 + i] = (pc.flags & kFlagResidual) != 0u ? amgVec[pc.o4 + i] - sum : sum;
  } else if (mode == kModeCoarseBegin) {
    /* dinv at amgVal[o0]; b, ax, res, d, x at amgVec[o1 .. o5]. */
    const bool zero = (pc.flags & kFlagZero) != 0u;
    const real ri = zero ? amgVec[pc.o1 + i] : amgVec[pc.o1 + i] - amgVec[pc.o2 + i];
    const real di = kInvTheta * amgVal[pc.o0 + i] * ri;
    amgVec[pc.o3 + i] = ri;
    amgVec[pc.o4 + i] = di;
    amgVec[pc.o5 + i] = zero ? di : amgVec[pc.o5 + i] + di;
  } else if (mode == kModeCoarseStep) {
    /* dinv at amgVal[o0]; ad, res, d, x at amgVec[o1 .. o4]. */
    const real ri = amgVec[pc.o2 + i] - amgVec[pc.o1 + i];
    const real di = kC1 * amgVec[pc.o3 + i] + kC2 * amgVal[pc.o0 + i] * ri;
    amgVec[pc.o2 + i] = ri;
    amgVec[pc.o3 + i] = di;
    amgVec[pc.o4 + i] += di;
  } else if (mode == kModeCoarseAdd) {
    amgVec[pc.o1 + i] += amgVec[pc.o0 + i];
  } else if (mode == kModeCoarsest) {
    /* y = A^-1 b on the rows of the bodies whose coarsest level this is (rows with entries; the
     * others unchanged): CSR starts at amgIdx[o0], columns amgIdx[o1], values amgInv[o2]; b, y at
     * amgVec[o3], [o4]. */
    const uint begin = amgIdx[pc.o0 + i], end = amgIdx[pc.o0 + i + 1u];
    if (begin == end) return;
    real sum = real(0);
    for (uint j = begin; j < end; ++j) sum += amgInv[pc.o2 + j] * amgVec[pc.o3 + amgIdx[pc.o1 + j]];
    amgVec[pc.o4 + i] = sum;
  }
}
