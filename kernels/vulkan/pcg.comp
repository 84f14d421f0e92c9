#version 450
/* The node passes of the single-reduction PCG (Chronopoulos-Gear; kernels/opencl/pcg.cl has the
 * derivation), one invocation per node, on the projected system (constrained dofs: identity rows and
 * columns, their entries of x, r, u, p, s kept at 0):
 *   kModeInit    M^-1 of the solve's coefficients per node (stored in minv), r = free (b - q) with
 *                q = A x in svec (kFlagZeroStart: x = 0, q not read), u = M^-1 r, p = s = 0;
 *                partials (r . u, r . r, b . b)
 *   kModeUpdate  p = u + beta p, s = w + beta s, x += alpha p, r -= alpha s, u = M^-1 r;
 *                partials (r . u, r . r, 0)
 * M^-1 (pc.precond): 0 the identity, 1 the inverse diagonal of A, 2 the inverse 3x3 node blocks of
 * A (massCoef M + k (blocks of R K R^T) + k S, constrained rows and columns replaced by the
 * identity; a non-positive pivot falls back to 1). */
#include "common.glsl"
#include "ops.glsl"

const uint kModeInit = 0u, kModeUpdate = 1u;

/* node_preconditioner of precond.cl, with the springs on the diagonal: the inverse of node n's
 * block into m (row-major 3x3; the diagonal preconditioner: the diagonal only). */
void node_inverse(uint n, uint s, out real m[9]) {
  const real massCoef = seg_coef(s, kCoefMass), stiff = seg_coef(s, kCoefStiff), springCoef = seg_coef(s, kCoefSpring);
  real f[3], d[3];
  for (uint k = 0u; k < 3u; ++k) {
    const uint dof = 3u * n + k;
    f[k] = freeDof[dof];
    d[k] = stiff * blocks[6u * n + k];
    if (has_flag(kFlagMass)) d[k] += massCoef * mass[dof];
    if (has_flag(kFlagSprings)) d[k] += springCoef * spring[dof];
  }
  for (int k = 0; k < 9; ++k) m[k] = real(0);
  if (pc.precond == 2u) {
    const real b01 = stiff * blocks[6u * n + 3u] * f[0] * f[1];
    const real b02 = stiff * blocks[6u * n + 4u] * f[0] * f[2];
    const real b12 = stiff * blocks[6u * n + 5u] * f[1] * f[2];
    real d0 = f[0] == real(0) ? real(1) : d[0];
    real d1 = f[1] == real(0) ? real(1) : d[1];
    real d2 = f[2] == real(0) ? real(1) : d[2];
    const real c00 = d1 * d2 - b12 * b12, c01 = b02 * b12 - b01 * d2, c02 = b01 * b12 - b02 * d1;
    const real c11 = d0 * d2 - b02 * b02, c12 = b01 * b02 - d0 * b12, c22 = d0 * d1 - b01 * b01;
    const real det = d0 * c00 + b01 * c01 + b02 * c02;
    if (det > real(0) && d0 > real(0) && d1 > real(0) && d2 > real(0)) {
      const real inv = real(1) / det;
      m[0] = c00 * inv * f[0];        m[1] = c01 * inv * f[0] * f[1]; m[2] = c02 * inv * f[0] * f[2];
      m[3] = c01 * inv * f[0] * f[1]; m[4] = c11 * inv * f[1];        m[5] = c12 * inv * f[1] * f[2];
      m[6] = c02 * inv * f[0] * f[2]; m[7] = c12 * inv * f[1] * f[2]; m[8] = c22 * inv * f[2];
      return;
    }
    d[0] = d0;
    d[1] = d1;
    d[2] = d2;
  }
  for (uint k = 0u; k < 3u; ++k) m[4u * k] = f[k] * (d[k] > real(0) ? real(1) / d[k] : real(1));
}

void main() {
  const uint n = gl_GlobalInvocationID.x, lid = gl_LocalInvocationID.x, g = gl_WorkGroupID.x;
  const uint s = nodeSeg[g];
  if (seg_info(s, kSegActive) == 0u) return;  /* the whole work-group */
  real ru = real(0), rr = real(0), bb = real(0);
  if (n < seg_info(s, kSegNodeEnd)) {
    if (pc.mode == kModeInit) {
      real m[9];
      if (pc.precond == 0u) {
        for (int k = 0; k < 9; ++k) m[k] = real(0);
        for (uint k = 0u; k < 3u; ++k) m[4u * k] = freeDof[3u * n + k];
      } else {
        node_inverse(n, s, m);
      }
      for (uint k = 0u; k < 9u; ++k) minv[9u * n + k] = m[k];
      real rn[3], un[3];
      for (uint k = 0u; k < 3u; ++k) {
        const uint d = 3u * n + k;
        const real bd = freeDof[d] * bvec[d];
        rn[k] = has_flag(kFlagZeroStart) ? bd : bd - freeDof[d] * svec[d];
        bb += bd * bd;
      }
      apply_inverse(m, rn, un);
      for (uint k = 0u; k < 3u; ++k) {
        const uint d = 3u * n + k;
        rvec[d] = rn[k];
        uvec[d] = un[k];
        pvec[d] = real(0);
        svec[d] = real(0);
        ru += rn[k] * un[k];
        rr += rn[k] * rn[k];
      }
    } else {
      real sums[2];
      pcg_update_node(n, scalars[kScalarCount * s + kScalarAlpha], scalars[kScalarCount * s + kScalarBeta], sums);
      ru = sums[0];
      rr = sums[1];
    }
  }
  s0[lid] = ru;
  s1[lid] = rr;
  s2[lid] = bb;
  s3[lid] = real(0);
  tree4();
  if (lid == 0u) {
    partials[3u * g] = s0[0];
    partials[3u * g + 1u] = s1[0];
    partials[3u * g + 2u] = s2[0];
  }
}
