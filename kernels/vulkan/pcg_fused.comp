#version 450
/* The node pass of a PCG iteration that ends it, one invocation per node, in two modes
 * (VulkanTuning::fusedPcg):
 *   kModeUpdateProduct  the iteration in two dispatches, for the preconditioners stored per node
 *                       (none, diagonal, 3x3 blocks): after element_fused.comp, whose
 *                       products take u at the corners as this pass stores it, pcg.comp's update
 *                       (p, s, x, r, u; ops.glsl's pcg_update_node) and gather.comp's product
 *                       w = A u (projected)
 *   kModeProduct        the iteration in three, with the multigrid: after pcg.comp's update (its
 *                       partials r . u, r . r written), the V-cycle and element.comp's product,
 *                       gather.comp's product alone
 * and then, in the segment's last work-group to finish, reduce.comp's kReduceStep. The same
 * operations on the same values as the four dispatches of the update, the product's two passes and
 * the scalars, the sums formed in the same order: the same bits.
 *
 * The last work-group: each work-group writes its partial sums, makes them visible (coherent
 * buffers, memoryBarrierBuffer) and counts itself in segInfo's kSegArrived; the one that counts
 * last sums the segment's partials in order, updates its scalars and resets the count to 0 (the
 * threadfence reduction of CUDA's samples, in GLSL's memory barriers: no work-group waits on
 * another). The host uploads the segment table with every count 0 at each solve's start. */
#define COROFEM_COHERENT_SUMS coherent
#define PRODUCT_IN uvec
#define PRODUCT_OUT wvec
#include "common.glsl"
#include "ops.glsl"

shared uint lastGroup;

const uint kModeUpdateProduct = 0u, kModeProduct = 1u;

void main() {
  const uint n = gl_GlobalInvocationID.x, lid = gl_LocalInvocationID.x, g = gl_WorkGroupID.x;
  const uint s = nodeSeg[g];
  if (seg_info(s, kSegActive) == 0u) return;  /* the whole work-group */
  const bool update = pc.mode == kModeUpdateProduct;
  real ru = real(0), rr = real(0), uw = real(0);
  if (n < seg_info(s, kSegNodeEnd)) {
    if (update) {
      real sums[2];
      pcg_update_node(n, scalars[kScalarCount * s + kScalarAlpha], scalars[kScalarCount * s + kScalarBeta], sums);
      ru = sums[0];
      rr = sums[1];
    }
    uw = gather_product_node(n, s);
  }
  s0[lid] = ru;
  s1[lid] = rr;
  s2[lid] = real(0);
  s3[lid] = uw;
  tree4();
  if (lid == 0u) {
    if (update) {
      partials[3u * g] = s0[0];
      partials[3u * g + 1u] = s1[0];
      partials[3u * g + 2u] = real(0);
    }
    partialsW[3u * g] = s3[0];
    partialsW[3u * g + 1u] = real(0);
    partialsW[3u * g + 2u] = real(0);
    memoryBarrierBuffer();
    const uint arrived = atomicAdd(segInfo[kSegInfoCount * s + kSegArrived], 1u);
    memoryBarrierBuffer();
    lastGroup = arrived + 1u == seg_info(s, kSegPartialCount) ? 1u : 0u;
  }
  barrier();
  if (lastGroup == 0u) return;
  memoryBarrierBuffer();
  segment_sums(s);
  if (lid == 0u) {
    update_scalars(s, kReduceStep, s0[0], s1[0], s2[0], s3[0]);
    segInfo[kSegInfoCount * s + kSegArrived] = 0u;
  }
}
