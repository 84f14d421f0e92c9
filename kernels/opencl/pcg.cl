/* Matrix-free preconditioned conjugate gradients on the projected system (constrained dofs: identity
 * rows and columns, their entries of x, r, z, p kept at 0). All scalars live in `scalars` on the
 * device (layout in corofem_layout.h); the host only reads them every checkEvery iterations.
 * Vectors are `real`; the dot products, their partials and the scalars are `sum_real` (double in
 * mixed precision, COROFEM_MIXED: float vectors and products, double sums and scalars). A kernel
 * that updates vectors converts its scalar to `real` once (a no-op unless mixed).
 * One iteration (q = A p by element_product + gather_product, which also gives p . q per group):
 *   reduce_finish(Alpha):  alpha = rho / (p . q)
 *   pcg_update:            x += alpha p, r -= alpha q, z = M^-1 r, partial sums of r . z and r . r
 *   reduce_finish(Beta):   beta = (r . z)_new / rho, rho = (r . z)_new, rr = r . r
 *   pcg_direction:         p = z + beta p
 * Dot products are two-stage and deterministic: fixed-order partial sums (corofem_reduce.h), then
 * one work-group per segment summing the segment's partials in a fixed order.
 * Many bodies (segments, corofem_layout.h) iterate together, each with its own scalars; a segment
 * that has converged is marked inactive by the host and its work-groups return at once.
 */
#ifndef COROFEM_EMBEDDED
#include "../shared/corofem_layout.h"
#include "../shared/corofem_reduce.h"
#endif

/* z = M^-1 r for the dofs of node n (M^-1 from precond_invert). */
COROFEM_FN void apply_preconditioner(uint n, __global const real* minv, const real* r, real* z) {
#if defined(COROFEM_PRECOND_BLOCK)
  __global const real* m = minv + 9 * n;
  z[0] = m[0] * r[0] + m[1] * r[1] + m[2] * r[2];
  z[1] = m[3] * r[0] + m[4] * r[1] + m[5] * r[2];
  z[2] = m[6] * r[0] + m[7] * r[1] + m[8] * r[2];
#elif defined(COROFEM_PRECOND_DIAG)
  z[0] = minv[3 * n] * r[0];
  z[1] = minv[3 * n + 1] * r[1];
  z[2] = minv[3 * n + 2] * r[2];
#else
  z[0] = r[0];
  z[1] = r[1];
  z[2] = r[2];
#endif
}

/* r = free (b - A x), z = M^-1 r, p = z; partials (r . z, r . r, |free b|^2). */
__kernel __attribute__((reqd_work_group_size(COROFEM_WG, 1, 1)))
void pcg_init(__global const uint* restrict nodeSeg, __global const uint* restrict segInfo,
              __global const real* restrict b, __global const real* restrict q,
              __global const real* restrict free, __global const real* restrict minv,
              __global real* restrict r, __global real* restrict z, __global real* restrict p,
              __global sum_real* restrict partials) {
  COROFEM_PARTIAL_LOCALS
  COROFEM_NODE_RANGE(nodeSeg, segInfo, s, first, last);
  sum_real rz = 0, rr = 0, bb = 0;
  for (uint n = first; n < last; ++n) {
    real rn[3], zn[3];
    #pragma unroll
    for (int k = 0; k < 3; ++k) {
      const uint d = 3 * n + k;
      const real bd = free[d] * b[d];
      rn[k] = bd - free[d] * q[d];
      bb += (sum_real)bd * (sum_real)bd;
    }
    apply_preconditioner(n, minv, rn, zn);
    #pragma unroll
    for (int k = 0; k < 3; ++k) {
      const uint d = 3 * n + k;
      r[d] = rn[k];
      z[d] = zn[k];
      p[d] = zn[k];
      rz += (sum_real)rn[k] * (sum_real)zn[k];
      rr += (sum_real)rn[k] * (sum_real)rn[k];
    }
  }
  COROFEM_PARTIAL_STORE(rz, rr, bb, partials);
}

/* x += alpha p, r -= alpha q, z = M^-1 r; partials (r . z, r . r, 0). */
__kernel __attribute__((reqd_work_group_size(COROFEM_WG, 1, 1)))
void pcg_update(__global const uint* restrict nodeSeg, __global const uint* restrict segInfo,
                __global const sum_real* restrict scalars, __global const real* restrict p,
                __global const real* restrict q, __global const real* restrict minv,
                __global real* restrict x, __global real* restrict r, __global real* restrict z,
                __global sum_real* restrict partials) {
  COROFEM_PARTIAL_LOCALS
  COROFEM_NODE_RANGE(nodeSeg, segInfo, s, first, last);
  const real alpha = (real)scalars[kScalarCount * s + kScalarAlpha];
  sum_real rz = 0, rr = 0;
  for (uint n = first; n < last; ++n) {
    real rn[3], zn[3];
    #pragma unroll
    for (int k = 0; k < 3; ++k) {
      const uint d = 3 * n + k;
      x[d] += alpha * p[d];
      rn[k] = r[d] - alpha * q[d];
      r[d] = rn[k];
    }
    apply_preconditioner(n, minv, rn, zn);
    #pragma unroll
    for (int k = 0; k < 3; ++k) {
      z[3 * n + k] = zn[k];
      rz += (sum_real)rn[k] * (sum_real)zn[k];
      rr += (sum_real)rn[k] * (sum_real)rn[k];
    }
  }
  COROFEM_PARTIAL_STORE(rz, rr, (sum_real)0, partials);
}

/* p = z + beta p, COROFEM_CHUNK nodes per work-item like the other PCG node kernels (one dof per
 * work-item made this trivial kernel cost as much as pcg_update on PoCL). */
__kernel __attribute__((reqd_work_group_size(COROFEM_WG, 1, 1)))
void pcg_direction(__global const uint* restrict nodeSeg, __global const uint* restrict segInfo,
                   __global const sum_real* restrict scalars, __global const real* restrict z,
                   __global real* restrict p) {
  COROFEM_NODE_RANGE(nodeSeg, segInfo, s, first, last);
  const real beta = (real)scalars[kScalarCount * s + kScalarBeta];
  for (uint d = 3 * first; d < 3 * last; ++d) p[d] = z[d] + beta * p[d];
}

/* Second stage of the dot products: work-group s sums segment s's partial triples in a fixed order
 * (strided lanes, then a tree: the same order for a body alone or in a batch), then updates the
 * segment's PCG scalars according to `mode` (kReduceInit/Alpha/Beta). A non-positive p . A p (A
 * not positive definite on the free dofs, or p = 0) sets alpha = 0 and the breakdown flag instead
 * of dividing. */
__kernel __attribute__((reqd_work_group_size(COROFEM_WG, 1, 1)))
void reduce_finish(__global const uint* restrict segInfo, __global const sum_real* restrict partials,
                   __global sum_real* restrict allScalars, const uint mode) {
  __local sum_real s0[COROFEM_WG], s1[COROFEM_WG], s2[COROFEM_WG];
  const uint lid = get_local_id(0), seg = get_global_id(0) / COROFEM_WG;
  if (seg_info(segInfo, seg, kSegActive) == 0u) return; /* the whole work-group */
  const uint partialCount = seg_info(segInfo, seg, kSegPartialCount);
  __global const sum_real* own = partials + kPartialComponents * seg_info(segInfo, seg, kSegPartialBegin);
  __global sum_real* scalars = allScalars + kScalarCount * seg;
  sum_real a = 0, b = 0, c = 0;
  for (uint g = lid; g < partialCount; g += COROFEM_WG) {
    a += own[kPartialComponents * g];
    b += own[kPartialComponents * g + 1];
    c += own[kPartialComponents * g + 2];
  }
  s0[lid] = a;
  s1[lid] = b;
  s2[lid] = c;
  barrier(CLK_LOCAL_MEM_FENCE);
  for (uint s = COROFEM_WG / 2; s > 0; s >>= 1) {
    if (lid < s) {
      s0[lid] += s0[lid + s];
      s1[lid] += s1[lid + s];
      s2[lid] += s2[lid + s];
    }
    barrier(CLK_LOCAL_MEM_FENCE);
  }
  if (lid != 0) return;
  if (mode == kReduceInit) {
    scalars[kScalarRho] = s0[0];
    scalars[kScalarRr] = s1[0];
    scalars[kScalarBb] = s2[0];
    scalars[kScalarAlpha] = 0;
    scalars[kScalarBeta] = 0;
    scalars[kScalarBreakdown] = 0;
  } else if (mode == kReduceAlpha) {
    const sum_real pq = s0[0];
    scalars[kScalarPq] = pq;
    if (pq > (sum_real)0) {
      scalars[kScalarAlpha] = scalars[kScalarRho] / pq;
    } else {
      scalars[kScalarAlpha] = 0;
      scalars[kScalarBreakdown] = 1;
    }
  } else {
    const sum_real rho = scalars[kScalarRho], rhoNew = s0[0];
    scalars[kScalarBeta] = rho != (sum_real)0 ? rhoNew / rho : (sum_real)0;
    scalars[kScalarRho] = rhoNew;
    scalars[kScalarRr] = s1[0];
  }
}
