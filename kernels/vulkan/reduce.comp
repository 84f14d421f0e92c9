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
 * and becomes inactive, so the iterations already recorded cost it nothing. */
#include "common.glsl"

shared real s0[64], s1[64], s2[64], s3[64];

void main() {
  const uint lid = gl_LocalInvocationID.x, seg = gl_WorkGroupID.x;
  if (seg_info(seg, kSegActive) == 0u) return;  /* the whole work-group */
  const uint begin = 3u * seg_info(seg, kSegPartialBegin), count = seg_info(seg, kSegPartialCount);
  real a = real(0), b = real(0), c = real(0), d = real(0);
  for (uint g = lid; g < count; g += WG) {
    a += partials[begin + 3u * g];
    b += partials[begin + 3u * g + 1u];
    c += partials[begin + 3u * g + 2u];
    d += partialsW[begin + 3u * g];
  }
  s0[lid] = a;
  s1[lid] = b;
  s2[lid] = c;
  s3[lid] = d;
  barrier();
  for (uint h = WG / 2u; h > 0u; h >>= 1u) {
    if (lid < h) {
      s0[lid] += s0[lid + h];
      s1[lid] += s1[lid + h];
      s2[lid] += s2[lid + h];
      s3[lid] += s3[lid + h];
    }
    barrier();
  }
  if (lid != 0u) return;
  const uint at = kScalarCount * seg, mode = pc.mode;
  const real gammaNew = s0[0], rr = s1[0], delta = s3[0];
  if (mode == kReduceResidual) {
    scalars[at + kScalarRr] = rr;
    scalars[at + kScalarBb] = s2[0];
    return;
  }
  real bb = s2[0];
  if (mode == kReduceInit) {
    scalars[at + kScalarBb] = bb;
    scalars[at + kScalarIterations] = real(0);
  } else {
    bb = scalars[at + kScalarBb];
    scalars[at + kScalarIterations] += real(1);
  }
  bool breakdown = false;
  if (mode != kReduceLast) {
    real beta = real(0), pq = delta;
    if (mode == kReduceStep) {
      const real gamma = scalars[at + kScalarRho], alpha = scalars[at + kScalarAlpha];
      beta = gamma != real(0) ? gammaNew / gamma : real(0);
      pq = alpha != real(0) ? delta - beta * gammaNew / alpha : real(0);
    }
    scalars[at + kScalarBeta] = beta;
    scalars[at + kScalarPq] = pq;
    breakdown = !(pq > real(0));
    scalars[at + kScalarAlpha] = breakdown ? real(0) : gammaNew / pq;
    scalars[at + kScalarBreakdown] = breakdown ? real(1) : real(0);
  }
  scalars[at + kScalarRho] = gammaNew;
  scalars[at + kScalarRr] = rr;
  const real tol2 = scalars[at + kScalarTol2];
  const uint stop = (isnan(rr) || isinf(rr)) ? kStopNonFinite
                    : rr <= tol2 * bb        ? kStopConverged
                    : breakdown              ? kStopBreakdown
                                             : kStopRunning;
  scalars[at + kScalarStop] = real(stop);
  if (stop != kStopRunning) segInfo[kSegInfoCount * seg + kSegActive] = 0u;
}
