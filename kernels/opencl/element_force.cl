/* Matrix-free co-rotational element operators, one work-item per COROFEM_VEC elements, each
 * writing the elements' 12-vectors in blocks of VEC elements (store_corner, corofem_vector.h) for
 * the deterministic per-node gather (gather.cl).
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
 *
 * Each work-item handles COROFEM_VEC consecutive elements with vector arithmetic (corofem_vector.h).
 * Every kernel serves one or many bodies (segments, corofem_layout.h): a work-group finds its
 * segment in elemSeg, returns at once when the segment is inactive, and takes the segment's
 * material and coefficients from segCoef.
 */
#ifndef COROFEM_EMBEDDED
#include "../shared/corofem_layout.h"
#include "../shared/corofem_vector.h"
#endif

/* The VEC elements e0 .. e0 + VEC - 1: corner node indices, rotated gradients a_1..a_3
 * (a[3 (i-1) + k]) and volumes. */
typedef struct {
  uintv node[4];
  realv a[9];
  realv volume;
} ElemBlock;

COROFEM_FN void load_element_block(uint e0, uint S, __global const uint* nodes, __global const real* geom,
                               __global const real* rotGrad, ElemBlock* b) {
  #pragma unroll
  for (int c = 0; c < 4; ++c) b->node[c] = VLOAD_INDEX(nodes + c * S + e0);
  #pragma unroll
  for (int k = 0; k < 9; ++k) b->a[k] = VLOAD(rotGrad + k * S + e0);
  b->volume = VLOAD(geom + kGeomVolume * S + e0);
}

/* sum_{i=1..3} (v_i - v_0) a_i^T for a node vector v (3N) at the elements' corners (9 entries,
 * row-major). */
COROFEM_FN void corner_outer_sum(const ElemBlock* b, __global const real* v, realv* P) {
  realv v0[3];
  #pragma unroll
  for (int j = 0; j < 3; ++j) v0[j] = gather_node_component(v, b->node[0], j);
  #pragma unroll
  for (int k = 0; k < 9; ++k) P[k] = (realv)0;
  #pragma unroll
  for (int i = 1; i < 4; ++i) {
    #pragma unroll
    for (int j = 0; j < 3; ++j) {
      const realv d = gather_node_component(v, b->node[i], j) - v0[j];
      #pragma unroll
      for (int k = 0; k < 3; ++k) P[3 * j + k] += d * b->a[3 * (i - 1) + k];
    }
  }
}

/* Given P, E = sym(P) - shift I, S_w = lambda tr(E) I + 2 mu E; writes y_i = V S_w a_i and
 * y_0 = -(y_1 + y_2 + y_3) to out; returns V S_w : E (twice the energy). */
COROFEM_FN realv write_stress_times_gradients(uint e0, uint S, const realv* P, real shift, const ElemBlock* b,
                                          real lambda, real mu, __global real* out) {
  const realv exx = P[0] - shift, eyy = P[4] - shift, ezz = P[8] - shift;
  const realv exy = (real)0.5 * (P[1] + P[3]);
  const realv exz = (real)0.5 * (P[2] + P[6]);
  const realv eyz = (real)0.5 * (P[5] + P[7]);
  const realv V = b->volume;
  const realv lt = lambda * (exx + eyy + ezz);
  const real m2 = 2 * mu;
  /* V S_w */
  const realv sxx = V * (lt + m2 * exx), syy = V * (lt + m2 * eyy), szz = V * (lt + m2 * ezz);
  const realv sxy = V * (m2 * exy), sxz = V * (m2 * exz), syz = V * (m2 * eyz);
  realv y0x = (realv)0, y0y = (realv)0, y0z = (realv)0;
  #pragma unroll
  for (int i = 0; i < 3; ++i) {
    const realv ax = b->a[3 * i], ay = b->a[3 * i + 1], az = b->a[3 * i + 2];
    const realv yx = sxx * ax + sxy * ay + sxz * az;
    const realv yy = sxy * ax + syy * ay + syz * az;
    const realv yz = sxz * ax + syz * ay + szz * az;
    store_corner(out, e0, i + 1, yx, yy, yz);
    y0x -= yx;
    y0y -= yy;
    y0z -= yz;
  }
  store_corner(out, e0, 0, y0x, y0y, y0z);
  return sxx * exx + syy * eyy + szz * ezz + (real)2 * (sxy * exy + sxz * exz + syz * eyz);
}

/* Internal forces, Eq. 9: P = F R^T, E = sym(F R^T) - I. With `energy` (not NULL; CPU devices):
 * also the strain energy of the work-item's VEC elements, V/2 S_w : E summed over its lanes in a
 * fixed order, at energy[global id] (0 for work-items past the segment's last element), which the
 * host sums per segment: the energy of the forces' own positions at no extra pass. */
__kernel __attribute__((reqd_work_group_size(COROFEM_WG, 1, 1)))
void element_forces(const uint S, __global const uint* restrict elemSeg, __global const uint* restrict segInfo,
                    __global const real* restrict segCoef, __global const uint* restrict nodes,
                    __global const real* restrict geom, __global const real* restrict rotGrad,
                    __global const real* restrict pos, __global real* restrict out,
                    __global real* restrict energy) {
  uint e0, s;
  if (!element_items(elemSeg, segInfo, &e0, &s)) {
    if (energy) energy[get_global_id(0)] = (real)0;
    return;
  }
  const real lambda = seg_coef(segCoef, s, kCoefLambda), mu = seg_coef(segCoef, s, kCoefMu);
  ElemBlock b;
  load_element_block(e0, S, nodes, geom, rotGrad, &b);
  realv P[9];
  corner_outer_sum(&b, pos, P);
  const realv twice = write_stress_times_gradients(e0, S, P, (real)1, &b, lambda, mu, out);
  if (energy) energy[get_global_id(0)] = (real)0.5 * lane_sum(twice);
}

/* Strain energy V/2 S_w : E = 1/2 (R^T x - X)^T K (R^T x - X) per element, summed per work-group
 * (lanes, then a fixed tree order) into partials[group] (the host sums a segment's groups). `out` is scratch (the forces). Padding
 * lanes have V = 0 and contribute nothing. */
__kernel __attribute__((reqd_work_group_size(COROFEM_WG, 1, 1)))
void element_energy(const uint S, __global const uint* restrict elemSeg, __global const uint* restrict segInfo,
                    __global const real* restrict segCoef, __global const uint* restrict nodes,
                    __global const real* restrict geom, __global const real* restrict rotGrad,
                    __global const real* restrict pos, __global real* restrict out,
                    __global real* restrict partials) {
  __local real sum[COROFEM_WG];
  const uint s = element_segment(elemSeg), e0 = get_global_id(0) * COROFEM_VEC, lid = get_local_id(0);
  if (seg_info(segInfo, s, kSegActive) == 0u) return; /* the whole work-group: before the barriers */
  const real lambda = seg_coef(segCoef, s, kCoefLambda), mu = seg_coef(segCoef, s, kCoefMu);
  real energy = (real)0;
  if (e0 < seg_info(segInfo, s, kSegElemEnd)) {
    ElemBlock b;
    load_element_block(e0, S, nodes, geom, rotGrad, &b);
    realv P[9];
    corner_outer_sum(&b, pos, P);
    energy = (real)0.5 * lane_sum(write_stress_times_gradients(e0, S, P, (real)1, &b, lambda, mu, out));
  }
  sum[lid] = energy;
  barrier(CLK_LOCAL_MEM_FENCE);
  for (uint s = COROFEM_WG / 2; s > 0; s >>= 1) {
    if (lid < s) sum[lid] += sum[lid + s];
    barrier(CLK_LOCAL_MEM_FENCE);
  }
  if (lid == 0) partials[get_global_id(0) / COROFEM_WG] = sum[0]; /* the element work-group */
}

/* The product's 12-vectors of the VEC elements e0 .. e0 + VEC - 1 (element_product, and the
 * element phase of pcg_iterate_group: the same code, so the same bits). */
COROFEM_FN void element_product_items(uint e0, uint S, real lambda, real mu, __global const uint* nodes,
                                      __global const real* geom, __global const real* rotGrad,
                                      __global const real* p, __global real* out) {
  ElemBlock b;
  load_element_block(e0, S, nodes, geom, rotGrad, &b);
  realv P[9];
  corner_outer_sum(&b, p, P);
  write_stress_times_gradients(e0, S, P, (real)0, &b, lambda, mu, out);
}

/* y_e = k R K R^T p_e (Eq. 11) from the gradients; the segment's lambda, mu already multiplied by k. */
__kernel __attribute__((reqd_work_group_size(COROFEM_WG, 1, 1)))
void element_product(const uint S, __global const uint* restrict elemSeg, __global const uint* restrict segInfo,
                     __global const real* restrict segCoef, __global const uint* restrict nodes,
                     __global const real* restrict geom, __global const real* restrict rotGrad,
                     __global const real* restrict p, __global real* restrict out) {
  uint e0, s;
  if (!element_items(elemSeg, segInfo, &e0, &s)) return;
  element_product_items(e0, S, seg_coef(segCoef, s, kCoefProdLambda), seg_coef(segCoef, s, kCoefProdMu), nodes, geom,
                        rotGrad, p, out);
}
