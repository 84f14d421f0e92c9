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
/* A segment's extent and coefficients, as both kernels below read them. */
typedef struct {
  uint elemBegin, elemEnd, elemItems, nodeBegin, nodeEnd, nodeItems, partialBegin;
  real lambda, mu, massCoef;
} GroupSegment;

COROFEM_FN GroupSegment group_segment(__global const uint* segInfo, __global const real* segCoef, uint seg) {
  GroupSegment g;
  g.elemBegin = seg_info(segInfo, seg, kSegElemBegin);
  g.elemEnd = seg_info(segInfo, seg, kSegElemEnd);
  g.elemItems = seg_info(segInfo, seg, kSegElemSpan) / COROFEM_VEC;
  g.nodeBegin = seg_info(segInfo, seg, kSegNodeBegin);
  g.nodeEnd = seg_info(segInfo, seg, kSegNodeEnd);
  g.nodeItems = seg_info(segInfo, seg, kSegPartialCount); /* one partial per node work-item */
  g.partialBegin = seg_info(segInfo, seg, kSegPartialBegin);
  g.lambda = seg_coef(segCoef, seg, kCoefProdLambda);
  g.mu = seg_coef(segCoef, seg, kCoefProdMu);
  g.massCoef = seg_coef(segCoef, seg, kCoefMass);
  return g;
}

/* Node work-item v of the segment in pcg_update: the update and the partials r . u, r . r. */
COROFEM_FN void group_update_item(const GroupSegment* g, uint v, real alpha, real beta, __global const real* w,
                                  __global const real* minv, __global real* p, __global real* sv,
                                  __global real* x, __global real* r, __global real* u,
                                  __global sum_real* partials) {
  const uint first = g->nodeBegin + v * COROFEM_CHUNK, last = min(first + (uint)COROFEM_CHUNK, g->nodeEnd);
  sum_real sums[2];
  pcg_update_nodes(first, last, alpha, beta, w, minv, p, sv, x, r, u, sums);
  store3_at(g->partialBegin + v, sums[0], sums[1], (sum_real)0, partials);
}

/* Element work-item v of the segment in element_product (of u). */
COROFEM_FN void group_product_item(const GroupSegment* g, uint v, uint S, __global const uint* nodes,
                                   __global const real* geom, __global const real* rotGrad,
                                   __global const real* u, __global real* elemOut) {
  const uint e0 = g->elemBegin + v * COROFEM_VEC;
  if (e0 < g->elemEnd) element_product_items(e0, S, g->lambda, g->mu, nodes, geom, rotGrad, u, elemOut);
}

/* Node work-item v of the segment in gather_product (projected): w = A u, the partials of u . w. */
COROFEM_FN void group_gather_item(const GroupSegment* g, uint v, __global const uint* start,
                                  __global const uint* entries, __global const real* elemOut,
                                  __global const real* mass, __global const real* free, __global const real* u,
                                  __global real* w, __global sum_real* partialsW) {
  const uint first = g->nodeBegin + v * COROFEM_CHUNK, last = min(first + (uint)COROFEM_CHUNK, g->nodeEnd);
  sum_real sums[3];
  gather_product_nodes(first, last, g->massCoef, start, entries, elemOut, mass, free, 1u, u, (__global const real*)0,
                       w, sums);
  store3_at(g->partialBegin + v, sums[0], sums[1], sums[2], partialsW);
}

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
  const GroupSegment g = group_segment(segInfo, segCoef, seg);
  __global sum_real* scalars = allScalars + kScalarCount * seg;
  if (lid == 0) running = seg_info(segInfo, seg, kSegActive);
  barrier(CLK_LOCAL_MEM_FENCE);
  for (uint it = 0; it < iterations && running != 0u; ++it) {
    const real alpha = (real)scalars[kScalarAlpha], beta = (real)scalars[kScalarBeta];
    for (uint v = lid; v < g.nodeItems; v += COROFEM_WG) group_update_item(&g, v, alpha, beta, w, minv, p, sv, x, r, u, partials);
    barrier(CLK_GLOBAL_MEM_FENCE);
    for (uint v = lid; v < g.elemItems; v += COROFEM_WG) group_product_item(&g, v, S, nodes, geom, rotGrad, u, elemOut);
    barrier(CLK_GLOBAL_MEM_FENCE);
    for (uint v = lid; v < g.nodeItems; v += COROFEM_WG)
      group_gather_item(&g, v, start, entries, elemOut, mass, free, u, w, partialsW);
    barrier(CLK_GLOBAL_MEM_FENCE);
    /* reduce_finish(kReduceStep) */
    segment_sums(segInfo, seg, g.nodeItems, partials, partialsW, s0, s1, s2, s3);
    if (lid == 0) {
      update_scalars(segInfo, seg, scalars, kReduceStep, tol2, s0[0], s1[0], s2[0], s3[0]);
      running = seg_info(segInfo, seg, kSegActive);
    }
    barrier(CLK_LOCAL_MEM_FENCE | CLK_GLOBAL_MEM_FENCE);
  }
}

/* pcg_iterate_group with a team of `team` work-groups per segment (CPU devices, a round of fewer
 * bodies than cores): the same iterations, the same items, the same bits, on several cores
 * without a launch between the phases.
 *
 * The work of each phase (update, product, gather: one chunk per COROFEM_WG work-items of the
 * launched grid; the scalars: one chunk) is handed out by tickets, numbered through the whole
 * launch, from the segment's counter team[0]; team[1] counts the chunks done. A group takes a
 * ticket, does its chunk and counts it, until it holds a ticket of a later phase, then waits
 * until every chunk of the current phase is done (team[1] reaches the phase's last ticket) and
 * goes on with the ticket it holds. A group waits only for chunks that a running group has taken,
 * so no group ever waits on one that has not started: a single core running the groups one after
 * the other does all the work in the first (no deadlock whatever the device's scheduling), two
 * cores share it. The scalars are updated by the group holding that phase's ticket; every group
 * then reads the stop from segInfo. The last group to leave (team[2]) zeroes the counters for the
 * next launch.
 *
 * Between groups, what one group stored is read by another after it has seen the count: the
 * counts are atomic read-modify-writes (full barriers on the x86 and ARM CPUs PoCL runs on), the
 * waiting group spins on a volatile load and then does an atomic read of its own. OpenCL 1.2 has
 * no memory-scope fence to promise this on a GPU, which is why GPUs keep the launched iterations. */
COROFEM_FN void team_wait(__global volatile uint* done, uint target) {
  while (done[0] < target) {
  }
  atomic_or(done, 0u); /* an atomic read: nothing after it is read before it */
}

__kernel __attribute__((reqd_work_group_size(COROFEM_WG, 1, 1)))
void pcg_iterate_team(const uint S, const uint teamSize, __global uint* teamState, __global uint* segInfo,
                      __global const real* segCoef, __global const uint* nodes, __global const real* geom,
                      __global const real* rotGrad, __global const uint* start,
                      __global const uint* entries, __global real* elemOut,
                      __global const real* mass, __global const real* free,
                      __global const real* minv, __global real* p, __global real* sv,
                      __global real* x, __global real* r, __global real* u,
                      __global real* w, __global sum_real* partials,
                      __global sum_real* partialsW, __global sum_real* allScalars,
                      const uint iterations, const sum_real tol2) {
  __local sum_real s0[COROFEM_WG], s1[COROFEM_WG], s2[COROFEM_WG], s3[COROFEM_WG];
  __local uint running, ticket;
  const uint lid = get_local_id(0), seg = get_global_id(0) / (COROFEM_WG * teamSize);
  const GroupSegment g = group_segment(segInfo, segCoef, seg);
  __global volatile sum_real* scalars = allScalars + kScalarCount * seg;
  __global volatile uint* team = teamState + kTeamStride * seg;
  __global volatile uint* active = segInfo + kSegInfoCount * seg + kSegActive;
  const uint nodeChunks = (g.nodeItems + COROFEM_WG - 1) / COROFEM_WG;
  const uint elemChunks = (g.elemItems + COROFEM_WG - 1) / COROFEM_WG;
  if (lid == 0) {
    running = *active;
    ticket = running != 0u ? atomic_inc(team) : 0xffffffffu;
  }
  barrier(CLK_LOCAL_MEM_FENCE);
  uint end = 0; /* one past the current phase's last ticket */
  for (uint it = 0; it < iterations && running != 0u; ++it) {
    const real alpha = (real)scalars[kScalarAlpha], beta = (real)scalars[kScalarBeta];
    /* pcg_update */
    end += nodeChunks;
    while (ticket < end) {
      const uint v = (ticket - (end - nodeChunks)) * COROFEM_WG + lid;
      if (v < g.nodeItems) group_update_item(&g, v, alpha, beta, w, minv, p, sv, x, r, u, partials);
      barrier(CLK_GLOBAL_MEM_FENCE);
      if (lid == 0) {
        atomic_inc(team + 1);
        ticket = atomic_inc(team);
      }
      barrier(CLK_LOCAL_MEM_FENCE);
    }
    if (lid == 0) team_wait(team + 1, end);
    barrier(CLK_LOCAL_MEM_FENCE | CLK_GLOBAL_MEM_FENCE);
    /* element_product of u */
    end += elemChunks;
    while (ticket < end) {
      const uint v = (ticket - (end - elemChunks)) * COROFEM_WG + lid;
      if (v < g.elemItems) group_product_item(&g, v, S, nodes, geom, rotGrad, u, elemOut);
      barrier(CLK_GLOBAL_MEM_FENCE);
      if (lid == 0) {
        atomic_inc(team + 1);
        ticket = atomic_inc(team);
      }
      barrier(CLK_LOCAL_MEM_FENCE);
    }
    if (lid == 0) team_wait(team + 1, end);
    barrier(CLK_LOCAL_MEM_FENCE | CLK_GLOBAL_MEM_FENCE);
    /* gather_product */
    end += nodeChunks;
    while (ticket < end) {
      const uint v = (ticket - (end - nodeChunks)) * COROFEM_WG + lid;
      if (v < g.nodeItems) group_gather_item(&g, v, start, entries, elemOut, mass, free, u, w, partialsW);
      barrier(CLK_GLOBAL_MEM_FENCE);
      if (lid == 0) {
        atomic_inc(team + 1);
        ticket = atomic_inc(team);
      }
      barrier(CLK_LOCAL_MEM_FENCE);
    }
    if (lid == 0) team_wait(team + 1, end);
    barrier(CLK_LOCAL_MEM_FENCE | CLK_GLOBAL_MEM_FENCE);
    /* reduce_finish(kReduceStep): one chunk */
    end += 1;
    while (ticket < end) {
      segment_sums(segInfo, seg, g.nodeItems, partials, partialsW, s0, s1, s2, s3);
      if (lid == 0) {
        update_scalars(segInfo, seg, (__global sum_real*)scalars, kReduceStep, tol2, s0[0], s1[0], s2[0], s3[0]);
        atomic_inc(team + 1);
        ticket = atomic_inc(team);
      }
      barrier(CLK_LOCAL_MEM_FENCE | CLK_GLOBAL_MEM_FENCE);
    }
    if (lid == 0) {
      team_wait(team + 1, end);
      running = *active;
    }
    barrier(CLK_LOCAL_MEM_FENCE | CLK_GLOBAL_MEM_FENCE);
  }
  if (lid == 0 && atomic_inc(team + 2) + 1u == teamSize) {
    team[0] = 0u;
    team[1] = 0u;
    team[2] = 0u;
  }
}
#endif
