/* The PCG iterations of pcg.cl for whole segments, a work-group at a time per segment, in ONE
 * launch (CPU devices: per-work-item partial sums, no COROFEM_TREE_REDUCE). pcg_iterate_group's
 * work-groups take the segments in turn from a list (one per compute unit); pcg_iterate_team's
 * teams have a segment each.
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
#include "../../shared/corofem_layout.h"
#include "../../shared/corofem_reduce.h"
#include "../../shared/corofem_vector.h"
#include "../element_force.cl"
#include "../gather.cl"
#include "../pcg.cl"
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

/* The arguments of both one-launch kernels, in the host's one order (segment_engine.cpp): the
 * team's size, epoch base and state (pcg_iterate_team; pcg_iterate_group, a team of one, reads
 * none of them), then what pcg_update, element_product and gather_product take (w is
 * gather_product's y), the iterations and the squared tolerance, and pcg_iterate_group's list of
 * segments with its claim word after them (groupOrder[groupCount]; pcg_iterate_team reads none). */
#define COROFEM_GROUP_PCG_PARAMS                                                                      \
  const uint S, const uint teamSize, const uint epochBase, __global uint *teamState, __global uint *segInfo, \
      __global const real *segCoef, __global const uint *nodes, __global const real *geom,              \
      __global const real *rotGrad, __global const uint *start, __global const uint *entries,           \
      __global real *elemOut, __global const real *mass, __global const real *free,                     \
      __global const real *minv, __global real *p, __global real *sv, __global real *x, __global real *r, \
      __global real *u, __global real *w, __global sum_real *partials, __global sum_real *partialsW,    \
      __global sum_real *allScalars, const uint iterations, const sum_real tol2, __global uint *groupOrder, \
      const uint groupCount

/* `iterations` iterations of kReduceStep (p, s, x, r, u updated; w = A u; alpha, beta), the set-up
 * (pcg_init, reduce_finish kReduceInit) done before, for the segments groupOrder[0 .. groupCount):
 * a work-group per compute unit, each taking the next segment from the claim word after the list
 * until none is left. The host lists them the costliest first, so this is the longest-first list
 * schedule whatever the runtime does with work-groups: PoCL hands a thread ceil(remaining /
 * threads) work-groups at a time, so with a work-group per segment in the scene's order the first
 * thread took the first half of the bodies (40 bodies of 880 to 4,480 elements on 2 cores: 77 ms
 * with the largest first in the scene against 51 ms with the smallest first). */
__kernel __attribute__((reqd_work_group_size(COROFEM_WG, 1, 1)))
void pcg_iterate_group(COROFEM_GROUP_PCG_PARAMS) {
  __local sum_real s0[COROFEM_WG], s1[COROFEM_WG], s2[COROFEM_WG], s3[COROFEM_WG];
  __local uint running, claimed;
  const uint lid = get_local_id(0);
  /* One exit, at the loop's uniform test (no early return: see the header). Each claim is read by
   * every item before the next barrier, and item 0 writes the next one only after it. */
  if (lid == 0) claimed = atomic_inc(groupOrder + groupCount);
  barrier(CLK_LOCAL_MEM_FENCE);
  uint k = claimed;
  while (k < groupCount) {
    const uint seg = groupOrder[k];
    const GroupSegment g = group_segment(segInfo, segCoef, seg);
    __global sum_real* scalars = allScalars + kScalarCount * seg;
    /* kSegRunningPacked: pcg_iterate_pack's body */
    if (lid == 0) running = seg_info(segInfo, seg, kSegActive) == kSegRunning ? 1u : 0u;
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
    if (lid == 0) claimed = atomic_inc(groupOrder + groupCount);
    barrier(CLK_LOCAL_MEM_FENCE);
    k = claimed;
  }
}

/* pcg_iterate_group with a team of `teamSize` work-groups per segment (CPU devices, a round of
 * fewer bodies than cores): the same iterations, the same items, the same bits, on several cores
 * without a launch between the phases.
 *
 * Each phase (update, product, gather: one chunk per COROFEM_WG work-items of the launched grid;
 * the scalars: one chunk) is split into chunks, and chunk c has a claim word in the segment's
 * flags; the phases are numbered by epochs that grow through the launch and from one launch to
 * the next (epochBase, from the host). Member m of the team (its work-group's place in the team)
 * claims the chunks of its own share of the phase first (atomic_max of the epoch: the old value
 * below the epoch means the chunk is its own), then any still unclaimed in the others' shares, from
 * their ends; it does each chunk it claims, adds its count to the segment's `done`, and waits
 * until `done` holds the whole phase. So a member's share stays in its core's cache from phase to
 * phase (its elements' outputs, its nodes' vectors), and a member that starts late or runs slow
 * loses its share to the others instead of holding them up: a member waits only for chunks that a
 * running member has claimed, so no scheduling of the groups can deadlock (one core running them
 * in turns: the first does everything, the others find every chunk taken). The scalars are
 * updated by whoever claims that phase's chunk; every member then reads the stop from segInfo. The
 * last member to leave zeroes `done` and its own count for the next launch.
 *
 * Between groups, what one stored is read by another after it has seen the count: the counts are
 * atomic read-modify-writes (PoCL: sequentially consistent, full barriers on the x86 and ARM CPUs
 * it runs on); the waiting group spins on a volatile load and then reads the count once more with
 * an atomic read-modify-write whose value it uses (team_wait).
 * OpenCL 1.2 has no memory-scope fence to promise this on a GPU (whose L1 caches are not coherent),
 * which is why GPUs keep the launched iterations. */
COROFEM_FN void team_wait(__global volatile uint* done, uint target) {
  while (done[0] < target) {
  }
  /* The acquire: an atomic read-modify-write whose value decides the loop, so the compiler keeps
   * it (an atomic_or whose result went unused was compiled to nothing), and nothing after it is
   * read before it. It runs once: the spin above has seen the count. */
  while (atomic_add(done, 0u) < target) {
  }
}

/* The chunk that member m of a team of T tries k-th in a phase of C chunks: its own share
 * [m C / T, (m + 1) C / T) in order, then the other members' shares from their ends. */
COROFEM_FN uint team_chunk(uint k, uint m, uint T, uint C) {
  const uint lo = m * C / T, own = (m + 1) * C / T - lo;
  if (k < own) return lo + k;
  k -= own;
  for (uint j = 1; j < T; ++j) {
    const uint h = (m + j) % T, hlo = h * C / T, hn = (h + 1) * C / T - hlo;
    if (k < hn) return hlo + hn - 1 - k;
    k -= hn;
  }
  return 0u; /* not reached: k < C */
}

/* Member `member`'s claim of the k-th chunk it tries in a phase of C chunks (lid 0; `claimed`:
 * the chunk + 1, or 0), and the end of a phase: its count added, the wait for the whole phase. */
#define TEAM_CLAIM(k, C)                                                                         \
  if (lid == 0) {                                                                                \
    const uint c = team_chunk((k), member, teamSize, (C));                                       \
    claimed = flags[c] < epoch && atomic_max(flags + c, epoch) < epoch ? c + 1u : 0u;            \
    count += claimed != 0u ? 1u : 0u;                                                            \
  }                                                                                              \
  barrier(CLK_LOCAL_MEM_FENCE);
#define TEAM_DONE()                                                                              \
  if (lid == 0) {                                                                                \
    if (count != 0u) atomic_add(done, count);                                                    \
    team_wait(done, end);                                                                        \
  }                                                                                              \
  barrier(CLK_LOCAL_MEM_FENCE | CLK_GLOBAL_MEM_FENCE);
/* A phase over items: `kind` 0 update, 1 product, 2 gather. */
#define TEAM_PHASE(kind, C, ITEMS)                                                               \
  epoch += 1u;                                                                                   \
  end += (C);                                                                                    \
  if (lid == 0) count = 0u;                                                                      \
  for (uint k = 0; k < (C); ++k) {                                                               \
    TEAM_CLAIM(k, (C))                                                                           \
    const uint v = (claimed - 1u) * COROFEM_WG + lid;                                            \
    if (claimed != 0u && v < (ITEMS)) {                                                          \
      if ((kind) == 0u) group_update_item(&g, v, alpha, beta, w, minv, p, sv, x, r, u, partials); \
      else if ((kind) == 1u) group_product_item(&g, v, S, nodes, geom, rotGrad, u, elemOut);      \
      else group_gather_item(&g, v, start, entries, elemOut, mass, free, u, w, partialsW);         \
    }                                                                                            \
    barrier(CLK_LOCAL_MEM_FENCE | CLK_GLOBAL_MEM_FENCE);                                         \
  }                                                                                              \
  TEAM_DONE()

/* teamState per segment (kTeamStride uints): [kTeamDone] chunks done in this launch,
 * [kTeamLeft] members gone, [kTeamFlags] where its claim words start in teamState (host). */
__kernel __attribute__((reqd_work_group_size(COROFEM_WG, 1, 1)))
void pcg_iterate_team(COROFEM_GROUP_PCG_PARAMS) {
  __local sum_real s0[COROFEM_WG], s1[COROFEM_WG], s2[COROFEM_WG], s3[COROFEM_WG];
  __local uint running, claimed, count;
  const uint lid = get_local_id(0), team = get_global_id(0) / COROFEM_WG;
  const uint seg = team / teamSize, member = team % teamSize;
  const GroupSegment g = group_segment(segInfo, segCoef, seg);
  __global volatile sum_real* scalars = allScalars + kScalarCount * seg;
  __global volatile uint* state = teamState + kTeamStride * seg;
  __global volatile uint* done = state + kTeamDone;
  __global volatile uint* flags = teamState + state[kTeamFlags];
  __global volatile uint* active = segInfo + kSegInfoCount * seg + kSegActive;
  const uint nodeChunks = (g.nodeItems + COROFEM_WG - 1) / COROFEM_WG;
  const uint elemChunks = (g.elemItems + COROFEM_WG - 1) / COROFEM_WG;
  if (lid == 0) running = *active == kSegRunning ? 1u : 0u; /* kSegRunningPacked: pcg_iterate_pack's body */
  barrier(CLK_LOCAL_MEM_FENCE);
  uint end = 0, epoch = epochBase; /* the chunks done when the current phase is; its epoch */
  for (uint it = 0; it < iterations && running != 0u; ++it) {
    const real alpha = (real)scalars[kScalarAlpha], beta = (real)scalars[kScalarBeta];
    TEAM_PHASE(0u, nodeChunks, g.nodeItems)  /* pcg_update */
    TEAM_PHASE(1u, elemChunks, g.elemItems)  /* element_product of u */
    TEAM_PHASE(2u, nodeChunks, g.nodeItems)  /* gather_product: w = A u */
    /* reduce_finish(kReduceStep): one chunk; every member runs the sums' barriers (none inside a
     * branch, for PoCL's sake), only the claimant over the partials. */
    epoch += 1u;
    end += 1u;
    if (lid == 0) count = 0u;
    TEAM_CLAIM(0u, 1u)
    segment_sums(segInfo, seg, claimed != 0u ? g.nodeItems : 0u, partials, partialsW, s0, s1, s2, s3);
    if (lid == 0 && claimed != 0u)
      update_scalars(segInfo, seg, (__global sum_real*)scalars, kReduceStep, tol2, s0[0], s1[0], s2[0], s3[0]);
    TEAM_DONE()
    if (lid == 0) running = *active;
    barrier(CLK_LOCAL_MEM_FENCE);
  }
  if (lid == 0 && atomic_inc(state + kTeamLeft) + 1u == teamSize) {
    state[kTeamDone] = 0u;
    state[kTeamLeft] = 0u;
  }
}
#undef TEAM_PHASE
#undef TEAM_DONE
#undef TEAM_CLAIM
#undef COROFEM_GROUP_PCG_PARAMS
#endif
