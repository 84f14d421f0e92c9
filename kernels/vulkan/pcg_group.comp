#version 450
/* Whole PCG iterations in one dispatch: work-group s runs up to pc.mode iterations of segment
 * (body) s, each the same phases as the path of one dispatch per phase (pcg.comp's update,
 * element.comp's product, gather.comp's product, reduce.comp's scalars; ops.glsl holds their code,
 * and the sums are formed in the same order), so the bits are the same; the phases meet at
 * work-group barriers instead of dispatch boundaries. A body that stops (converged, broken down,
 * non-finite) leaves the loop at once, as its inactive segment does on the other path. With
 * kFlagCapLast the last iteration is the cap's: no product after its update.
 * For bodies whose phases are too small to fill a device (a launch costs more than their work); the
 * host picks it by size (VulkanDevice). */
#define COROFEM_COHERENT coherent
#define PRODUCT_IN uvec
#define PRODUCT_OUT wvec
#include "common.glsl"
#include "ops.glsl"

shared uint stopped;

/* Makes every invocation's buffer writes visible to the work-group, and waits for them. */
void sync() {
  memoryBarrierBuffer();
  barrier();
}

void main() {
  const uint seg = gl_WorkGroupID.x, lid = gl_LocalInvocationID.x, S = pc.S;
  if (seg_info(seg, kSegActive) == 0u) return;  /* the whole work-group */
  const uint nodeBegin = seg_info(seg, kSegNodeBegin), nodeEnd = seg_info(seg, kSegNodeEnd);
  const uint elemBegin = seg_info(seg, kSegElemBegin), elemEnd = seg_info(seg, kSegElemEnd);
  const uint groupBegin = seg_info(seg, kSegPartialBegin), groups = seg_info(seg, kSegPartialCount);
  const real lambda = seg_coef(seg, kCoefProdLambda), mu = seg_coef(seg, kCoefProdMu);
  for (uint it = 0u; it < pc.mode; ++it) {
    const bool capLast = has_flag(kFlagCapLast) && it + 1u == pc.mode;
    /* p, s, x, r, u; partials (r . u, r . r, 0) per 64 nodes */
    const real alpha = scalars[kScalarCount * seg + kScalarAlpha], beta = scalars[kScalarCount * seg + kScalarBeta];
    for (uint g = 0u; g < groups; ++g) {
      const uint n = nodeBegin + WG * g + lid;
      real sums[2] = real[2](real(0), real(0));
      if (n < nodeEnd) pcg_update_node(n, alpha, beta, sums);
      s0[lid] = sums[0];
      s1[lid] = sums[1];
      s2[lid] = real(0);
      s3[lid] = real(0);
      tree4();
      if (lid == 0u) {
        partials[3u * (groupBegin + g)] = s0[0];
        partials[3u * (groupBegin + g) + 1u] = s1[0];
        partials[3u * (groupBegin + g) + 2u] = real(0);
      }
    }
    sync();
    if (!capLast) {
      /* w = A u (projected); partials u . w per 64 nodes */
      for (uint e = elemBegin + lid; e < elemEnd; e += WG) element_pass(e, S, lambda, mu, false);
      sync();
      for (uint g = 0u; g < groups; ++g) {
        const uint n = nodeBegin + WG * g + lid;
        s0[lid] = n < nodeEnd ? gather_product_node(n, seg) : real(0);
        s1[lid] = real(0);
        s2[lid] = real(0);
        s3[lid] = real(0);
        tree4();
        if (lid == 0u) {
          partialsW[3u * (groupBegin + g)] = s0[0];
          partialsW[3u * (groupBegin + g) + 1u] = real(0);
          partialsW[3u * (groupBegin + g) + 2u] = real(0);
        }
      }
      sync();
    }
    segment_sums(seg);
    if (lid == 0u)
      stopped = update_scalars(seg, capLast ? kReduceLast : kReduceStep, s0[0], s1[0], s2[0], s3[0]) != kStopRunning
                    ? 1u : 0u;
    sync();
    if (stopped != 0u) break;
  }
}
