/* The warped smoothed-aggregation multigrid preconditioner ("amg", host/src/precond/amg.hpp) on the
 * device: one symmetric V-cycle z = M^-1 r per PCG iteration.
 *
 * Level 0 is the body's own dofs in the device numbering (node kernels over the segments, a
 * stopped segment's work-groups return at once); its operator is the current A (the engine's
 * matrix-free product) with the inverses of its 3x3 node blocks that pcg_init formed in minv
 * (COROFEM_PRECOND_BLOCK), scaled per segment by 1 / lambda_max (scale), so that Chebyshev's
 * interval is the same [1 / 30, 1] for every body and its coefficients are kernel arguments.
 * Coarser levels hold every body's rows end to end in CSR matrices (block diagonal: a body's rows
 * only reach its own columns): the rest operators A_l, the prolongations P_l and restrictions
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
#include "pcg.cl"
#endif

/* -- level 0 (node chunks of the active segments) */

/* Chebyshev's begin on level 0: res = b - ax (zero != 0: res = b, x = 0), d = s B^-1 res / theta,
 * x += d (B^-1 the node's block inverse in minv). */
__kernel __attribute__((reqd_work_group_size(COROFEM_WG, 1, 1)))
void amg_fine_begin(__global const uint* restrict nodeSeg, __global const uint* restrict segInfo,
                    __global const real* restrict scale, __global const real* restrict minv,
                    __global const real* restrict b, __global const real* restrict ax, const uint zero,
                    const real invTheta, __global real* restrict res, __global real* restrict d,
                    __global real* restrict x) {
  uint n, s;
  if (!node_item(nodeSeg, segInfo, &n, &s)) return;
  const real sc = scale[s] * invTheta;
  real rn[3], zn[3];
  for (int k = 0; k < 3; ++k) rn[k] = zero ? b[3 * n + k] : b[3 * n + k] - ax[3 * n + k];
  apply_preconditioner(n, minv, rn, zn);
  for (int k = 0; k < 3; ++k) {
    const uint i = 3 * n + k;
    const real dk = sc * zn[k];
    res[i] = rn[k];
    d[i] = dk;
    x[i] = zero ? dk : x[i] + dk;
  }
}

/* Chebyshev's step on level 0: res -= ad, d = c1 d + c2 s B^-1 res, x += d. `last` != 0 (the end of
 * the V-cycle, x = z = M^-1 r): also the partial sums (r . z, r . r, |free b|^2 from b where
 * given: the set-up's) as pcg_update / pcg_init leave them for reduce_finish. */
__kernel __attribute__((reqd_work_group_size(COROFEM_WG, 1, 1)))
void amg_fine_step(__global const uint* restrict nodeSeg, __global const uint* restrict segInfo,
                   __global const real* restrict scale, __global const real* restrict minv,
                   __global const real* restrict ad, const real c1, const real c2, __global real* restrict res,
                   __global real* restrict d, __global real* restrict x, const uint last,
                   __global const real* restrict r, __global const real* restrict b,
                   __global const real* restrict free, __global sum_real* restrict partials) {
  COROFEM_PARTIAL_LOCALS
  COROFEM_NODE_RANGE(nodeSeg, segInfo, s, first, last_);
  const real sc = scale[s] * c2;
  sum_real ru = 0, rr = 0, bb = 0;
  for (uint n = first; n < last_; ++n) {
    real rn[3], zn[3];
    for (int k = 0; k < 3; ++k) rn[k] = res[3 * n + k] - ad[3 * n + k];
    apply_preconditioner(n, minv, rn, zn);
    for (int k = 0; k < 3; ++k) {
      const uint i = 3 * n + k;
      const real dk = c1 * d[i] + sc * zn[k];
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

/* w = R^T (b - ax) per node, R the rotation of the node's aggregate (none: R = I). */
__kernel __attribute__((reqd_work_group_size(COROFEM_WG, 1, 1)))
void amg_fine_unwarp(__global const uint* restrict nodeSeg, __global const uint* restrict segInfo,
                     __global const int* restrict nodeAggregate, __global const real* restrict rotations,
                     __global const real* restrict b, __global const real* restrict ax, __global real* restrict w) {
  uint n, s;
  if (!node_item(nodeSeg, segInfo, &n, &s)) return;
  real v[3];
  for (int k = 0; k < 3; ++k) v[k] = b[3 * n + k] - ax[3 * n + k];
  const int a = nodeAggregate[n];
  if (a < 0) {
    for (int k = 0; k < 3; ++k) w[3 * n + k] = v[k];
    return;
  }
  __global const real* R = rotations + 9 * a;
  for (int k = 0; k < 3; ++k) w[3 * n + k] = R[k] * v[0] + R[3 + k] * v[1] + R[6 + k] * v[2];
}

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

/* -- coarse levels (one work-item per row of all bodies) */

/* y = A x (mode 0) or y = b - A x (mode 1), A in slices of kAmgSlice rows (sliced ELLPACK): slice
 * s holds its rows' entries column by column from slice[s], as many columns as its longest row
 * (the shorter rows padded with zeros at column 0), so that the rows of a slice read their entries
 * side by side. Two shapes of one product (the same sums in the same order):
 *   amg_spmv         one work-item per row (GPUs: a slice's loads coalesce)
 *   amg_spmv_slices  one work-item per slice, its rows a vector (CPUs: PoCL did not vectorise the
 *                    row-per-item loop; this took 42 us against 75 on a level-1 product of the beam) */
#define kAmgSlice 16
#ifdef COROFEM_DOUBLE
typedef double16 real16;
#else
typedef float16 real16;
#endif
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
  y[i] = mode == 1u ? b[i] - sum : sum;
}

__kernel void amg_spmv_slices(const uint rows, __global const uint* restrict slice, __global const uint* restrict cols,
                              __global const real* restrict values, __global const real* restrict x,
                              __global const real* restrict b, const uint mode, __global real* restrict y) {
  const uint s = get_global_id(0), first = kAmgSlice * s;
  if (first >= rows) return;
  const uint begin = slice[s], end = slice[s + 1];
  real16 sum = (real16)0;
  for (uint j = begin; j < end; j += kAmgSlice) {
    const uint16 c = vload16(0, cols + j);
    const real16 xv = (real16)(x[c.s0], x[c.s1], x[c.s2], x[c.s3], x[c.s4], x[c.s5], x[c.s6], x[c.s7], x[c.s8],
                               x[c.s9], x[c.sa], x[c.sb], x[c.sc], x[c.sd], x[c.se], x[c.sf]);
    const real16 v = vload16(0, values + j);
    sum += select((real16)0, v * xv, isnotequal(v, (real16)0));  /* padding skipped (amg_spmv) */
  }
  real out[kAmgSlice];
  vstore16(sum, 0, out);
  for (uint k = 0; k < kAmgSlice && first + k < rows; ++k) y[first + k] = mode == 1u ? b[first + k] - out[k] : out[k];
}

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

/* x += e. */
__kernel void amg_coarse_add(const uint rows, __global const real* restrict e, __global real* restrict x) {
  const uint i = get_global_id(0);
  if (i >= rows) return;
  x[i] += e[i];
}
