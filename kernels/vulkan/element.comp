#version 450
/* Matrix-free co-rotational element operators, one invocation per element, each writing its
 * element's 12-vector (12 e + 3 c + k) for the deterministic per-node gather (gather.comp): the port
 * of kernels/opencl/element_force.cl (its derivation is there). With the rotated gradients
 * a_i = R grad N_i (rotations.comp; the linear formulation: the gradients themselves):
 *   kModeForces   f = R K (R^T x - X) (Eq. 9): P = sum_{i=1..3} (x_i - x_0) a_i^T, E = sym(P) - I,
 *                 S_w = lambda tr(E) I + 2 mu E, f_i = V S_w a_i, f_0 = -(f_1 + f_2 + f_3); and the
 *                 element's strain energy V/2 S_w : E into energy[e]
 *   kModeProduct  y_e = k R K R^T p_e (Eq. 11): the same algebra on p = vin without the shift,
 *                 lambda and mu already multiplied by the stiffness coefficient (kCoefProd*)
 *   kModeCorners  sqrt(V) a_c of every corner (a_0 = -(a_1 + a_2 + a_3)), for the preconditioner's
 *                 node blocks (gather.comp, kModeBlocks)
 * Only the elements of active segments run. */
#include "common.glsl"

const uint kModeForces = 0u, kModeProduct = 1u, kModeCorners = 2u;

void main() {
  const uint e = gl_GlobalInvocationID.x, S = pc.S;
  const uint s = elemSeg[e / WG];
  if (seg_info(s, kSegActive) == 0u || e >= seg_info(s, kSegElemEnd)) return;
  real a[9];
  for (uint k = 0u; k < 9u; ++k) a[k] = rotGrad[k * S + e];
  const real V = geom[kGeomVolume * S + e];
  if (pc.mode == kModeCorners) {
    const real w = sqrt(V);
    for (uint k = 0u; k < 3u; ++k) elemOut[12u * e + k] = -w * (a[k] + a[3 + k] + a[6 + k]);
    for (uint c = 1u; c < 4u; ++c)
      for (uint k = 0u; k < 3u; ++k) elemOut[12u * e + 3u * c + k] = w * a[3 * (c - 1u) + k];
    return;
  }
  const bool forces = pc.mode == kModeForces;
  const real lambda = seg_coef(s, forces ? kCoefLambda : kCoefProdLambda);
  const real mu = seg_coef(s, forces ? kCoefMu : kCoefProdMu);
  const real shift = forces ? real(1) : real(0);
  uint node[4];
  for (uint c = 0u; c < 4u; ++c) node[c] = corners[c * S + e];
  /* P = sum_{i=1..3} (v_i - v_0) a_i^T, v the positions or p */
  real P[9];
  for (int k = 0; k < 9; ++k) P[k] = real(0);
  real v0[3];
  for (uint j = 0u; j < 3u; ++j) v0[j] = forces ? pos[3u * node[0] + j] : vin[3u * node[0] + j];
  for (uint i = 1u; i < 4u; ++i)
    for (uint j = 0u; j < 3u; ++j) {
      const real d = (forces ? pos[3u * node[i] + j] : vin[3u * node[i] + j]) - v0[j];
      for (uint k = 0u; k < 3u; ++k) P[3 * j + k] += d * a[3 * (i - 1u) + k];
    }
  const real exx = P[0] - shift, eyy = P[4] - shift, ezz = P[8] - shift;
  const real exy = real(0.5) * (P[1] + P[3]);
  const real exz = real(0.5) * (P[2] + P[6]);
  const real eyz = real(0.5) * (P[5] + P[7]);
  const real lt = lambda * (exx + eyy + ezz);
  const real m2 = real(2) * mu;
  const real sxx = V * (lt + m2 * exx), syy = V * (lt + m2 * eyy), szz = V * (lt + m2 * ezz);
  const real sxy = V * (m2 * exy), sxz = V * (m2 * exz), syz = V * (m2 * eyz);
  real y0x = real(0), y0y = real(0), y0z = real(0);
  for (uint i = 0u; i < 3u; ++i) {
    const real ax = a[3 * i], ay = a[3 * i + 1], az = a[3 * i + 2];
    const real yx = sxx * ax + sxy * ay + sxz * az;
    const real yy = sxy * ax + syy * ay + syz * az;
    const real yz = sxz * ax + syz * ay + szz * az;
    elemOut[12u * e + 3u * (i + 1u)] = yx;
    elemOut[12u * e + 3u * (i + 1u) + 1u] = yy;
    elemOut[12u * e + 3u * (i + 1u) + 2u] = yz;
    y0x -= yx;
    y0y -= yy;
    y0z -= yz;
  }
  elemOut[12u * e] = y0x;
  elemOut[12u * e + 1u] = y0y;
  elemOut[12u * e + 2u] = y0z;
  if (forces)
    energy[e] = real(0.5) * (sxx * exx + syy * eyy + szz * ezz + real(2) * (sxy * exy + sxz * exz + syz * eyz));
}
