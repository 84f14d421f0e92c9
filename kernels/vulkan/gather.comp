#version 450
/* Deterministic per-node gathers of the element 12-vectors (elemOut), one invocation per node, in
 * the fixed CSR order built once on the host (gatherStart / gatherEntry = 12 e + 3 c): no atomics,
 * so two runs give the same bits. The port of kernels/opencl/gather.cl and precond.cl's
 * node_stiffness_blocks:
 *   kModeSum       vout = the gathered forces
 *   kModeProduct   y = vout = massCoef M p + (gathered products) + k S p, p = vin, S the springs;
 *                  projected (y = 0 on constrained dofs) with kFlagProject; the work-group's p . y
 *                  into partialsW (PCG's delta)
 *   kModeResidual  vout = free b - A x (x = vin), the true residual after a solve; the work-group's
 *                  (0, r . r, b . b) into partials
 *   kModeBlocks    blocks = sum over incident (e, c) of R K_e,cc R^T = V ((lambda + mu) a_c a_c^T +
 *                  mu |a_c|^2 I), from the sqrt(V) a_c of element.comp's kModeCorners
 * Sums per work-group are fixed-order trees in shared memory, one triple per work-group. */
#include "common.glsl"
#include "ops.glsl"

const uint kModeSum = 0u, kModeProduct = 1u, kModeResidual = 2u, kModeBlocks = 3u;

void main() {
  const uint n = gl_GlobalInvocationID.x, lid = gl_LocalInvocationID.x, g = gl_WorkGroupID.x;
  const uint s = nodeSeg[g];
  if (seg_info(s, kSegActive) == 0u) return;  /* the whole work-group (segments are whole groups) */
  const bool real_node = n < seg_info(s, kSegNodeEnd);

  if (pc.mode == kModeBlocks) {
    if (!real_node) return;
    const real lambda = seg_coef(s, kCoefLambda), mu = seg_coef(s, kCoefMu), lm = lambda + mu;
    real b[6] = real[6](real(0), real(0), real(0), real(0), real(0), real(0));
    const uint end = gatherStart[n + 1u];
    for (uint j = gatherStart[n]; j < end; ++j) {
      const uint at = gatherEntry[j];
      const real ax = elemOut[at], ay = elemOut[at + 1u], az = elemOut[at + 2u];
      const real iso = mu * (ax * ax + ay * ay + az * az);
      b[0] += lm * ax * ax + iso;
      b[1] += lm * ay * ay + iso;
      b[2] += lm * az * az + iso;
      b[3] += lm * ax * ay;
      b[4] += lm * ax * az;
      b[5] += lm * ay * az;
    }
    for (uint k = 0u; k < 6u; ++k) blocks[6u * n + k] = b[k];
    return;
  }
  if (pc.mode == kModeSum) {
    if (!real_node) return;
    real acc[3];
    gather_node(n, acc);
    for (uint k = 0u; k < 3u; ++k) vout[3u * n + k] = acc[k];
    return;
  }

  real t0 = real(0), t1 = real(0), t2 = real(0);
  if (real_node) {
    if (pc.mode == kModeProduct) {
      t0 = gather_product_node(n, s);
    } else {  /* kModeResidual: vout = free b - A x */
      real y[3];
      product_node(n, s, y);
      for (uint k = 0u; k < 3u; ++k) {
        const uint d = 3u * n + k;
        const real bd = freeDof[d] * bvec[d], rd = bd - y[k] * freeDof[d];
        vout[d] = rd;
        t1 += rd * rd;
        t2 += bd * bd;
      }
    }
  }
  s0[lid] = t0;
  s1[lid] = t1;
  s2[lid] = t2;
  s3[lid] = real(0);
  tree4();
  if (lid == 0u) {
    if (pc.mode == kModeProduct) {
      partialsW[3u * g] = s0[0];
      partialsW[3u * g + 1u] = real(0);
      partialsW[3u * g + 2u] = real(0);
    } else {
      partials[3u * g] = real(0);
      partials[3u * g + 1u] = s1[0];
      partials[3u * g + 2u] = s2[0];
    }
  }
}
