/* Per-element rotation R_e: the rotational part of the deformation gradient F = D_s D_m^-1, which
 * the simplified co-rotational formulation uses in Eq. 9 (forces) and Eq. 11 (K^R = R K R^T).
 * One work-item per element. The method is chosen at build time:
 *   COROFEM_ROT_POLAR  Higham's scaled Newton iteration for the polar factor, with a fallback to
 *                      the SVD path for inverted, degenerate or non-converging elements; on CPUs
 *                      (vector path) the Newton-Schulz iteration where F is near-orthogonal;
 *   COROFEM_ROT_SVD    Jacobi eigen-decomposition of F^T F, R = U V^T, smallest singular direction
 *                      flipped when det F < 0 (the reference's convention: always a proper rotation);
 *   COROFEM_ROT_QUAT   Mueller et al. 2016, "A robust method to extract the rotational part of
 *                      deformations", warm-started from the previous rotation kept as a quaternion;
 *   COROFEM_ROT_QR     Gram-Schmidt of F's columns (cheap edge frame; equals the polar factor only
 *                      for pure rotations: the error grows with the shear).
 * The kernel writes the rotated gradients a_i = R grad N_i (i = 1..3) that the force, product and
 * preconditioner kernels use instead of R (see element_force.cl), and, with writeCorners, the
 * per-corner a_c that node_stiffness_blocks gathers (the device-only benchmark pass; the host's
 * setPositions leaves the blocks to the solve, by corner_gradients, since the forces overwrite the
 * corners first). R itself only with writeR: no kernel reads it (the host asks for it when it
 * reads the rotations back, and the Quaternion method's passes write it always; 9 of the 30 reals
 * an element writes). Only the work-groups of active segments (bodies) run.
 * quat is NULL unless the method is COROFEM_ROT_QUAT.
 */
#ifndef COROFEM_EMBEDDED
#include "../shared/corofem_layout.h"
#include "../shared/corofem_vector.h"
#include "mat3.cl"
#endif

#ifndef COROFEM_POLAR_ITERS
#define COROFEM_POLAR_ITERS 12
#endif
#ifndef COROFEM_JACOBI_SWEEPS
#define COROFEM_JACOBI_SWEEPS 8
#endif
#ifndef COROFEM_QUAT_ITERS
#define COROFEM_QUAT_ITERS 6
#endif

/* F = sum_i x_i grad N_i^T = sum_{i=1..3} (x_i - x_0) grad N_i^T, since sum_i grad N_i = 0. The
 * differences keep float accurate for bodies far from the origin. */
COROFEM_FN Mat3 element_deformation_gradient(uint e, uint S, __global const uint* nodes,
                                         __global const real* geom, __global const real* pos) {
  const uint n0 = nodes[e];
  const real x0 = pos[3 * n0], y0 = pos[3 * n0 + 1], z0 = pos[3 * n0 + 2];
  Mat3 F;
  #pragma unroll
  for (int k = 0; k < 9; ++k) F.m[k] = (real)0;
  #pragma unroll
  for (int i = 1; i < 4; ++i) {
    const uint n = nodes[i * S + e];
    const real d[3] = {pos[3 * n] - x0, pos[3 * n + 1] - y0, pos[3 * n + 2] - z0};
    const real g[3] = {geom[(3 * (i - 1)) * S + e], geom[(3 * (i - 1) + 1) * S + e],
                       geom[(3 * (i - 1) + 2) * S + e]};
    #pragma unroll
    for (int j = 0; j < 3; ++j)
      #pragma unroll
      for (int k = 0; k < 3; ++k) F.m[3 * j + k] += d[j] * g[k];
  }
  return F;
}

/* ------------------------------------------------------------------ SVD via Jacobi on F^T F */

/* One Jacobi rotation J in the (p, q) plane zeroing a_pq of the symmetric A: A <- J^T A J,
 * V <- V J, with J_pp = J_qq = c, J_pq = s, J_qp = -s and t = s / c the smaller root of
 * t^2 + 2 theta t - 1 = 0, theta = (a_qq - a_pp) / (2 a_pq). */
COROFEM_FN void jacobi_rotate(real* a, real* v, int p, int q) {
  const real apq = a[3 * p + q];
  if (apq == (real)0) return;
  const real theta = (a[3 * q + q] - a[3 * p + p]) / (2 * apq);
  real t;
  if (fabs(theta) > (real)1e15)
    t = (real)0.5 / theta;
  else
    t = (theta >= (real)0 ? (real)1 : (real)-1) / (fabs(theta) + sqrt(theta * theta + (real)1));
  const real c = (real)1 / sqrt(t * t + (real)1), s = t * c;
  #pragma unroll
  for (int k = 0; k < 3; ++k) {
    const real akp = a[3 * k + p], akq = a[3 * k + q];
    a[3 * k + p] = c * akp - s * akq;
    a[3 * k + q] = s * akp + c * akq;
  }
  #pragma unroll
  for (int k = 0; k < 3; ++k) {
    const real apk = a[3 * p + k], aqk = a[3 * q + k];
    a[3 * p + k] = c * apk - s * aqk;
    a[3 * q + k] = s * apk + c * aqk;
  }
  #pragma unroll
  for (int k = 0; k < 3; ++k) {
    const real vkp = v[3 * k + p], vkq = v[3 * k + q];
    v[3 * k + p] = c * vkp - s * vkq;
    v[3 * k + q] = s * vkp + c * vkq;
  }
}

COROFEM_FN void swap_columns(real* a, real* v, int p, int q) {
  real t = a[3 * p + p];
  a[3 * p + p] = a[3 * q + q];
  a[3 * q + q] = t;
  #pragma unroll
  for (int k = 0; k < 3; ++k) {
    t = v[3 * k + p];
    v[3 * k + p] = v[3 * k + q];
    v[3 * k + q] = t;
  }
}

/* F = U S V^T from the eigen-decomposition F^T F = V S^2 V^T (cyclic Jacobi, quadratically
 * convergent), u_1 = F v_1 / |F v_1|, u_2 = F v_2 orthogonalised against u_1, u_3 = u_1 x u_2 and
 * V made proper (det V = +1). Then R = U V^T is the polar factor when det F > 0; when det F < 0
 * the true u_3 is -(u_1 x u_2), so using +(u_1 x u_2) flips the smallest singular direction:
 * R = U diag(1, 1, -1) V^T, exactly the reference's choice (detail::polarRotation). Flat or
 * collapsed elements (s_3 or s_2 ~ 0) still get an orthonormal U, so R stays a proper rotation. */
COROFEM_FN Mat3 rotation_svd(const Mat3* F) {
  real a[9];
  Mat3 FtF = mat3_tmul(F, F);
  #pragma unroll
  for (int k = 0; k < 9; ++k) a[k] = FtF.m[k];
  real v[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  const real scale2 = a[0] * a[0] + a[4] * a[4] + a[8] * a[8];
  for (int sweep = 0; sweep < COROFEM_JACOBI_SWEEPS; ++sweep) {
    const real off = a[1] * a[1] + a[2] * a[2] + a[5] * a[5];
    if (!(off > REAL_EPS * REAL_EPS * scale2)) break;
    jacobi_rotate(a, v, 0, 1);
    jacobi_rotate(a, v, 0, 2);
    jacobi_rotate(a, v, 1, 2);
  }
  /* Sort eigenvalues (squared singular values) descending, columns of V with them. */
  if (a[0] < a[4]) swap_columns(a, v, 0, 1);
  if (a[0] < a[8]) swap_columns(a, v, 0, 2);
  if (a[4] < a[8]) swap_columns(a, v, 1, 2);
  /* Proper V. */
  const real detV = v[0] * (v[4] * v[8] - v[5] * v[7]) - v[1] * (v[3] * v[8] - v[5] * v[6]) +
                    v[2] * (v[3] * v[7] - v[4] * v[6]);
  if (detV < (real)0) {
    v[2] = -v[2];
    v[5] = -v[5];
    v[8] = -v[8];
  }
  real u1[3], u2[3], u3[3];
  #pragma unroll
  for (int j = 0; j < 3; ++j) {
    u1[j] = F->m[3 * j] * v[0] + F->m[3 * j + 1] * v[3] + F->m[3 * j + 2] * v[6];
    u2[j] = F->m[3 * j] * v[1] + F->m[3 * j + 1] * v[4] + F->m[3 * j + 2] * v[7];
  }
  const real fscale = sqrt(a[0] + a[4] + a[8]);
  real n1 = sqrt(u1[0] * u1[0] + u1[1] * u1[1] + u1[2] * u1[2]);
  if (!(n1 > REAL_TINY + REAL_EPS * fscale)) {
    /* F ~ 0: the element collapsed to a point; no rotation can be read off. */
    return mat3_identity();
  }
  #pragma unroll
  for (int j = 0; j < 3; ++j) u1[j] /= n1;
  real d = u1[0] * u2[0] + u1[1] * u2[1] + u1[2] * u2[2];
  #pragma unroll
  for (int j = 0; j < 3; ++j) u2[j] -= d * u1[j];
  real n2 = sqrt(u2[0] * u2[0] + u2[1] * u2[1] + u2[2] * u2[2]);
  if (!(n2 > (real)16 * REAL_EPS * n1)) {
    /* Collapsed to a line: any unit vector normal to u_1 (the axis least aligned with u_1). */
    int k = 0;
    if (fabs(u1[1]) < fabs(u1[k])) k = 1;
    if (fabs(u1[2]) < fabs(u1[k])) k = 2;
    #pragma unroll
    for (int j = 0; j < 3; ++j) u2[j] = (j == k ? (real)1 : (real)0) - u1[k] * u1[j];
    n2 = sqrt(u2[0] * u2[0] + u2[1] * u2[1] + u2[2] * u2[2]);
  }
  #pragma unroll
  for (int j = 0; j < 3; ++j) u2[j] /= n2;
  u3[0] = u1[1] * u2[2] - u1[2] * u2[1];
  u3[1] = u1[2] * u2[0] - u1[0] * u2[2];
  u3[2] = u1[0] * u2[1] - u1[1] * u2[0];
  Mat3 R;
  #pragma unroll
  for (int j = 0; j < 3; ++j)
    #pragma unroll
    for (int k = 0; k < 3; ++k)
      R.m[3 * j + k] = u1[j] * v[3 * k] + u2[j] * v[3 * k + 1] + u3[j] * v[3 * k + 2];
  return R;
}

/* ------------------------------------------------------------------ polar: scaled Newton */

/* Higham's iteration R <- (g R + R^-T / g) / 2 from R = F, with the Frobenius-norm scaling
 * g = (|R^-1|_F / |R|_F)^(1/2) that makes the first steps fast for any stretch. It converges
 * quadratically to the orthogonal polar factor when det F > 0. Inverted (det F <= 0, where Newton
 * would converge to an improper factor), nearly singular or non-converged elements take the SVD
 * path, whose convention matches the reference. The stop test |R_k+1 - R_k|_F < sqrt(eps) leaves
 * an error ~ eps after the quadratic step already taken. */
COROFEM_FN Mat3 rotation_polar(const Mat3* F) {
  const real fn2 = mat3_norm2(F);
  const real detF = mat3_det(F);
  if (!(detF > (real)1e-3 * fn2 * sqrt(fn2) * (real)1e-3)) return rotation_svd(F);
  Mat3 R = *F;
  for (int it = 0; it < COROFEM_POLAR_ITERS; ++it) {
    const real det = mat3_det(&R);
    Mat3 C = mat3_cofactor(&R); /* R^-T = C / det */
    const real r2 = mat3_norm2(&R), c2 = mat3_norm2(&C);
    const real g = sqrt(sqrt(c2 / (det * det * r2)));
    const real hr = (real)0.5 * g, hc = (real)0.5 / (g * det);
    real diff2 = (real)0;
    #pragma unroll
    for (int k = 0; k < 9; ++k) {
      const real nk = hr * R.m[k] + hc * C.m[k];
      diff2 += (nk - R.m[k]) * (nk - R.m[k]);
      R.m[k] = nk;
    }
    if (diff2 < (real)3 * REAL_EPS) return R; /* |dR|_F < sqrt(3 eps), |R|_F = sqrt 3 */
  }
  return rotation_svd(F);
}

/* ------------------------------------------------------------------ quaternion (Mueller 2016) */

COROFEM_FN Mat3 quat_to_matrix(real4 q) {
  const real x = q.x, y = q.y, z = q.z, w = q.w;
  Mat3 R;
  R.m[0] = 1 - 2 * (y * y + z * z);
  R.m[1] = 2 * (x * y - z * w);
  R.m[2] = 2 * (x * z + y * w);
  R.m[3] = 2 * (x * y + z * w);
  R.m[4] = 1 - 2 * (x * x + z * z);
  R.m[5] = 2 * (y * z - x * w);
  R.m[6] = 2 * (x * z - y * w);
  R.m[7] = 2 * (y * z + x * w);
  R.m[8] = 1 - 2 * (x * x + y * y);
  return R;
}

/* omega = sum_i r_i x f_i / (|sum_i r_i . f_i| + tiny) (r_i, f_i the columns of R and F) is a
 * Newton-like step towards the rotation with R^T F symmetric; q <- exp(omega) q. Each step keeps q
 * a unit quaternion, so R is a proper rotation whatever F is (also inverted). Warm start: q is the
 * previous step's rotation, so a few iterations per step suffice. */
COROFEM_FN Mat3 rotation_quaternion(const Mat3* F, real4* qInOut) {
  real4 q = *qInOut;
  for (int it = 0; it < COROFEM_QUAT_ITERS; ++it) {
    const Mat3 R = quat_to_matrix(q);
    real ox = 0, oy = 0, oz = 0, dot = 0;
    #pragma unroll
    for (int c = 0; c < 3; ++c) {
      const real rx = R.m[c], ry = R.m[3 + c], rz = R.m[6 + c];
      const real fx = F->m[c], fy = F->m[3 + c], fz = F->m[6 + c];
      ox += ry * fz - rz * fy;
      oy += rz * fx - rx * fz;
      oz += rx * fy - ry * fx;
      dot += rx * fx + ry * fy + rz * fz;
    }
    const real inv = (real)1 / (fabs(dot) + (real)1e-9);
    ox *= inv;
    oy *= inv;
    oz *= inv;
    const real w = sqrt(ox * ox + oy * oy + oz * oz);
    if (!(w > (real)10 * REAL_EPS)) break;
    const real s = sin((real)0.5 * w) / w, c = cos((real)0.5 * w);
    const real4 dq = (real4)(s * ox, s * oy, s * oz, c);
    /* Hamilton product dq * q */
    real4 nq;
    nq.x = dq.w * q.x + dq.x * q.w + dq.y * q.z - dq.z * q.y;
    nq.y = dq.w * q.y - dq.x * q.z + dq.y * q.w + dq.z * q.x;
    nq.z = dq.w * q.z + dq.x * q.y - dq.y * q.x + dq.z * q.w;
    nq.w = dq.w * q.w - dq.x * q.x - dq.y * q.y - dq.z * q.z;
    q = nq / sqrt(nq.x * nq.x + nq.y * nq.y + nq.z * nq.z + nq.w * nq.w);
  }
  *qInOut = q;
  return quat_to_matrix(q);
}

/* ------------------------------------------------------------------ QR: edge frame */

/* Gram-Schmidt of F's columns f_1, f_2 (r_1 = f_1 / |f_1|, r_2 = normalised f_2 - (r_1 . f_2) r_1,
 * r_3 = r_1 x r_2): F = R T with T upper triangular. Proper by construction; equal to the polar
 * factor only when F is a rotation. Degenerate columns take the SVD path. */
COROFEM_FN Mat3 rotation_qr(const Mat3* F) {
  real r1[3] = {F->m[0], F->m[3], F->m[6]};
  real r2[3] = {F->m[1], F->m[4], F->m[7]};
  const real fn = sqrt(mat3_norm2(F));
  const real n1 = sqrt(r1[0] * r1[0] + r1[1] * r1[1] + r1[2] * r1[2]);
  if (!(n1 > (real)1e-3 * fn)) return rotation_svd(F);
  #pragma unroll
  for (int j = 0; j < 3; ++j) r1[j] /= n1;
  const real d = r1[0] * r2[0] + r1[1] * r2[1] + r1[2] * r2[2];
  #pragma unroll
  for (int j = 0; j < 3; ++j) r2[j] -= d * r1[j];
  const real n2 = sqrt(r2[0] * r2[0] + r2[1] * r2[1] + r2[2] * r2[2]);
  if (!(n2 > (real)1e-3 * fn)) return rotation_svd(F);
  #pragma unroll
  for (int j = 0; j < 3; ++j) r2[j] /= n2;
  Mat3 R;
  R.m[0] = r1[0];
  R.m[3] = r1[1];
  R.m[6] = r1[2];
  R.m[1] = r2[0];
  R.m[4] = r2[1];
  R.m[7] = r2[2];
  R.m[2] = r1[1] * r2[2] - r1[2] * r2[1];
  R.m[5] = r1[2] * r2[0] - r1[0] * r2[2];
  R.m[8] = r1[0] * r2[1] - r1[1] * r2[0];
  return R;
}

/* ------------------------------------------------------------------ vectorised polar */

#if COROFEM_VEC > 1
/* g = the symmetric R^T R of COROFEM_VEC matrices (row-major R): (0,0) (1,1) (2,2) (0,1) (0,2) (1,2). */
COROFEM_FN void polar_gram(const realv* R, realv* g) {
  g[0] = R[0] * R[0] + R[3] * R[3] + R[6] * R[6];
  g[1] = R[1] * R[1] + R[4] * R[4] + R[7] * R[7];
  g[2] = R[2] * R[2] + R[5] * R[5] + R[8] * R[8];
  g[3] = R[0] * R[1] + R[3] * R[4] + R[6] * R[7];
  g[4] = R[0] * R[2] + R[3] * R[5] + R[6] * R[8];
  g[5] = R[1] * R[2] + R[4] * R[5] + R[7] * R[8];
}

/* rotation_polar on COROFEM_VEC elements at once (the same iteration and stop test per lane; a
 * lane that has converged keeps its value). Returns the lanes that must take the SVD path:
 * inverted or degenerate (det F <= 1e-6 |F|^3) or not converged. */
COROFEM_FN maskv rotation_polar_v(const realv* F, realv* R) {
  realv fn2 = (realv)0;
  #pragma unroll
  for (int k = 0; k < 9; ++k) fn2 += F[k] * F[k];
  const realv detF = F[0] * (F[4] * F[8] - F[5] * F[7]) - F[1] * (F[3] * F[8] - F[5] * F[6]) +
                     F[2] * (F[3] * F[7] - F[4] * F[6]);
  const maskv bad = !(detF > (real)1e-6 * fn2 * sqrt(fn2));
  /* Near-orthogonal F, the small strains of most frames: every running lane with |F^T F - I|_F <= 1/2
   * (singular values in [0.70, 1.22]). There the Newton-Schulz iteration R <- R (3 I - R^T R) / 2
   * converges quadratically to the same polar factor (a singular value 1 + d becomes
   * 1 - 1.5 d^2 - 0.5 d^3) with multiplications only, where the scaled Newton below needs a
   * determinant, two roots and two divisions per step. Lanes bound for the SVD path iterate on R = I. */
  {
    realv g[6];  /* F^T F: (0,0) (1,1) (2,2) (0,1) (0,2) (1,2) */
    polar_gram(F, g);
    const realv e2 = (g[0] - (real)1) * (g[0] - (real)1) + (g[1] - (real)1) * (g[1] - (real)1) +
                     (g[2] - (real)1) * (g[2] - (real)1) + (real)2 * (g[3] * g[3] + g[4] * g[4] + g[5] * g[5]);
    if (all(bad | (e2 <= (real)0.25))) {
      #pragma unroll
      for (int k = 0; k < 9; ++k) R[k] = select(F[k], (k % 4 == 0) ? (realv)1 : (realv)0, bad);
      maskv converged = bad;
      for (int it = 0; it < COROFEM_POLAR_ITERS; ++it) {
        if (it > 0) polar_gram(R, g);
        /* H = (R^T R - I) / 2, R <- R - R H; |R^T R - I|_F^2 < 3 eps leaves an error ~ eps after this step */
        const realv h[6] = {(real)0.5 * (g[0] - (real)1), (real)0.5 * (g[1] - (real)1), (real)0.5 * (g[2] - (real)1),
                            (real)0.5 * g[3], (real)0.5 * g[4], (real)0.5 * g[5]};
        const realv err2 = (real)4 * (h[0] * h[0] + h[1] * h[1] + h[2] * h[2] +
                                      (real)2 * (h[3] * h[3] + h[4] * h[4] + h[5] * h[5]));
        #pragma unroll
        for (int j = 0; j < 3; ++j) {
          const realv r0 = R[3 * j], r1 = R[3 * j + 1], r2 = R[3 * j + 2];
          const realv n0 = r0 - (r0 * h[0] + r1 * h[3] + r2 * h[4]);
          const realv n1 = r1 - (r0 * h[3] + r1 * h[1] + r2 * h[5]);
          const realv n2 = r2 - (r0 * h[4] + r1 * h[5] + r2 * h[2]);
          R[3 * j] = select(n0, r0, converged);
          R[3 * j + 1] = select(n1, r1, converged);
          R[3 * j + 2] = select(n2, r2, converged);
        }
        converged = converged | (err2 < (real)3 * REAL_EPS);
        if (all(converged)) break;
      }
      return bad | !converged;
    }
  }
  maskv done = bad;
  #pragma unroll
  for (int k = 0; k < 9; ++k) R[k] = F[k];
  realv diffPrev2 = (realv)1; /* |R_k - R_k-1|_F^2 of the previous step */
  for (int it = 0; it < COROFEM_POLAR_ITERS; ++it) {
    realv C[9];
    C[0] = R[4] * R[8] - R[5] * R[7];
    C[1] = R[5] * R[6] - R[3] * R[8];
    C[2] = R[3] * R[7] - R[4] * R[6];
    C[3] = R[2] * R[7] - R[1] * R[8];
    C[4] = R[0] * R[8] - R[2] * R[6];
    C[5] = R[1] * R[6] - R[0] * R[7];
    C[6] = R[1] * R[5] - R[2] * R[4];
    C[7] = R[2] * R[3] - R[0] * R[5];
    C[8] = R[0] * R[4] - R[1] * R[3];
    const realv det = R[0] * C[0] + R[1] * C[1] + R[2] * C[2];
    /* Scaled while some running lane still takes large steps (relative step above 1e-2, as
     * Higham advises); near convergence g -> 1 anyway, and plain Newton saves its two roots and a
     * division (rotation_polar: 1.08x at 10k elements, no change at 100k; A/B on PoCL). */
    realv g = (realv)1;
    if (any(!done & (diffPrev2 > (real)3e-4))) {
      realv r2 = (realv)0, c2 = (realv)0;
      #pragma unroll
      for (int k = 0; k < 9; ++k) {
        r2 += R[k] * R[k];
        c2 += C[k] * C[k];
      }
      g = sqrt(sqrt(c2 / (det * det * r2)));
    }
    const realv hr = (real)0.5 * g, hc = (real)0.5 / (g * det);
    realv diff2 = (realv)0;
    #pragma unroll
    for (int k = 0; k < 9; ++k) {
      const realv nk = hr * R[k] + hc * C[k];
      diff2 += (nk - R[k]) * (nk - R[k]);
      R[k] = select(nk, R[k], done);
    }
    done = done | (diff2 < (real)3 * REAL_EPS);
    diffPrev2 = diff2;
    if (all(done)) break;
  }
  return bad | !done;
}
#endif

/* ------------------------------------------------------------------ corner data for the preconditioner */

/* sqrt(V) a_c (a_0 = -(a_1 + a_2 + a_3)) of the VEC elements e0.. in the element output layout
 * (store_corner), for node_stiffness_blocks (precond.cl): with the volume folded in, the node
 * gather there needs no per-element lookup of V. */
COROFEM_FN void store_corner_gradients(__global real* out, uint e0, const realv* a, realv volume) {
  const realv w = sqrt(volume);
  store_corner(out, e0, 0, -w * (a[0] + a[3] + a[6]), -w * (a[1] + a[4] + a[7]), -w * (a[2] + a[5] + a[8]));
  #pragma unroll
  for (int c = 1; c < 4; ++c)
    store_corner(out, e0, c, w * a[3 * (c - 1)], w * a[3 * (c - 1) + 1], w * a[3 * (c - 1) + 2]);
}

/* ------------------------------------------------------------------ the kernel */

COROFEM_FN Mat3 rotation_of(const Mat3* F, __global real* quat, uint e, uint S) {
#if defined(COROFEM_ROT_SVD)
  return rotation_svd(F);
#elif defined(COROFEM_ROT_QUAT)
  real4 q = (real4)(quat[e], quat[S + e], quat[2 * S + e], quat[3 * S + e]);
  const Mat3 R = rotation_quaternion(F, &q);
  quat[e] = q.x;
  quat[S + e] = q.y;
  quat[2 * S + e] = q.z;
  quat[3 * S + e] = q.w;
  return R;
#elif defined(COROFEM_ROT_QR)
  return rotation_qr(F);
#else
  return rotation_polar(F);
#endif
}

/* One work-item per COROFEM_VEC elements: F gathered with vector arithmetic, the rotation by the
 * chosen method (Polar: vectorised Newton with per-lane SVD fallback; the others lane by lane),
 * then R and a_i = R grad N_i written as vectors. Padding lanes (zero gradients, F = 0) get R = I
 * from the SVD path's collapsed-element rule and write only into the padding. */
__kernel __attribute__((reqd_work_group_size(COROFEM_WG, 1, 1)))
void compute_rotations(const uint S, __global const uint* restrict elemSeg, __global const uint* restrict segInfo,
                       __global const uint* restrict nodes, __global const real* restrict geom,
                       __global const real* restrict pos, __global real* restrict rot,
                       __global real* restrict rotGrad, __global real* restrict quat,
                       __global real* restrict corners, const uint writeCorners, const uint writeR) {
  uint e0, s;
  if (!element_items(elemSeg, segInfo, &e0, &s)) return;
#if COROFEM_VEC == 1
  const Mat3 F = element_deformation_gradient(e0, S, nodes, geom, pos);
  const Mat3 R = rotation_of(&F, quat, e0, S);
  if (writeR) {
    #pragma unroll
    for (int k = 0; k < 9; ++k) rot[k * S + e0] = R.m[k];
  }
  real a[9];
  #pragma unroll
  for (int i = 0; i < 3; ++i) {
    const real g0 = geom[(3 * i) * S + e0], g1 = geom[(3 * i + 1) * S + e0], g2 = geom[(3 * i + 2) * S + e0];
    #pragma unroll
    for (int j = 0; j < 3; ++j) {
      a[3 * i + j] = R.m[3 * j] * g0 + R.m[3 * j + 1] * g1 + R.m[3 * j + 2] * g2;
      rotGrad[(3 * i + j) * S + e0] = a[3 * i + j];
    }
  }
  if (writeCorners) store_corner_gradients(corners, e0, a, VLOAD(geom + kGeomVolume * S + e0));
#else
  /* F = sum_{i=1..3} (x_i - x_0) grad N_i^T, VEC elements at once */
  uintv idx[4];
  #pragma unroll
  for (int c = 0; c < 4; ++c) idx[c] = VLOAD_INDEX(nodes + c * S + e0);
  realv g[9], F[9], x0[3];
  #pragma unroll
  for (int k = 0; k < 9; ++k) {
    g[k] = VLOAD(geom + k * S + e0);
    F[k] = (realv)0;
  }
  #pragma unroll
  for (int j = 0; j < 3; ++j) x0[j] = gather_node_component(pos, idx[0], j);
  #pragma unroll
  for (int i = 1; i < 4; ++i)
    #pragma unroll
    for (int j = 0; j < 3; ++j) {
      const realv d = gather_node_component(pos, idx[i], j) - x0[j];
      #pragma unroll
      for (int k = 0; k < 3; ++k) F[3 * j + k] += d * g[3 * (i - 1) + k];
    }
  realv R[9];
#if defined(COROFEM_ROT_SVD) || defined(COROFEM_ROT_QUAT) || defined(COROFEM_ROT_QR)
  const maskv scalarLanes = (maskv)(-1);
#else
  const maskv scalarLanes = rotation_polar_v(F, R);
#endif
  if (any(scalarLanes)) {
    real lanesF[9][COROFEM_VEC], lanesR[9][COROFEM_VEC];
    int lanesScalar[COROFEM_VEC];
    #pragma unroll
    for (int k = 0; k < 9; ++k) {
      VSTORE(F[k], lanesF[k]);
#if defined(COROFEM_ROT_SVD) || defined(COROFEM_ROT_QUAT) || defined(COROFEM_ROT_QR)
      R[k] = (realv)0;
#endif
      VSTORE(R[k], lanesR[k]);
    }
    {
      maskv m = scalarLanes;
      real tmp[COROFEM_VEC];
      VSTORE(select((realv)0, (realv)1, m), tmp);
      #pragma unroll
      for (int l = 0; l < COROFEM_VEC; ++l) lanesScalar[l] = tmp[l] != (real)0;
    }
    for (int l = 0; l < COROFEM_VEC; ++l) {
      if (!lanesScalar[l]) continue;
      Mat3 Fl;
      #pragma unroll
      for (int k = 0; k < 9; ++k) Fl.m[k] = lanesF[k][l];
#if defined(COROFEM_ROT_SVD) || defined(COROFEM_ROT_QUAT) || defined(COROFEM_ROT_QR)
      const Mat3 Rl = rotation_of(&Fl, quat, e0 + l, S);
#else
      const Mat3 Rl = rotation_svd(&Fl);
#endif
      #pragma unroll
      for (int k = 0; k < 9; ++k) lanesR[k][l] = Rl.m[k];
    }
    #pragma unroll
    for (int k = 0; k < 9; ++k) R[k] = VLOAD(lanesR[k]);
  }
  if (writeR) {
    #pragma unroll
    for (int k = 0; k < 9; ++k) VSTORE(R[k], rot + k * S + e0);
  }
  realv a[9];
  #pragma unroll
  for (int i = 0; i < 3; ++i)
    #pragma unroll
    for (int j = 0; j < 3; ++j) {
      a[3 * i + j] = R[3 * j] * g[3 * i] + R[3 * j + 1] * g[3 * i + 1] + R[3 * j + 2] * g[3 * i + 2];
      VSTORE(a[3 * i + j], rotGrad + (3 * i + j) * S + e0);
    }
  if (writeCorners) store_corner_gradients(corners, e0, a, VLOAD(geom + kGeomVolume * S + e0));
#endif
}
