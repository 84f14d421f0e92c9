/* Preconditioners of the system matrix A = massCoef M + k K^R: its diagonal or its 3x3 node
 * blocks, inverted per node. The diagonal blocks of the rotated element stiffness have a closed
 * form: for corner i with gradient g_i and rotated gradient a_i = R g_i,
 *   R K_e,ii R^T = V ((lambda + mu) a_i a_i^T + mu |a_i|^2 I)
 * (from sigma = lambda tr(eps) I + 2 mu eps with eps = sym(u g_i^T)), so no 12x12 is needed.
 * corner_gradients + node_stiffness_blocks run before a solve whose rotations changed since its
 * blocks were formed (the blocks rotate with the elements; a step's last evaluation, which no solve
 * follows, forms none); node_preconditioner mixes in the coefficients of the solve and inverts,
 * inside pcg_init (pcg.cl). Each takes its segment's (body's) material and coefficients (corofem_layout.h).
 */
#ifndef COROFEM_EMBEDDED
#include "../shared/corofem_layout.h"
#include "../shared/corofem_vector.h"
#endif

/* Reals per node in `blocks`: the symmetric block (xx, yy, zz, xy, xz, yz) for the block
 * preconditioner, its diagonal (xx, yy, zz) for the diagonal one. */
#ifdef COROFEM_PRECOND_BLOCK
#define COROFEM_NODE_BLOCK 6
#else
#define COROFEM_NODE_BLOCK 3
#endif
/* Reals per node in `minv`, the inverse: a row-major 3x3 (block) or the diagonal's 3. */
#ifdef COROFEM_PRECOND_BLOCK
#define COROFEM_NODE_INVERSE 9
#else
#define COROFEM_NODE_INVERSE 3
#endif

/* Element pass: a_c of every corner into the element output buffer (store_corner), for
 * node_stiffness_blocks to gather, from the a_i compute_rotations wrote (the same values as its own
 * writeCorners stores: the forces overwrite those before a solve needs them). */
__kernel __attribute__((reqd_work_group_size(COROFEM_WG, 1, 1)))
void corner_gradients(const uint S, __global const uint* restrict elemSeg, __global const uint* restrict segInfo,
                      __global const real* restrict geom, __global const real* restrict rotGrad,
                      __global real* restrict out) {
  uint e0, s;
  if (!element_items(elemSeg, segInfo, &e0, &s)) return;
  realv a[9];
  #pragma unroll
  for (int k = 0; k < 9; ++k) a[k] = VLOAD(rotGrad + k * S + e0);
  store_corner_gradients(out, e0, a, VLOAD(geom + kGeomVolume * S + e0));
}

/* blocks[COROFEM_NODE_BLOCK n + (xx, yy, zz[, xy, xz, yz])] = sum over incident (e, c) of R K_e,cc R^T
 * = V ((lambda + mu) a_c a_c^T + mu |a_c|^2 I), from the sqrt(V) a_c written by compute_rotations
 * or corner_gradients, in the fixed CSR order. */
__kernel __attribute__((reqd_work_group_size(COROFEM_WG, 1, 1)))
void node_stiffness_blocks(__global const uint* restrict nodeSeg, __global const uint* restrict segInfo,
                           __global const real* restrict segCoef, __global const uint* restrict start,
                           __global const uint* restrict entries, __global const real* restrict corners,
                           __global real* restrict blocks) {
  uint n, s;
  if (!node_item(nodeSeg, segInfo, &n, &s)) return;
  const real lambda = seg_coef(segCoef, s, kCoefLambda), mu = seg_coef(segCoef, s, kCoefMu);
  real b[6] = {0, 0, 0, 0, 0, 0};
  const uint end = start[n + 1];
  const real lm = lambda + mu;
  for (uint j = start[n]; j < end; ++j) {
    __global const real* c = corners + (size_t)entries[j];
    const real ax = c[0], ay = c[COROFEM_VEC], az = c[2 * COROFEM_VEC];
    const real iso = mu * (ax * ax + ay * ay + az * az);
    b[0] += lm * ax * ax + iso;
    b[1] += lm * ay * ay + iso;
    b[2] += lm * az * az + iso;
#ifdef COROFEM_PRECOND_BLOCK /* the diagonal preconditioner reads only the diagonal */
    b[3] += lm * ax * ay;
    b[4] += lm * ax * az;
    b[5] += lm * ay * az;
#endif
  }
#ifdef COROFEM_PRECOND_BLOCK
  #pragma unroll
  for (int k = 0; k < 6; ++k) blocks[COROFEM_NODE_BLOCK * n + k] = b[k];
#else
  #pragma unroll
  for (int k = 0; k < 3; ++k) blocks[COROFEM_NODE_BLOCK * n + k] = b[k];
#endif
}

/* B = k blocks + massCoef diag(m) of node n, rows/columns of constrained dofs replaced by the
 * identity, inverted into m (9 entries, row-major 3x3, with COROFEM_PRECOND_BLOCK; 3 with
 * COROFEM_PRECOND_DIAG). Constrained dofs get 0 in the inverse so that z = M^-1 r stays 0 there. A
 * non-positive pivot (a node touched by no element and massless) falls back to 1. pcg_init forms it
 * for every node of a solve (the coefficients are the solve's) and stores it for pcg_update. */
COROFEM_FN void node_preconditioner(uint n, real massCoef, real stiffCoef, __global const real* blocks,
                                    __global const real* mass, __global const real* free, real* m) {
  const real f0 = free[3 * n], f1 = free[3 * n + 1], f2 = free[3 * n + 2];
  /* mass = NULL: no body on this device has mass (static problems) */
  const real m0 = mass ? mass[3 * n] : (real)0, m1 = mass ? mass[3 * n + 1] : (real)0,
             m2 = mass ? mass[3 * n + 2] : (real)0;
  real d0 = stiffCoef * blocks[COROFEM_NODE_BLOCK * n] + massCoef * m0;
  real d1 = stiffCoef * blocks[COROFEM_NODE_BLOCK * n + 1] + massCoef * m1;
  real d2 = stiffCoef * blocks[COROFEM_NODE_BLOCK * n + 2] + massCoef * m2;
#ifdef COROFEM_PRECOND_BLOCK
  real b01 = stiffCoef * blocks[COROFEM_NODE_BLOCK * n + 3] * f0 * f1;
  real b02 = stiffCoef * blocks[COROFEM_NODE_BLOCK * n + 4] * f0 * f2;
  real b12 = stiffCoef * blocks[COROFEM_NODE_BLOCK * n + 5] * f1 * f2;
  if (f0 == (real)0) d0 = 1;
  if (f1 == (real)0) d1 = 1;
  if (f2 == (real)0) d2 = 1;
  /* symmetric inverse by cofactors */
  const real c00 = d1 * d2 - b12 * b12, c01 = b02 * b12 - b01 * d2, c02 = b01 * b12 - b02 * d1;
  const real c11 = d0 * d2 - b02 * b02, c12 = b01 * b02 - d0 * b12, c22 = d0 * d1 - b01 * b01;
  const real det = d0 * c00 + b01 * c01 + b02 * c02;
  if (det > (real)0 && d0 > (real)0 && d1 > (real)0 && d2 > (real)0) {
    const real inv = (real)1 / det;
    m[0] = c00 * inv * f0;      m[1] = c01 * inv * f0 * f1; m[2] = c02 * inv * f0 * f2;
    m[3] = c01 * inv * f0 * f1; m[4] = c11 * inv * f1;      m[5] = c12 * inv * f1 * f2;
    m[6] = c02 * inv * f0 * f2; m[7] = c12 * inv * f1 * f2; m[8] = c22 * inv * f2;
  } else {
    m[0] = f0 * (d0 > (real)0 ? (real)1 / d0 : (real)1); m[1] = m[2] = m[3] = (real)0;
    m[4] = f1 * (d1 > (real)0 ? (real)1 / d1 : (real)1); m[5] = m[6] = m[7] = (real)0;
    m[8] = f2 * (d2 > (real)0 ? (real)1 / d2 : (real)1);
  }
#else
  m[0] = f0 * (d0 > (real)0 ? (real)1 / d0 : (real)1);
  m[1] = f1 * (d1 > (real)0 ? (real)1 / d1 : (real)1);
  m[2] = f2 * (d2 > (real)0 ? (real)1 / d2 : (real)1);
#endif
}
