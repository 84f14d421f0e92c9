/* Deterministic scatter of the per-element 12-vectors to the nodes, written as a gather: one
 * work-item per node sums its incident (element, corner) contributions in the fixed CSR order
 * built once on the host, so two runs give the same bits (no atomics, no colouring).
 * entries[j] = ((e / VEC) * 12 + 3 c) * VEC + e % VEC addresses component x of corner c of element
 * e in `elemOut`; y and z follow VEC and 2 VEC reals later (store_corner, corofem_vector.h).
 */
#ifndef COROFEM_EMBEDDED
#include "../shared/corofem_layout.h"
#include "../shared/corofem_reduce.h"
#include "../shared/corofem_vector.h"
#endif

COROFEM_FN void gather_node(uint n, __global const uint* start, __global const uint* entries,
                        __global const real* elemOut, real* acc) {
  real sx = 0, sy = 0, sz = 0;
  const uint end = start[n + 1];
  for (uint j = start[n]; j < end; ++j) {
    const uint at = entries[j];
    sx += elemOut[at];
    sy += elemOut[at + COROFEM_VEC];
    sz += elemOut[at + 2 * COROFEM_VEC];
  }
  acc[0] = sx;
  acc[1] = sy;
  acc[2] = sz;
}

/* f_n = sum over incident elements (internal forces, Eq. 9 assembled). */
__kernel __attribute__((reqd_work_group_size(COROFEM_WG, 1, 1)))
void gather_sum(__global const uint* restrict nodeSeg, __global const uint* restrict segInfo,
                __global const uint* restrict start, __global const uint* restrict entries,
                __global const real* restrict elemOut, __global real* restrict out) {
  uint n, s;
  if (!node_item(nodeSeg, segInfo, &n, &s)) return;
  real acc[3];
  gather_node(n, start, entries, elemOut, acc);
  out[3 * n] = acc[0];
  out[3 * n + 1] = acc[1];
  out[3 * n + 2] = acc[2];
}

/* (A p)_d of dof d of node n from the node's gathered element products acc_k (k = d - 3 n). */
COROFEM_FN real product_entry(uint d, real acc, real massCoef, __global const real* mass,
                              __global const real* free, uint project, real pd) {
  const real yd = (mass ? massCoef * mass[d] * pd : (real)0) + acc;
  return project ? yd * free[d] : yd;
}

/* The node loop of gather_product for the work-item's nodes [first, last): y = A p and the sum
 * p . y into sums[0]; or, with a right-hand side rb (the true residual after a solve), y = free b -
 * A p (projected whatever `project` says: the host passes 1 with rb) and the sums r . r, |free b|^2
 * into sums[1], sums[2], as pcg_init forms them from A x (the same terms in the same order: the
 * same bits). The residual's entry takes the projection as a constant: with the runtime flag, PoCL
 * compiled its ternary into a masked load from the constant pool, which a 2-core AMD Zen 4 took
 * about 150 cycles over whenever the mask was off (the residual of bench_batch's 100 bodies, 63,000
 * nodes: 11.5 ms against 0.89 ms; the same code without a right-hand side was unaffected). */
COROFEM_FN void gather_product_nodes(uint first, uint last, real massCoef, __global const uint* start,
                                     __global const uint* entries, __global const real* elemOut,
                                     __global const real* mass, __global const real* free, uint project,
                                     __global const real* p, __global const real* rb, __global real* y,
                                     sum_real* sums) {
  sum_real dot = (sum_real)0, rr = (sum_real)0, bb = (sum_real)0;
  /* Two loops, the branch outside them: inside, it cost PoCL 1.1 us on a 10k-element product. */
  if (!rb) {
    for (uint n = first; n < last; ++n) {
      real acc[3];
      gather_node(n, start, entries, elemOut, acc);
      #pragma unroll
      for (int k = 0; k < 3; ++k) {
        const uint d = 3 * n + k;
        const real pd = p[d], yd = product_entry(d, acc[k], massCoef, mass, free, project, pd);
        y[d] = yd;
        dot += (sum_real)pd * (sum_real)yd;  /* exact term in mixed precision */
      }
    }
  } else {
    for (uint n = first; n < last; ++n) {
      real acc[3];
      gather_node(n, start, entries, elemOut, acc);
      #pragma unroll
      for (int k = 0; k < 3; ++k) {
        const uint d = 3 * n + k;
        const real yd = product_entry(d, acc[k], massCoef, mass, free, 1u, p[d]);
        const real bd = free[d] * rb[d], rd = bd - yd;
        y[d] = rd;
        bb += (sum_real)bd * (sum_real)bd;
        rr += (sum_real)rd * (sum_real)rd;
      }
    }
  }
  sums[0] = dot;
  sums[1] = rr;
  sums[2] = bb;
}

/* y = massCoef M p + (element products, already scaled by the stiffness coefficient), with the
 * lumped mass M (mass = NULL: no body of the device has mass, the term is 0) and the segment's
 * massCoef. Rayleigh damping C = alpha M + beta K^R needs no code of its own: the host folds
 * it into massCoef = m + c alpha and the stiffness coefficient k + c beta.
 * project != 0 (inside PCG): y_d = 0 on constrained dofs (free[d] = 0): with p_d = 0 there, this is
 * the identity row/column of the projected system. The partial sums of p . y (corofem_reduce.h,
 * in sum_real: double in mixed precision) give PCG its alpha. With rb (b) instead: y = free b - A p,
 * the true residual after a solve, and its sums (gather_product_nodes). */
__kernel __attribute__((reqd_work_group_size(COROFEM_WG, 1, 1)))
void gather_product(__global const uint* restrict nodeSeg, __global const uint* restrict segInfo,
                    __global const real* restrict segCoef, __global const uint* restrict start,
                    __global const uint* restrict entries, __global const real* restrict elemOut,
                    __global const real* restrict mass, __global const real* restrict free,
                    const uint project, __global const real* restrict p, __global real* restrict y,
                    __global sum_real* restrict partials, __global const real* restrict rb) {
  COROFEM_PARTIAL_LOCALS
  COROFEM_NODE_RANGE(nodeSeg, segInfo, s, first, last);
  sum_real sums[3];
  gather_product_nodes(first, last, seg_coef(segCoef, s, kCoefMass), start, entries, elemOut, mass, free, project,
                       p, rb, y, sums);
  COROFEM_PARTIAL_STORE(sums[0], sums[1], sums[2], partials);
}
