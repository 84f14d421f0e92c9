/* The PCG iterations of pcg.cl for whole segments, one work-group per segment, in ONE launch
 * (CPU devices: per-work-item partial sums, no COROFEM_TREE_REDUCE).
 *
 * The launched PCG runs 4 kernels per iteration (pcg_update, element_product, gather_product,
 * reduce_finish), each over every active segment. On a CPU device each launch costs a few
 * microseconds of PoCL's dispatch and thread wake-up, which for bodies of a few thousand elements
 * is more than their kernels' own time, and a tile of bodies keeps launching while its slowest body
 * iterates. pcg_iterate_group instead gives each segment one work-group, which runs up to
 * `iterations` iterations back to back, separated by work-group barriers only, and leaves the loop
 * when reduce_finish's convergence test stops the segment: a converged body costs nothing more and
 * the others go on without a launch, on data that stays in the core's cache.
 *
 * Each phase calls the launched kernels' own code (pcg_update_nodes, element_product_items,
 * gather_product_nodes, segment_sums, update_scalars) for every work-item of the launched grid
 * that the group stands in for (work-item lid takes items lid, lid + WG, ...), and stores the same
 * partial sums at the same places: the result is the launched iterations' bit for bit
 * (tests/opencl/test_opencl_batch.cpp), so a body's answer does not depend on which path ran it.
 *
 * No early return and no barrier inside a branch (PoCL 3.1 ran code after barriers on every
 * work-item in kernels that had either): an inactive segment's group runs no iteration. No
 * `restrict` on the arguments: with it, PoCL 3.1 gave wrong iterates from the second iteration of
 * the loop on (the first was right), presumably by moving loads across the loop's barriers. */
#ifndef COROFEM_EMBEDDED
#include "../shared/corofem_layout.h"
#include "../shared/corofem_reduce.h"
#include "../shared/corofem_vector.h"
#include "element_force.cl"
#include "gather.cl"
#include "pcg.cl"
#endif

#ifndef COROFEM_TREE_REDUCE
/* `iterations` iterations of kReduceStep (p, s, x, r, u updated; w = A u; alpha, beta), for the
 * segment of each work-group (launched over Span::Segments), the set-up (pcg_init, reduce_finish
 * kReduceInit) done before. Arguments as pcg_update, element_product and gather_product take them
 * (w is gather_product's y). */
__kernel __attribute__((reqd_work_group_size(COROFEM_WG, 1, 1)))
void pcg_iterate_group(const uint S, __global uint* segInfo, __global const real* segCoef,
                       __global const uint* nodes, __global const real* geom,
                       __global const real* rotGrad, __global const uint* start,
                       __global const uint* entries, __global real* elemOut,
                       __global const real* mass, __global const real* free,
                       __global const real* minv, __global real* p, __global real* sv,
                       __global real* x, __global real* r, __global real* u,
                       __global real* w, __global sum_real* partials,
                       __global sum_real* partialsW, __global sum_real* allScalars,
                       const uint iterations, const sum_real tol2) {
  __local sum_real s0[COROFEM_WG], s1[COROFEM_WG], s2[COROFEM_WG], s3[COROFEM_WG];
  __local uint running;
  const uint lid = get_local_id(0), seg = get_global_id(0) / COROFEM_WG;
  const uint elemBegin = seg_info(segInfo, seg, kSegElemBegin), elemEnd = seg_info(segInfo, seg, kSegElemEnd);
  const uint elemItems = seg_info(segInfo, seg, kSegElemSpan) / COROFEM_VEC;
  const uint nodeBegin = seg_info(segInfo, seg, kSegNodeBegin), nodeEnd = seg_info(segInfo, seg, kSegNodeEnd);
  const uint nodeItems = seg_info(segInfo, seg, kSegPartialCount);  /* one partial per node work-item */
  const uint partialBegin = seg_info(segInfo, seg, kSegPartialBegin);
  const real lambda = seg_coef(segCoef, seg, kCoefProdLambda), mu = seg_coef(segCoef, seg, kCoefProdMu);
  const real massCoef = seg_coef(segCoef, seg, kCoefMass);
  __global sum_real* scalars = allScalars + kScalarCount * seg;
  if (lid == 0) running = seg_info(segInfo, seg, kSegActive);
  barrier(CLK_LOCAL_MEM_FENCE);
  for (uint it = 0; it < iterations && running != 0u; ++it) {
    /* pcg_update */
    const real alpha = (real)scalars[kScalarAlpha], beta = (real)scalars[kScalarBeta];
    for (uint v = lid; v < nodeItems; v += COROFEM_WG) {
      const uint first = nodeBegin + v * COROFEM_CHUNK, last = min(first + (uint)COROFEM_CHUNK, nodeEnd);
      sum_real sums[2];
      pcg_update_nodes(first, last, alpha, beta, w, minv, p, sv, x, r, u, sums);
      store3_at(partialBegin + v, sums[0], sums[1], (sum_real)0, partials);
    }
    barrier(CLK_GLOBAL_MEM_FENCE);
    /* element_product of u */
    for (uint v = lid; v < elemItems; v += COROFEM_WG) {
      const uint e0 = elemBegin + v * COROFEM_VEC;
      if (e0 < elemEnd) element_product_items(e0, S, lambda, mu, nodes, geom, rotGrad, u, elemOut);
    }
    barrier(CLK_GLOBAL_MEM_FENCE);
    /* gather_product (projected): w = A u and the partials of u . w */
    for (uint v = lid; v < nodeItems; v += COROFEM_WG) {
      const uint first = nodeBegin + v * COROFEM_CHUNK, last = min(first + (uint)COROFEM_CHUNK, nodeEnd);
      sum_real sums[3];
      gather_product_nodes(first, last, massCoef, start, entries, elemOut, mass, free, 1u, u,
                           (__global const real*)0, w, sums);
      store3_at(partialBegin + v, sums[0], sums[1], sums[2], partialsW);
    }
    barrier(CLK_GLOBAL_MEM_FENCE);
    /* reduce_finish(kReduceStep) */
    segment_sums(segInfo, seg, nodeItems, partials, partialsW, s0, s1, s2, s3);
    if (lid == 0) {
      update_scalars(segInfo, seg, scalars, kReduceStep, tol2, s0[0], s1[0], s2[0], s3[0]);
      running = seg_info(segInfo, seg, kSegActive);
    }
    barrier(CLK_LOCAL_MEM_FENCE | CLK_GLOBAL_MEM_FENCE);
  }
}
#endif
