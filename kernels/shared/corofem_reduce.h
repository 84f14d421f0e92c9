/* First stage of the deterministic two-stage dot products (OpenCL C only). The second stage is
 * reduce_finish in pcg.cl. Node kernels that produce partial sums walk COROFEM_CHUNK consecutive
 * nodes per work-item, and then either
 *   COROFEM_TREE_REDUCE defined (GPUs): a fixed-order tree over the work-group in local memory,
 *     one partial per work-group; or
 *   not defined (CPUs): each work-item writes its own partial, with no barrier at all (PoCL splits
 *     a kernel at every barrier into separate work-item loops, which made the fused PCG kernels
 *     several times slower than their arithmetic).
 * Either way the summation order is fixed by the sizes alone, so results are reproducible bit for
 * bit. Partials are sum_real (corofem_layout.h: double in mixed precision). A kernel declares
 * COROFEM_PARTIAL_LOCALS at its top and ends with COROFEM_PARTIAL_STORE(a, b, c, partials) reached by every work-item. */
#ifndef COROFEM_REDUCE_H
#define COROFEM_REDUCE_H
#ifdef __OPENCL_C_VERSION__

#ifndef COROFEM_CHUNK
#define COROFEM_CHUNK 1
#endif

#ifdef COROFEM_TREE_REDUCE
/* Fixed-order tree sum of three values over the work-group into partials[3 group + k]. */
COROFEM_FN void group_sum3(__local sum_real* s0, __local sum_real* s1, __local sum_real* s2, sum_real a,
                           sum_real b, sum_real c, __global sum_real* partials) {
  const uint lid = get_local_id(0);
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
  if (lid == 0) {
    const uint g = get_global_id(0) / COROFEM_WG; /* the group, also under a global offset */
    partials[kPartialComponents * g] = s0[0];
    partials[kPartialComponents * g + 1] = s1[0];
    partials[kPartialComponents * g + 2] = s2[0];
  }
}
#define COROFEM_PARTIAL_LOCALS __local sum_real s0_[COROFEM_WG], s1_[COROFEM_WG], s2_[COROFEM_WG];
#define COROFEM_PARTIAL_STORE(a, b, c, partials) group_sum3(s0_, s1_, s2_, (a), (b), (c), (partials))
#else
/* The partial triple i (a work-item's own: i is its global id; pcg_iterate_group stores those of the
 * work-items it stands in for). */
COROFEM_FN void store3_at(uint i, sum_real a, sum_real b, sum_real c, __global sum_real* partials) {
  partials[kPartialComponents * i] = a;
  partials[kPartialComponents * i + 1] = b;
  partials[kPartialComponents * i + 2] = c;
}
COROFEM_FN void item_store3(sum_real a, sum_real b, sum_real c, __global sum_real* partials) {
  store3_at(get_global_id(0), a, b, c, partials);
}
#define COROFEM_PARTIAL_LOCALS
#define COROFEM_PARTIAL_STORE(a, b, c, partials) item_store3((a), (b), (c), (partials))
#endif

/* The nodes [first, last) of this work-item and their segment s (corofem_layout.h); a work-group
 * of an inactive segment returns at once (all its work-items alike, so before any barrier). */
#define COROFEM_NODE_RANGE(nodeSeg, segInfo, s, first, last)                    \
  const uint first = get_global_id(0) * COROFEM_CHUNK;                          \
  const uint s = node_segment((nodeSeg), first);                                \
  if (seg_info((segInfo), s, kSegActive) == 0u) return;                         \
  const uint last = min(first + (uint)COROFEM_CHUNK, seg_info((segInfo), s, kSegNodeEnd))

#endif /* __OPENCL_C_VERSION__ */
#endif /* COROFEM_REDUCE_H */
