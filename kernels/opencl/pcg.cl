/* Matrix-free preconditioned conjugate gradients on the projected system (constrained dofs: identity
 * rows and columns, their entries of x, r, u, p, w, s kept at 0), in the single-reduction form of
 * Chronopoulos and Gear (1989; "Method 1" of D'Azevedo, Eijkhout and Romine 1993, PETSc's
 * KSPCGUseSingleReduction). Mathematically the same iterates as the textbook PCG; per iteration it
 * needs one global reduction instead of two, so one iteration is 4 launches instead of 6:
 *   pcg_update:            p = u + beta p,  s = w + beta s   (s = A p, by recurrence)
 *                          x += alpha p,    r -= alpha s,    u = M^-1 r
 *                          partials of gamma' = r . u and r . r
 *   element_product(u) + gather_product:  w = A u, partials of delta' = u . w
 *   reduce_finish(Step):   beta = gamma' / gamma, alpha = gamma' / (delta' - beta gamma' / alpha)
 * (the iteration cap's last iteration has no successor: pcg_update and reduce_finish(Last) only)
 * Why the denominator is p . A p: with s_i = A p_i, (p_{i+1}, A p_{i+1}) = (u_{i+1}, w_{i+1}) +
 * beta (u_{i+1}, A p_i) (A-conjugacy drops (p_i, A p_{i+1})), and A p_i = (r_i - r_{i+1}) / alpha_i
 * with (u_{i+1}, r_i) = 0 gives (u_{i+1}, A p_i) = -gamma_{i+1} / alpha_i.
 * Set-up (r = b - A x, u = M^-1 r, w = A u, p = s = 0, alpha_0 = gamma_0 / delta_0, beta_0 = 0) costs
 * one product more than the textbook form; afterwards both do one product per iteration.
 * All scalars live in `scalars` on the device (layout in corofem_layout.h); the host reads them
 * without blocking after every checkEvery iterations. Vectors are `real`; the dot products, their partials and the scalars
 * are `sum_real` (double in mixed precision, COROFEM_MIXED: float vectors and products, double sums
 * and scalars). A kernel that updates vectors converts its scalars to `real` once (a no-op unless
 * mixed). Dot products are two-stage and deterministic: fixed-order partial sums (corofem_reduce.h),
 * then one work-group per segment summing the segment's partials in a fixed order; pcg_update
 * writes its partials to `partials`, gather_product to `partialsW`.
 * Many bodies (segments, corofem_layout.h) iterate together, each with its own scalars; a segment
 * that has stopped is marked inactive by reduce_finish itself and its work-groups return at once.
 */
#ifndef COROFEM_EMBEDDED
#include "../shared/corofem_layout.h"
#include "../shared/corofem_reduce.h"
#include "precond.cl"
#endif

/* z = M^-1 r with the node's inverse m in private memory (as node_preconditioner formed it). */
COROFEM_FN void apply_node_inverse(const real* m, const real* r, real* z) {
#if defined(COROFEM_PRECOND_BLOCK)
  z[0] = m[0] * r[0] + m[1] * r[1] + m[2] * r[2];
  z[1] = m[3] * r[0] + m[4] * r[1] + m[5] * r[2];
  z[2] = m[6] * r[0] + m[7] * r[1] + m[8] * r[2];
#else
  z[0] = m[0] * r[0];
  z[1] = m[1] * r[1];
  z[2] = m[2] * r[2];
#endif
}

/* z = M^-1 r for the dofs of node n (M^-1 as pcg_init stored it; the identity without a
 * preconditioner). */
COROFEM_FN void apply_preconditioner(uint n, __global const real* minv, const real* r, real* z) {
#if defined(COROFEM_PRECOND_BLOCK) || defined(COROFEM_PRECOND_DIAG)
  real m[COROFEM_NODE_INVERSE];
  #pragma unroll
  for (int k = 0; k < COROFEM_NODE_INVERSE; ++k) m[k] = minv[COROFEM_NODE_INVERSE * n + k];
  apply_node_inverse(m, r, z);
#else
  z[0] = r[0];
  z[1] = r[1];
  z[2] = r[2];
#endif
}

/* M^-1 of the solve's coefficients from the node blocks (node_preconditioner, precond.cl), stored
 * for pcg_update; r = free (b - A x) (q = A x; zeroStart != 0: x = 0, q is not read), u = M^-1 r,
 * p = s = 0; partials (r . u, r . r, |free b|^2). */
__kernel __attribute__((reqd_work_group_size(COROFEM_WG, 1, 1)))
void pcg_init(__global const uint* restrict nodeSeg, __global const uint* restrict segInfo,
              __global const real* restrict segCoef, __global const real* restrict blocks,
              __global const real* restrict mass, const uint zeroStart, __global const real* restrict b,
              __global const real* restrict q, __global const real* restrict free, __global real* restrict minv,
              __global real* restrict r, __global real* restrict u, __global real* restrict p,
              __global real* restrict sv, __global sum_real* restrict partials) {
  COROFEM_PARTIAL_LOCALS
  COROFEM_NODE_RANGE(nodeSeg, segInfo, s, first, last);
#if defined(COROFEM_PRECOND_BLOCK) || defined(COROFEM_PRECOND_DIAG)
  const real massCoef = seg_coef(segCoef, s, kCoefMass), stiffCoef = seg_coef(segCoef, s, kCoefStiff);
#endif
  sum_real ru = 0, rr = 0, bb = 0;
  for (uint n = first; n < last; ++n) {
#if defined(COROFEM_PRECOND_BLOCK) || defined(COROFEM_PRECOND_DIAG)
    real m[COROFEM_NODE_INVERSE];
    node_preconditioner(n, massCoef, stiffCoef, blocks, mass, free, m);
    #pragma unroll
    for (int k = 0; k < COROFEM_NODE_INVERSE; ++k) minv[COROFEM_NODE_INVERSE * n + k] = m[k];
#endif
    real rn[3], un[3];
    #pragma unroll
    for (int k = 0; k < 3; ++k) {
      const uint d = 3 * n + k;
      const real bd = free[d] * b[d];
      rn[k] = zeroStart ? bd : bd - free[d] * q[d];
      bb += (sum_real)bd * (sum_real)bd;
    }
#if defined(COROFEM_PRECOND_BLOCK) || defined(COROFEM_PRECOND_DIAG)
    apply_node_inverse(m, rn, un);  /* from the private inverse, not a read back of what was stored */
#else
    apply_preconditioner(n, minv, rn, un);
#endif
    #pragma unroll
    for (int k = 0; k < 3; ++k) {
      const uint d = 3 * n + k;
      r[d] = rn[k];
      u[d] = un[k];
      p[d] = (real)0;
      sv[d] = (real)0;
      ru += (sum_real)rn[k] * (sum_real)un[k];
      rr += (sum_real)rn[k] * (sum_real)rn[k];
    }
  }
  COROFEM_PARTIAL_STORE(ru, rr, bb, partials);
}

/* The update of pcg_update for the nodes [first, last): p = u + beta p, s = w + beta s,
 * x += alpha p, r -= alpha s, u = M^-1 r; the work-item's sums r . u, r . r into sums[0], sums[1]
 * (pcg_update, and the update phase of pcg_iterate_group: the same code, so the same bits). */
COROFEM_FN void pcg_update_nodes(uint first, uint last, real alpha, real beta, __global const real* w,
                                 __global const real* minv, __global real* p, __global real* sv, __global real* x,
                                 __global real* r, __global real* u, sum_real* sums) {
  sum_real ru = 0, rr = 0;
#if COROFEM_CHUNK == 4 && (!defined(COROFEM_PRECOND_BLOCK) || defined(COROFEM_AMG)) && !defined(COROFEM_TREE_REDUCE)
  /* A whole chunk (CPUs): its 12 dofs as three real4, so that the update compiles to vector code
   * (PoCL leaves the loop below scalar). The lane sums are added in a fixed order. */
  if (last == first + 4) {
    sum_real4 ru4 = (sum_real4)0, rr4 = (sum_real4)0;
    #pragma unroll
    for (uint j = 0; j < 3; ++j) {
      const uint d = 3 * first + 4 * j;
      const real4 pd = vload4(0, u + d) + beta * vload4(0, p + d), sd = vload4(0, w + d) + beta * vload4(0, sv + d);
      vstore4(pd, 0, p + d);
      vstore4(sd, 0, sv + d);
      vstore4(vload4(0, x + d) + alpha * pd, 0, x + d);
      const real4 rd = vload4(0, r + d) - alpha * sd;
      vstore4(rd, 0, r + d);
#if defined(COROFEM_PRECOND_DIAG) && !defined(COROFEM_AMG)
      const real4 ud = vload4(0, minv + d) * rd;
#else
      const real4 ud = rd;
#endif
      vstore4(ud, 0, u + d);
      ru4 += TO_SUM4(rd) * TO_SUM4(ud);
      rr4 += TO_SUM4(rd) * TO_SUM4(rd);
    }
    sums[0] = (ru4.x + ru4.y) + (ru4.z + ru4.w);
    sums[1] = (rr4.x + rr4.y) + (rr4.z + rr4.w);
    return;
  }
#endif
  for (uint n = first; n < last; ++n) {
    real rn[3], un[3];
    #pragma unroll
    for (int k = 0; k < 3; ++k) {
      const uint d = 3 * n + k;
      const real pd = u[d] + beta * p[d], sd = w[d] + beta * sv[d];
      p[d] = pd;
      sv[d] = sd;
      x[d] += alpha * pd;
      rn[k] = r[d] - alpha * sd;
      r[d] = rn[k];
    }
#ifdef COROFEM_AMG  /* the multigrid's cycle forms u after this kernel (engine_amg.hpp) */
    for (int k = 0; k < 3; ++k) un[k] = rn[k];
#else
    apply_preconditioner(n, minv, rn, un);
#endif
    #pragma unroll
    for (int k = 0; k < 3; ++k) {
      u[3 * n + k] = un[k];
      ru += (sum_real)rn[k] * (sum_real)un[k];
      rr += (sum_real)rn[k] * (sum_real)rn[k];
    }
  }
  sums[0] = ru;
  sums[1] = rr;
}

/* p = u + beta p, s = w + beta s, x += alpha p, r -= alpha s, u = M^-1 r; partials (r . u, r . r, 0). */
__kernel __attribute__((reqd_work_group_size(COROFEM_WG, 1, 1)))
void pcg_update(__global const uint* restrict nodeSeg, __global const uint* restrict segInfo,
                __global const sum_real* restrict scalars, __global const real* restrict w,
                __global const real* restrict minv, __global real* restrict p, __global real* restrict sv,
                __global real* restrict x, __global real* restrict r, __global real* restrict u,
                __global sum_real* restrict partials) {
  COROFEM_PARTIAL_LOCALS
  COROFEM_NODE_RANGE(nodeSeg, segInfo, s, first, last);
  const real alpha = (real)scalars[kScalarCount * s + kScalarAlpha];
  const real beta = (real)scalars[kScalarCount * s + kScalarBeta];
  sum_real sums[2];
  pcg_update_nodes(first, last, alpha, beta, w, minv, p, sv, x, r, u, sums);
  COROFEM_PARTIAL_STORE(sums[0], sums[1], (sum_real)0, partials);
}

/* The scalars of one segment from its sums (work-item 0 of reduce_finish). One exit only: PoCL 3.1
 * ran the code after reduce_finish's barriers on every work-item when it held a second return. */
COROFEM_FN void update_scalars(__global uint* segInfo, uint seg, __global sum_real* scalars, uint mode, sum_real tol2,
                               sum_real gammaNew, sum_real rr, sum_real bbSum, sum_real delta) {
  if (mode == kReduceResidual) {
    scalars[kScalarRr] = rr;
    scalars[kScalarBb] = bbSum;
  } else {
    sum_real bb = bbSum;
    if (mode == kReduceInit) {
      scalars[kScalarBb] = bb;
      scalars[kScalarIterations] = 0;
    } else {
      bb = scalars[kScalarBb];
      scalars[kScalarIterations] += 1;
    }
    bool breakdown = false;
    if (mode != kReduceLast) {  /* the next iteration's alpha and beta (the cap's last has none) */
      sum_real beta = (sum_real)0, pq = delta;
      if (mode == kReduceStep) {
        const sum_real gamma = scalars[kScalarRho], alpha = scalars[kScalarAlpha];
        beta = gamma != (sum_real)0 ? gammaNew / gamma : (sum_real)0;
        pq = alpha != (sum_real)0 ? delta - beta * gammaNew / alpha : (sum_real)0;
      }
      scalars[kScalarBeta] = beta;
      scalars[kScalarPq] = pq;
      breakdown = !(pq > (sum_real)0);
      scalars[kScalarAlpha] = breakdown ? (sum_real)0 : gammaNew / pq;
      scalars[kScalarBreakdown] = breakdown ? 1 : 0;
    }
    scalars[kScalarRho] = gammaNew;
    scalars[kScalarRr] = rr;
    const uint stop = !isfinite(rr) ? kStopNonFinite : rr <= tol2 * bb ? kStopConverged
                                                        : breakdown ? kStopBreakdown : kStopRunning;
    scalars[kScalarStop] = (sum_real)stop;
    if (stop != kStopRunning) segInfo[kSegInfoCount * seg + kSegActive] = 0u;
  }
}

/* Second stage of the dot products: work-group s sums segment s's partials of pcg_init/pcg_update
 * (`partials`: r . u, r . r, b . b) and, in kReduceInit and kReduceStep, of gather_product
 * (`partialsW`: u . w in component 0), then updates the segment's PCG scalars according to `mode`:
 *   kReduceInit      gamma, rr, bb; alpha = gamma / delta, beta = 0; iterations = 0
 *   kReduceStep      beta = gamma' / gamma, alpha = gamma' / (delta' - beta gamma' / alpha), gamma, rr;
 *                    iterations + 1
 *   kReduceResidual  rr, bb only (the true residual after the solve)
 *   kReduceLast      gamma, rr, iterations + 1: the iteration cap's last iteration, after which no
 *                    alpha or beta is needed, so its product w = A u is not computed either
 * A non-positive p . A p (A not positive definite on the free dofs, or p = 0) sets alpha = 0 and the
 * breakdown flag instead of dividing. In every mode but kReduceResidual the convergence test runs here,
 * after every iteration (tol2 = tolerance^2): a converged, broken-down or non-finite segment records
 * why (kScalarStop) and becomes inactive, so the iterations the host enqueued ahead of its next
 * read of the scalars cost that segment nothing and leave its x as it was at the stop. */
/* The sums of the first `count` partials of segment seg (pcg_init/pcg_update's three,
 * gather_product's first) into s0..s3[0], in a fixed order: strided lanes, then a tree (the same
 * for a body alone or in a batch). */
COROFEM_FN void segment_sums(__global const uint* segInfo, uint seg, uint count,
                             __global const sum_real* partials, __global const sum_real* partialsW,
                             __local sum_real* s0, __local sum_real* s1, __local sum_real* s2, __local sum_real* s3) {
  const uint lid = get_local_id(0);
  const uint begin = kPartialComponents * seg_info(segInfo, seg, kSegPartialBegin);
  /* Both buffers in every mode (kReduceResidual and kReduceLast ignore partialsW): one loop, one tree. */
  sum_real a = 0, b = 0, c = 0, d = 0;
  for (uint g = lid; g < count; g += COROFEM_WG) {
    a += partials[begin + kPartialComponents * g];
    b += partials[begin + kPartialComponents * g + 1];
    c += partials[begin + kPartialComponents * g + 2];
    d += partialsW[begin + kPartialComponents * g];
  }
  s0[lid] = a;
  s1[lid] = b;
  s2[lid] = c;
  s3[lid] = d;
  barrier(CLK_LOCAL_MEM_FENCE);
  for (uint s = COROFEM_WG / 2; s > 0; s >>= 1) {
    if (lid < s) {
      s0[lid] += s0[lid + s];
      s1[lid] += s1[lid + s];
      s2[lid] += s2[lid + s];
      s3[lid] += s3[lid + s];
    }
    barrier(CLK_LOCAL_MEM_FENCE);
  }
}

__kernel __attribute__((reqd_work_group_size(COROFEM_WG, 1, 1)))
void reduce_finish(__global uint* restrict segInfo, __global const sum_real* restrict partials,
                   __global const sum_real* restrict partialsW, __global sum_real* restrict allScalars,
                   const uint mode, const sum_real tol2) {
  __local sum_real s0[COROFEM_WG], s1[COROFEM_WG], s2[COROFEM_WG], s3[COROFEM_WG];
  const uint lid = get_local_id(0), seg = get_global_id(0) / COROFEM_WG;
  /* An inactive segment's group sums too but changes nothing. (Returning here at once, as the other
   * kernels do, made PoCL 3.1 run update_scalars on every work-item once it could clear the flag.) */
  const bool active = seg_info(segInfo, seg, kSegActive) != 0u;
  segment_sums(segInfo, seg, seg_info(segInfo, seg, kSegPartialCount), partials, partialsW, s0, s1, s2, s3);
  if (lid == 0 && active)
    update_scalars(segInfo, seg, allScalars + kScalarCount * seg, mode, tol2, s0[0], s1[0], s2[0], s3[0]);
}

