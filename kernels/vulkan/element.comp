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
#include "ops.glsl"

const uint kModeForces = 0u, kModeProduct = 1u, kModeCorners = 2u;

void main() {
  const uint e = gl_GlobalInvocationID.x, S = pc.S;
  const uint s = elemSeg[e / WG];
  if (seg_info(s, kSegActive) == 0u || e >= seg_info(s, kSegElemEnd)) return;
  if (pc.mode == kModeCorners) {
    const real w = sqrt(geom[kGeomVolume * S + e]);
    real a[9];
    for (uint k = 0u; k < 9u; ++k) a[k] = rotGrad[k * S + e];
    for (uint k = 0u; k < 3u; ++k) elemOut[12u * e + k] = -w * (a[k] + a[3 + k] + a[6 + k]);
    for (uint c = 1u; c < 4u; ++c)
      for (uint k = 0u; k < 3u; ++k) elemOut[12u * e + 3u * c + k] = w * a[3 * (c - 1u) + k];
    return;
  }
  const bool forces = pc.mode == kModeForces;
  const real energyOf = element_pass(e, S, seg_coef(s, forces ? kCoefLambda : kCoefProdLambda),
                                     seg_coef(s, forces ? kCoefMu : kCoefProdMu), forces);
  if (forces) energy[e] = energyOf;
}
