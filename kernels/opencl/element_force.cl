/* Matrix-free co-rotational element operators, one work-item per element, each writing the
 * element's 12-vector (corner c, component k at (3 c + k) * S + e) for the deterministic per-node
 * gather (gather.cl).
 *
 * Internal force (paper Eq. 9): f = R K (R^T x - X). With K = V B^T H B (Eq. 7) applied from the
 * gradients instead of a stored 12x12:
 *   q_i = R^T x_i - X_i,  G = sum_i q_i grad_i^T = R^T F - I   (sum_i X_i grad_i^T = D_m D_m^-1 = I),
 *   eps = (G + G^T) / 2,  sigma = lambda tr(eps) I + 2 mu eps,  f_i = R (V sigma grad_i).
 * Everything is rotated into the current frame with the rotated gradients a_i = R grad_i written
 * by compute_rotations: E = R eps R^T = sym(F R^T) - I with F R^T = sum_{i=1..3} (x_i - x_0) a_i^T,
 * S_w = R sigma R^T = lambda tr(E) I + 2 mu E, f_i = V S_w a_i, f_0 = -(f_1 + f_2 + f_3)
 * (sum_i grad_i = 0). R itself is never read: 9 + 1 reals per element instead of 9 + 9 + 1.
 *
 * Product with the rotated stiffness (Eq. 11, K^R = R K R^T), the same algebra without the rest
 * state: P = sum_{i=1..3} (p_i - p_0) a_i^T, E = sym(P), y_i = V S_w a_i. The stiffness
 * coefficient of the system matrix is folded into lambda and mu by the host.
 *
 * Linear formulation: R = I, a_i = grad_i (uploaded once, compute_rotations never runs).
 */
#ifndef COROFEM_EMBEDDED
#include "../shared/corofem_layout.h"
#include "mat3.cl"
#endif

/* Reads the rotated gradients a_1..a_3 (a[3 (i-1) + k]) and the volume of element e. */
inline real load_rotated_gradients(uint e, uint S, __global const real* rotGrad,
                                   __global const real* geom, real* a) {
  for (int k = 0; k < 9; ++k) a[k] = rotGrad[k * S + e];
  return geom[kGeomVolume * S + e];
}

/* sum_{i=1..3} (v_i - v_0) a_i^T for a node vector v (3N) at the element's corners. */
inline Mat3 corner_outer_sum(uint e, uint S, __global const uint* nodes, __global const real* v,
                             const real* a) {
  const uint n0 = nodes[e];
  const real v0x = v[3 * n0], v0y = v[3 * n0 + 1], v0z = v[3 * n0 + 2];
  Mat3 P;
  for (int k = 0; k < 9; ++k) P.m[k] = (real)0;
  for (int i = 1; i < 4; ++i) {
    const uint n = nodes[i * S + e];
    const real d[3] = {v[3 * n] - v0x, v[3 * n + 1] - v0y, v[3 * n + 2] - v0z};
    const real* ai = a + 3 * (i - 1);
    for (int j = 0; j < 3; ++j)
      for (int k = 0; k < 3; ++k) P.m[3 * j + k] += d[j] * ai[k];
  }
  return P;
}

/* Given E (symmetric part taken here, minus `shift` I), writes y_i = V S_w a_i with
 * S_w = lambda tr(E) I + 2 mu E, and y_0 = -(y_1 + y_2 + y_3). Returns S_w : E. */
inline real write_stress_times_gradients(uint e, uint S, const Mat3* P, real shift, real volume,
                                         real lambda, real mu, const real* a,
                                         __global real* out) {
  const real exx = P->m[0] - shift, eyy = P->m[4] - shift, ezz = P->m[8] - shift;
  const real exy = (real)0.5 * (P->m[1] + P->m[3]);
  const real exz = (real)0.5 * (P->m[2] + P->m[6]);
  const real eyz = (real)0.5 * (P->m[5] + P->m[7]);
  const real lt = lambda * (exx + eyy + ezz), m2 = 2 * mu;
  /* V S_w */
  const real sxx = volume * (lt + m2 * exx), syy = volume * (lt + m2 * eyy),
             szz = volume * (lt + m2 * ezz);
  const real sxy = volume * m2 * exy, sxz = volume * m2 * exz, syz = volume * m2 * eyz;
  real y0x = 0, y0y = 0, y0z = 0;
  for (int i = 0; i < 3; ++i) {
    const real ax = a[3 * i], ay = a[3 * i + 1], az = a[3 * i + 2];
    const real yx = sxx * ax + sxy * ay + sxz * az;
    const real yy = sxy * ax + syy * ay + syz * az;
    const real yz = sxz * ax + syz * ay + szz * az;
    out[(3 * (i + 1)) * S + e] = yx;
    out[(3 * (i + 1) + 1) * S + e] = yy;
    out[(3 * (i + 1) + 2) * S + e] = yz;
    y0x -= yx;
    y0y -= yy;
    y0z -= yz;
  }
  out[e] = y0x;
  out[S + e] = y0y;
  out[2 * S + e] = y0z;
  /* V S_w : E (for the energy) */
  return sxx * exx + syy * eyy + szz * ezz + 2 * (sxy * exy + sxz * exz + syz * eyz);
}

/* Internal forces, Eq. 9. */
__kernel __attribute__((reqd_work_group_size(COROFEM_WG, 1, 1)))
void element_forces(const uint count, const uint S, __global const uint* restrict nodes,
                    __global const real* restrict geom, __global const real* restrict rotGrad,
                    __global const real* restrict pos, const real lambda, const real mu,
                    __global real* restrict out) {
  const uint e = get_global_id(0);
  if (e >= count) return;
  real a[9];
  const real volume = load_rotated_gradients(e, S, rotGrad, geom, a);
  const Mat3 FRt = corner_outer_sum(e, S, nodes, pos, a); /* F R^T */
  write_stress_times_gradients(e, S, &FRt, (real)1, volume, lambda, mu, a, out);
}

/* Strain energy V/2 S_w : E = 1/2 (R^T x - X)^T K (R^T x - X) per element, summed per work-group
 * (fixed tree order) into partials[group]. `out` is scratch (the forces come for free). */
__kernel __attribute__((reqd_work_group_size(COROFEM_WG, 1, 1)))
void element_energy(const uint count, const uint S, __global const uint* restrict nodes,
                    __global const real* restrict geom, __global const real* restrict rotGrad,
                    __global const real* restrict pos, const real lambda, const real mu,
                    __global real* restrict out, __global real* restrict partials) {
  __local real sum[COROFEM_WG];
  const uint e = get_global_id(0), lid = get_local_id(0);
  real energy = (real)0;
  if (e < count) {
    real a[9];
    const real volume = load_rotated_gradients(e, S, rotGrad, geom, a);
    const Mat3 FRt = corner_outer_sum(e, S, nodes, pos, a);
    energy = (real)0.5 * write_stress_times_gradients(e, S, &FRt, (real)1, volume, lambda, mu, a, out);
  }
  sum[lid] = energy;
  barrier(CLK_LOCAL_MEM_FENCE);
  for (uint s = COROFEM_WG / 2; s > 0; s >>= 1) {
    if (lid < s) sum[lid] += sum[lid + s];
    barrier(CLK_LOCAL_MEM_FENCE);
  }
  if (lid == 0) partials[get_group_id(0)] = sum[0];
}

/* y_e = k R K R^T p_e (Eq. 11) from the gradients; lambda, mu already multiplied by k. */
__kernel __attribute__((reqd_work_group_size(COROFEM_WG, 1, 1)))
void element_product(const uint count, const uint S, __global const uint* restrict nodes,
                     __global const real* restrict geom, __global const real* restrict rotGrad,
                     __global const real* restrict p, const real lambda, const real mu,
                     __global real* restrict out) {
  const uint e = get_global_id(0);
  if (e >= count) return;
  real a[9];
  const real volume = load_rotated_gradients(e, S, rotGrad, geom, a);
  const Mat3 P = corner_outer_sum(e, S, nodes, p, a);
  write_stress_times_gradients(e, S, &P, (real)0, volume, lambda, mu, a, out);
}

/* Stored-K_e variant: y_e = k R (K_e (R^T p_e)) with the upper triangle of K_e (78 reals, row by
 * row) computed on the host by detail::linearStiffness. Reads 78 + 9 reals per element instead of
 * 10: kept to measure that trade (bench_opencl), not the default. */
__kernel __attribute__((reqd_work_group_size(COROFEM_WG, 1, 1)))
void element_product_stored(const uint count, const uint S, __global const uint* restrict nodes,
                            __global const real* restrict stiffness, __global const real* restrict rot,
                            __global const real* restrict p, const real k,
                            __global real* restrict out) {
  const uint e = get_global_id(0);
  if (e >= count) return;
  real R[9];
  for (int j = 0; j < 9; ++j) R[j] = rot[j * S + e];
  real q[12], y[12];
  for (int c = 0; c < 4; ++c) {
    const uint n = nodes[c * S + e];
    const real px = p[3 * n], py = p[3 * n + 1], pz = p[3 * n + 2];
    for (int j = 0; j < 3; ++j) q[3 * c + j] = R[j] * px + R[3 + j] * py + R[6 + j] * pz; /* R^T p */
    y[3 * c] = y[3 * c + 1] = y[3 * c + 2] = (real)0;
  }
  uint idx = 0;
  for (int r = 0; r < 12; ++r) {
    y[r] += stiffness[idx * S + e] * q[r];
    ++idx;
    for (int c = r + 1; c < 12; ++c, ++idx) {
      const real kv = stiffness[idx * S + e];
      y[r] += kv * q[c];
      y[c] += kv * q[r];
    }
  }
  for (int c = 0; c < 4; ++c)
    for (int j = 0; j < 3; ++j)
      out[(3 * c + j) * S + e] =
          k * (R[3 * j] * y[3 * c] + R[3 * j + 1] * y[3 * c + 1] + R[3 * j + 2] * y[3 * c + 2]);
}
