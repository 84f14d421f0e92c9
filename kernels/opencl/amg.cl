/* The warped smoothed-aggregation multigrid preconditioner ("amg", host/src/precond/amg.hpp) on the
 * device: one symmetric V-cycle z = M^-1 r per PCG iteration.
 *
 * Level 0 is the body's own dofs in the device numbering (node kernels over the segments, a
 * stopped segment's work-groups return at once); its operator is the current A (the engine's
 * matrix-free product) with the inverses of its 3x3 node blocks that pcg_init formed in minv
 * (COROFEM_PRECOND_BLOCK), scaled per segment by 1 / lambda_max (scale), so that Chebyshev's
 * interval is the same [1 / 30, 1] for every body and its coefficients are kernel arguments.
 * Coarser levels hold every body's rows end to end in the sparse formats of
 * host/src/device/device_amg.hpp (block diagonal: a body's rows only reach its own columns;
 * sliced ELLPACK on GPUs, dense blocks on CPU devices): the rest operators A_l, the prolongations P_l and restrictions
 * P_l^T, and at a body's coarsest level the dense inverse of its operator. The warp: each node's
 * 3-vector turned by its aggregate's rotation (9 reals, row-major) before the restriction (R^T)
 * and after the prolongation (R).
 *
 * Chebyshev smoothing of A x = b over [1/30, 1] of the scaled D^-1 A, degree 2:
 *   begin:  res = b - A x (x = 0: res = b), d = D^-1 res / theta, x += d
 *   step:   res -= A d, d = c1 d + c2 D^-1 res, x += d
 */
#ifndef COROFEM_EMBEDDED
#include "../shared/corofem_layout.h"
#include "../shared/corofem_reduce.h"
#include "gather.cl"
#include "pcg.cl"
#endif

/* -- level 0 (node chunks of the active segments) */

/* Chebyshev's begin on level 0 from x = 0 (the pre-smoothing): res = b, d = s B^-1 b / theta,
 * x = d (B^-1 the node's block inverse in minv). */
__kernel __attribute__((reqd_work_group_size(COROFEM_WG, 1, 1)))
void amg_fine_begin(__global const uint* restrict nodeSeg, __global const uint* restrict segInfo,
                    __global const real* restrict scale, __global const real* restrict minv,
                    __global const real* restrict b, const real invTheta, __global real* restrict res,
                    __global real* restrict d, __global real* restrict x) {
  uint n, s;
  if (!node_item(nodeSeg, segInfo, &n, &s)) return;
  const real sc = scale[s] * invTheta;
  real rn[3], zn[3];
  for (int k = 0; k < 3; ++k) rn[k] = b[3 * n + k];
  apply_preconditioner(n, minv, rn, zn);
  for (int k = 0; k < 3; ++k) {
    const uint i = 3 * n + k;
    const real dk = sc * zn[k];
    res[i] = rn[k];
    d[i] = dk;
    x[i] = dk;
  }
}

/* The passes after a product of the current operator (element_product of u done): each gathers
 * its node's (A u)_n as gather_product does (projected, the same sums: au below) and goes on with
 * the node's own entries only, so that the product's gather and the pass are one launch and A u is
 * never stored. u (and src) may be the pass's own d, x or res (no `restrict` on those): a node
 * reads its entries of them before it writes them, and no other node reads them (the gathers read
 * the element products). */
COROFEM_FN void fine_gathered(uint n, real massCoef, __global const uint* start, __global const uint* entries,
                              __global const real* elemOut, __global const real* mass, __global const real* free,
                              __global const real* u, real* au) {
  real acc[3];
  gather_node(n, start, entries, elemOut, acc);
  for (int k = 0; k < 3; ++k) au[k] = product_entry(3 * n + k, acc[k], massCoef, mass, free, 1u, u[3 * n + k]);
}
#define AMG_GATHER_PARAMS                                                                                    \
  __global const uint *restrict nodeSeg, __global const uint *restrict segInfo,                              \
      __global const real *restrict segCoef, __global const uint *restrict start,                            \
      __global const uint *restrict entries, __global const real *restrict elemOut,                          \
      __global const real *restrict mass, __global const real *restrict free

/* A Chebyshev pass on level 0 after the product of u:
 *   the step (u = d, src = res):        res -= A d, d = c1 d + c2 s B^-1 res, x += d
 *   a begin (u = x, src = b, c1 = 0):   res = b - A x, d = c2 s B^-1 res, x += d (c2 = 1 / theta)
 * `last` != 0 (the step that ends the V-cycle, x = z = M^-1 r): also the partial sums (r . z,
 * r . r, |free b|^2 from b where given: the set-up's) as pcg_update / pcg_init leave them for
 * reduce_finish. */
__kernel __attribute__((reqd_work_group_size(COROFEM_WG, 1, 1)))
void amg_fine_pass(AMG_GATHER_PARAMS, __global const real* restrict scale, __global const real* restrict minv,
                   __global const real* u, __global const real* src, const real c1, const real c2,
                   __global real* res, __global real* d, __global real* x, const uint last,
                   __global const real* restrict r, __global const real* restrict b,
                   __global sum_real* restrict partials) {
  COROFEM_PARTIAL_LOCALS
  COROFEM_NODE_RANGE(nodeSeg, segInfo, s, first, last_);
  const real sc = scale[s] * c2, massCoef = seg_coef(segCoef, s, kCoefMass);
  sum_real ru = 0, rr = 0, bb = 0;
  for (uint n = first; n < last_; ++n) {
    real au[3], rn[3], zn[3];
    fine_gathered(n, massCoef, start, entries, elemOut, mass, free, u, au);
    for (int k = 0; k < 3; ++k) rn[k] = src[3 * n + k] - au[k];
    apply_preconditioner(n, minv, rn, zn);
    for (int k = 0; k < 3; ++k) {
      const uint i = 3 * n + k;
      /* a begin does not read d: what a step left there is no part of its sum */
      const real dk = (c1 != (real)0 ? c1 * d[i] : (real)0) + sc * zn[k];
      const real xk = x[i] + dk;
      res[i] = rn[k];
      d[i] = dk;
      x[i] = xk;
      if (last) {
        ru += (sum_real)r[i] * (sum_real)xk;
        rr += (sum_real)r[i] * (sum_real)r[i];
        if (b) bb += (sum_real)(free[i] * b[i]) * (sum_real)(free[i] * b[i]);
      }
    }
  }
  if (last) COROFEM_PARTIAL_STORE(ru, rr, bb, partials);
}

/* After the product of x: w = R^T (b - A x) per node, R the rotation of the node's aggregate
 * (none: R = I), the residual the restriction takes. */
__kernel __attribute__((reqd_work_group_size(COROFEM_WG, 1, 1)))
void amg_fine_unwarp(AMG_GATHER_PARAMS, __global const real* restrict x, __global const int* restrict nodeAggregate,
                     __global const real* restrict rotations, __global const real* restrict b,
                     __global real* restrict w) {
  COROFEM_NODE_RANGE(nodeSeg, segInfo, s, first, last);
  const real massCoef = seg_coef(segCoef, s, kCoefMass);
  for (uint n = first; n < last; ++n) {
    real ax[3], v[3];
    fine_gathered(n, massCoef, start, entries, elemOut, mass, free, x, ax);
    for (int k = 0; k < 3; ++k) v[k] = b[3 * n + k] - ax[k];
    const int a = nodeAggregate[n];
    if (a < 0) {
      for (int k = 0; k < 3; ++k) w[3 * n + k] = v[k];
    } else {
      __global const real* R = rotations + 9 * a;
      for (int k = 0; k < 3; ++k) w[3 * n + k] = R[k] * v[0] + R[3 + k] * v[1] + R[6 + k] * v[2];
    }
  }
}
#undef AMG_GATHER_PARAMS

/* x += free (R e) per node. */
__kernel __attribute__((reqd_work_group_size(COROFEM_WG, 1, 1)))
void amg_fine_warp_add(__global const uint* restrict nodeSeg, __global const uint* restrict segInfo,
                       __global const int* restrict nodeAggregate, __global const real* restrict rotations,
                       __global const real* restrict e, __global const real* restrict free,
                       __global real* restrict x) {
  uint n, s;
  if (!node_item(nodeSeg, segInfo, &n, &s)) return;
  const int a = nodeAggregate[n];
  real v[3];
  if (a < 0) {
    for (int k = 0; k < 3; ++k) v[k] = e[3 * n + k];
  } else {
    __global const real* R = rotations + 9 * a;
    for (int k = 0; k < 3; ++k) v[k] = R[3 * k] * e[3 * n] + R[3 * k + 1] * e[3 * n + 1] + R[3 * k + 2] * e[3 * n + 2];
  }
  for (int k = 0; k < 3; ++k) x[3 * n + k] += free[3 * n + k] * v[k];
}

/* -- coarse levels (every body's rows: a work-item per row, or per block row in the blocked layout) */

/* y = A x (mode 0), y = b - A x (mode 1) or y += A x (mode 2), a work-item per row (GPUs), A in
 * slices of kAmgSlice rows (sliced ELLPACK): slice s holds its rows' entries column by column from
 * slice[s], as many columns as its longest row (the shorter rows padded with zeros at column 0),
 * so that the rows of a slice read their entries side by side (a slice's loads coalesce). */
#define kAmgSlice 16
__kernel void amg_spmv(const uint rows, __global const uint* restrict slice, __global const uint* restrict cols,
                       __global const real* restrict values, __global const real* restrict x,
                       __global const real* restrict b, const uint mode, __global real* restrict y) {
  const uint i = get_global_id(0);
  if (i >= rows) return;
  const uint s = i / kAmgSlice, begin = slice[s] + i % kAmgSlice, end = slice[s + 1];
  real sum = 0;
  /* Padding (value 0) is skipped, not multiplied: its column belongs to another body, whose x may
   * not be finite. */
  for (uint j = begin; j < end; j += kAmgSlice)
    if (values[j] != (real)0) sum += values[j] * x[cols[j]];
  y[i] = mode == 1u ? b[i] - sum : mode == 2u ? y[i] + sum : sum;
}

/* The same products (modes 0, 1, 2) of a matrix in dense RB x CB blocks (the blocked layout of
 * host/src/device/device_amg.hpp, CPU devices, where PoCL vectorised neither a row per work-item
 * nor a slice of rows per work-item well: an entry's column needs a gather of its own): a work-item
 * per block row, the blocks' columns
 * read whole (an aggregate's 6 modes, a node's 3 dofs), so that a block is CB vector
 * multiply-adds of its columns (RB reals each, loaded as one vector of 4 or 8: the lanes past RB
 * read the next column and are never stored; the host pads the values). The sums run over the
 * blocks in column order and each block's columns in order: a row's entries in column order, as
 * amg_spmv sums them, with the block's zeros added in. Every column a block reads is a vertex of
 * the block row's own body (a padded row of it is zero), never another body's. */
#define AMG_BLOCK_PRODUCT(RB, CB, VEC, VLOAD, VSTORE, W)                                                  \
  const uint i = get_global_id(0);                                                                        \
  if (i >= blockRows) return;                                                                             \
  VEC acc = (VEC)0;                                                                                       \
  for (uint j = start[i]; j < start[i + 1]; ++j) {                                                        \
    __global const real* v = values + (RB) * (CB) * j;                                                    \
    __global const real* xc = x + (CB) * cols[j];                                                         \
    _Pragma("unroll") for (int c = 0; c < (CB); ++c) acc += VLOAD(0, v + (RB) * c) * xc[c];               \
  }                                                                                                       \
  real out[W];                                                                                            \
  VSTORE(acc, 0, out);                                                                                    \
  _Pragma("unroll") for (int r = 0; r < (RB); ++r) {                                                      \
    const uint k = (RB) * i + r;                                                                          \
    y[k] = mode == 1u ? b[k] - out[r] : mode == 2u ? y[k] + out[r] : out[r];                              \
  }
#ifdef COROFEM_DOUBLE
typedef double8 real8;
#else
typedef float8 real8;
#endif
#define AMG_BLOCK_PARAMS                                                                                  \
  const uint blockRows, __global const uint *restrict start, __global const uint *restrict cols,          \
      __global const real *restrict values, __global const real *restrict x, __global const real *restrict b, \
      const uint mode, __global real *restrict y
/* P_0, the prolongation to level 0: a node's 3 rows, an aggregate's 6 columns. */
__kernel void amg_blocks_3x6(AMG_BLOCK_PARAMS) { AMG_BLOCK_PRODUCT(3, 6, real4, vload4, vstore4, 4) }
/* P_0^T, the restriction to level 1. */
__kernel void amg_blocks_6x3(AMG_BLOCK_PARAMS) { AMG_BLOCK_PRODUCT(6, 3, real8, vload8, vstore8, 8) }
/* The coarse levels' operators and transfers. */
__kernel void amg_blocks_6x6(AMG_BLOCK_PARAMS) { AMG_BLOCK_PRODUCT(6, 6, real8, vload8, vstore8, 8) }
#undef AMG_BLOCK_PARAMS
#undef AMG_BLOCK_PRODUCT

/* Chebyshev's begin on a coarse level (dinv already scaled by 1 / lambda_max): res = b - ax
 * (zero != 0: res = b, x = 0), d = dinv res / theta, x += d. */
__kernel void amg_coarse_begin(const uint rows, __global const real* restrict dinv, __global const real* restrict b,
                               __global const real* restrict ax, const uint zero, const real invTheta,
                               __global real* restrict res, __global real* restrict d, __global real* restrict x) {
  const uint i = get_global_id(0);
  if (i >= rows) return;
  const real ri = zero ? b[i] : b[i] - ax[i];
  const real di = invTheta * dinv[i] * ri;
  res[i] = ri;
  d[i] = di;
  x[i] = zero ? di : x[i] + di;
}

/* Chebyshev's step on a coarse level: res -= ad, d = c1 d + c2 dinv res, x += d. */
__kernel void amg_coarse_step(const uint rows, __global const real* restrict dinv, __global const real* restrict ad,
                              const real c1, const real c2, __global real* restrict res, __global real* restrict d,
                              __global real* restrict x) {
  const uint i = get_global_id(0);
  if (i >= rows) return;
  const real ri = res[i] - ad[i];
  const real di = c1 * d[i] + c2 * dinv[i] * ri;
  res[i] = ri;
  d[i] = di;
  x[i] += di;
}

/* y = A^-1 b on the rows of the bodies whose coarsest level this is (rows with entries; the others
 * unchanged), A^-1 the dense inverse. In double where the device has it: a body's coarsest
 * operator can be nearly singular (a light body held only in some directions), and its inverse's
 * entries then span more magnitudes than float resolves. */
#ifdef COROFEM_AMG_COARSEST_DOUBLE
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
typedef double coarsest_real;
#else
typedef real coarsest_real;
#endif
__kernel void amg_coarsest(const uint rows, __global const uint* restrict start, __global const uint* restrict cols,
                           __global const coarsest_real* restrict values, __global const real* restrict b,
                           __global real* restrict y) {
  const uint i = get_global_id(0);
  if (i >= rows) return;
  const uint begin = start[i], end = start[i + 1];
  if (begin == end) return;
  coarsest_real sum = 0;
  for (uint j = begin; j < end; ++j) sum += values[j] * (coarsest_real)b[cols[j]];
  y[i] = (real)sum;
}
