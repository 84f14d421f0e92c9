#version 450
/* The second stage of PCG's dot products and the scalars' update, one work-group per segment
 * (kernels/opencl/pcg.cl's reduce_finish and update_scalars; the modes are corofem_layout.h's
 * kReduce*): the segment's partial triples of pcg.comp (partials: r . u, r . r, b . b) and of
 * gather.comp (partialsW: u . w) summed in a fixed order (strided lanes, then a tree), then
 *   kReduceInit      gamma, rr, bb; alpha = gamma / delta, beta = 0; iterations = 0
 *   kReduceStep      beta = gamma' / gamma, alpha = gamma' / (delta' - beta gamma' / alpha); + 1
 *   kReduceResidual  rr, bb only (the true residual)
 *   kReduceLast      gamma, rr; + 1 (the cap's last iteration: no next alpha or beta)
 * A non-positive p . A p sets alpha = 0 and the breakdown flag. After every mode but Residual the
 * stop test (tolerance^2 at kScalarTol2): a converged, broken-down or non-finite segment records why
 * and becomes inactive, so the iterations already recorded cost it nothing.
 *   kReduceEnergy    none of the above, and dispatched over the element work-groups (element.comp's):
 *                    work-group g sums the energies its elements' forces wrote (energy[64 g + i], a
 *                    tree) into energy[S + g], so that the host reads one real per 64 elements with
 *                    the forces and adds each body's in order. */
#include "common.glsl"
#include "ops.glsl"

void main() {
  const uint seg = pc.mode == kReduceEnergy ? elemSeg[gl_WorkGroupID.x] : gl_WorkGroupID.x;
  if (seg_info(seg, kSegActive) == 0u) return;  /* the whole work-group */
  if (pc.mode == kReduceEnergy) {
    const uint lid = gl_LocalInvocationID.x, g = gl_WorkGroupID.x, e = WG * g + lid;
    s0[lid] = e < seg_info(seg, kSegElemEnd) ? energy[e] : real(0);
    s1[lid] = real(0);
    s2[lid] = real(0);
    s3[lid] = real(0);
    tree4();
    if (lid == 0u) energy[pc.S + g] = s0[0];
    return;
  }
  segment_sums(seg);
  if (gl_LocalInvocationID.x == 0u) update_scalars(seg, pc.mode, s0[0], s1[0], s2[0], s3[0]);
}
