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
 *   kReduceEnergy    none of the above: the segment's strain energy, the sum of its elements' energies
 *                    (energy[], written by element.comp's forces), into kScalarEnergy, so that the host
 *                    reads a real per segment with the forces, not a real per element. Summed in the
 *                    same fixed order (strided lanes from the segment's first element, each
 *                    compensated, then the tree):
 *                    a body's bits do not depend on where its segment lies. */
#include "common.glsl"
#include "ops.glsl"

void main() {
  const uint seg = gl_WorkGroupID.x;
  if (seg_info(seg, kSegActive) == 0u) return;  /* the whole work-group */
  if (pc.mode == kReduceEnergy) {
    const uint lid = gl_LocalInvocationID.x;
    const uint begin = seg_info(seg, kSegElemBegin), end = seg_info(seg, kSegElemEnd);
    /* Compensated (Kahan) per lane: a lane adds up to E / 64 energies, in float a million-element
     * body's 15,600, whose rounding would otherwise reach 1e-4 of the sum. */
    precise real sum = real(0), lost = real(0);
    for (uint e = begin + lid; e < end; e += WG) {
      precise const real y = energy[e] - lost;
      precise const real t = sum + y;
      lost = (t - sum) - y;
      sum = t;
    }
    s0[lid] = sum;
    s1[lid] = real(0);
    s2[lid] = real(0);
    s3[lid] = real(0);
    tree4();
    if (lid == 0u) scalars[kScalarCount * seg + kScalarEnergy] = s0[0];
    return;
  }
  segment_sums(seg);
  if (gl_LocalInvocationID.x == 0u) update_scalars(seg, pc.mode, s0[0], s1[0], s2[0], s3[0]);
}
