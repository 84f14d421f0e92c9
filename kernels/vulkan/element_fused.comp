#version 450
/* The element half of a PCG iteration in two dispatches (pcg_fused.comp's kModeUpdateProduct is the
 * node half), one invocation per element: element.comp's product of PCG's next u, k R K R^T u_e,
 * with u computed at the element's corners from the vectors before the iteration's update (ops.glsl's
 * pcg_corner_u, with the segment's alpha and beta): the u that the node pass stores, the same
 * arithmetic with no contraction (`precise`). A shader of its own: as a mode of element.comp it
 * slowed lavapipe's code for that shader's other modes (docs/performance.md). */
#include "common.glsl"
#include "ops.glsl"

void main() {
  const uint e = gl_GlobalInvocationID.x, S = pc.S;
  const uint s = elemSeg[e / WG];
  if (seg_info(s, kSegActive) == 0u || e >= seg_info(s, kSegElemEnd)) return;
  const real alpha = scalars[kScalarCount * s + kScalarAlpha], beta = scalars[kScalarCount * s + kScalarBeta];
  real v[12];
  for (uint c = 0u; c < 4u; ++c) {
    real u[3];
    pcg_corner_u(corners[c * S + e], alpha, beta, u);
    for (uint j = 0u; j < 3u; ++j) v[3u * c + j] = u[j];
  }
  element_pass_of(e, S, seg_coef(s, kCoefProdLambda), seg_coef(s, kCoefProdMu), false, v);
}
