#version 450
/* Per-element rotation R_e, the rotational part of F = D_s D_m^-1 (paper Sec. 3), one invocation
 * per element: the port of kernels/opencl/rotation.cl's GPU path (one element per work-item), with
 * the method chosen by pc.rotation:
 *   0 Polar       Higham's scaled Newton iteration, the SVD path for inverted, degenerate or
 *                 non-converging elements;
 *   1 Svd         Jacobi eigen-decomposition of F^T F, R = U V^T, the smallest singular direction
 *                 flipped when det F < 0 (the reference's convention: always a proper rotation);
 *   2 Quaternion  Mueller et al. 2016, warm-started from the quaternion kept per element;
 *   3 Qr          Gram-Schmidt of F's columns (equal to the polar factor only for pure rotations).
 * Writes the rotated gradients a_i = R grad N_i (i = 1..3), which the force, product and
 * preconditioner shaders use instead of R; R itself with kFlagWriteR; sqrt(V) a_c per corner into
 * elemOut with kFlagWriteCorners (the preconditioner's node blocks gather them). */
#include "common.glsl"

const int kPolarIters = 12;
const int kJacobiSweeps = 8;
const int kQuatIters = 6;

real det3(in real a[9]) {
  return a[0] * (a[4] * a[8] - a[5] * a[7]) - a[1] * (a[3] * a[8] - a[5] * a[6]) + a[2] * (a[3] * a[7] - a[4] * a[6]);
}

real norm2_3(in real a[9]) {
  real s = real(0);
  for (int i = 0; i < 9; ++i) s += a[i] * a[i];
  return s;
}

void identity3(out real r[9]) {
  for (int i = 0; i < 9; ++i) r[i] = real(0);
  r[0] = r[4] = r[8] = real(1);
}

/* One Jacobi rotation zeroing a_pq of the symmetric a: a <- J^T a J, v <- v J. */
void jacobi_rotate(inout real a[9], inout real v[9], int p, int q) {
  const real apq = a[3 * p + q];
  if (apq == real(0)) return;
  const real theta = (a[3 * q + q] - a[3 * p + p]) / (real(2) * apq);
  real t;
  if (abs(theta) > real(1e15))
    t = real(0.5) / theta;
  else
    t = (theta >= real(0) ? real(1) : real(-1)) / (abs(theta) + sqrt(theta * theta + real(1)));
  const real c = real(1) / sqrt(t * t + real(1)), s = t * c;
  for (int k = 0; k < 3; ++k) {
    const real akp = a[3 * k + p], akq = a[3 * k + q];
    a[3 * k + p] = c * akp - s * akq;
    a[3 * k + q] = s * akp + c * akq;
  }
  for (int k = 0; k < 3; ++k) {
    const real apk = a[3 * p + k], aqk = a[3 * q + k];
    a[3 * p + k] = c * apk - s * aqk;
    a[3 * q + k] = s * apk + c * aqk;
  }
  for (int k = 0; k < 3; ++k) {
    const real vkp = v[3 * k + p], vkq = v[3 * k + q];
    v[3 * k + p] = c * vkp - s * vkq;
    v[3 * k + q] = s * vkp + c * vkq;
  }
}

void swap_columns(inout real a[9], inout real v[9], int p, int q) {
  real t = a[3 * p + p];
  a[3 * p + p] = a[3 * q + q];
  a[3 * q + q] = t;
  for (int k = 0; k < 3; ++k) {
    t = v[3 * k + p];
    v[3 * k + p] = v[3 * k + q];
    v[3 * k + q] = t;
  }
}

/* F = U S V^T from F^T F = V S^2 V^T (cyclic Jacobi); R = U V^T with u_3 = u_1 x u_2 (rotation.cl's
 * rotation_svd: the same conventions for inverted, flat and collapsed elements). */
void rotation_svd(in real F[9], out real R[9]) {
  real a[9];
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) a[3 * i + j] = F[i] * F[j] + F[3 + i] * F[3 + j] + F[6 + i] * F[6 + j];
  real v[9] = real[9](real(1), real(0), real(0), real(0), real(1), real(0), real(0), real(0), real(1));
  const real scale2 = a[0] * a[0] + a[4] * a[4] + a[8] * a[8];
  for (int sweep = 0; sweep < kJacobiSweeps; ++sweep) {
    const real off = a[1] * a[1] + a[2] * a[2] + a[5] * a[5];
    if (!(off > REAL_EPS * REAL_EPS * scale2)) break;
    jacobi_rotate(a, v, 0, 1);
    jacobi_rotate(a, v, 0, 2);
    jacobi_rotate(a, v, 1, 2);
  }
  if (a[0] < a[4]) swap_columns(a, v, 0, 1);
  if (a[0] < a[8]) swap_columns(a, v, 0, 2);
  if (a[4] < a[8]) swap_columns(a, v, 1, 2);
  const real detV = v[0] * (v[4] * v[8] - v[5] * v[7]) - v[1] * (v[3] * v[8] - v[5] * v[6]) +
                    v[2] * (v[3] * v[7] - v[4] * v[6]);
  if (detV < real(0)) {
    v[2] = -v[2];
    v[5] = -v[5];
    v[8] = -v[8];
  }
  real u1[3], u2[3], u3[3];
  for (int j = 0; j < 3; ++j) {
    u1[j] = F[3 * j] * v[0] + F[3 * j + 1] * v[3] + F[3 * j + 2] * v[6];
    u2[j] = F[3 * j] * v[1] + F[3 * j + 1] * v[4] + F[3 * j + 2] * v[7];
  }
  const real fscale = sqrt(a[0] + a[4] + a[8]);
  const real n1 = sqrt(u1[0] * u1[0] + u1[1] * u1[1] + u1[2] * u1[2]);
  if (!(n1 > REAL_TINY + REAL_EPS * fscale)) {  /* collapsed to a point: no rotation to read off */
    identity3(R);
    return;
  }
  for (int j = 0; j < 3; ++j) u1[j] /= n1;
  const real d = u1[0] * u2[0] + u1[1] * u2[1] + u1[2] * u2[2];
  for (int j = 0; j < 3; ++j) u2[j] -= d * u1[j];
  real n2 = sqrt(u2[0] * u2[0] + u2[1] * u2[1] + u2[2] * u2[2]);
  if (!(n2 > real(16) * REAL_EPS * n1)) {  /* collapsed to a line: the axis least aligned with u_1 */
    int k = 0;
    if (abs(u1[1]) < abs(u1[k])) k = 1;
    if (abs(u1[2]) < abs(u1[k])) k = 2;
    for (int j = 0; j < 3; ++j) u2[j] = (j == k ? real(1) : real(0)) - u1[k] * u1[j];
    n2 = sqrt(u2[0] * u2[0] + u2[1] * u2[1] + u2[2] * u2[2]);
  }
  for (int j = 0; j < 3; ++j) u2[j] /= n2;
  u3[0] = u1[1] * u2[2] - u1[2] * u2[1];
  u3[1] = u1[2] * u2[0] - u1[0] * u2[2];
  u3[2] = u1[0] * u2[1] - u1[1] * u2[0];
  for (int j = 0; j < 3; ++j)
    for (int k = 0; k < 3; ++k) R[3 * j + k] = u1[j] * v[3 * k] + u2[j] * v[3 * k + 1] + u3[j] * v[3 * k + 2];
}

/* Higham's R <- (g R + R^-T / g) / 2 from R = F, g = (|R^-1|_F / |R|_F)^(1/2); stops when
 * |R_k+1 - R_k|_F < sqrt(3 eps). False where the SVD path must decide instead (an inverted or
 * degenerate element, or no convergence): main() calls rotation_svd then. Its one call site there
 * keeps one copy of it in the compiled shader (every function is inlined): five copies took a
 * CPU driver's compiler (lavapipe) about 0.4 s at every device's creation. */
bool rotation_polar(in real F[9], out real R[9]) {
  const real fn2 = norm2_3(F);
  const real detF = det3(F);
  if (!(detF > real(1e-3) * fn2 * sqrt(fn2) * real(1e-3))) return false;
  R = F;
  for (int it = 0; it < kPolarIters; ++it) {
    const real det = det3(R);
    real C[9];
    C[0] = R[4] * R[8] - R[5] * R[7];
    C[1] = R[5] * R[6] - R[3] * R[8];
    C[2] = R[3] * R[7] - R[4] * R[6];
    C[3] = R[2] * R[7] - R[1] * R[8];
    C[4] = R[0] * R[8] - R[2] * R[6];
    C[5] = R[1] * R[6] - R[0] * R[7];
    C[6] = R[1] * R[5] - R[2] * R[4];
    C[7] = R[2] * R[3] - R[0] * R[5];
    C[8] = R[0] * R[4] - R[1] * R[3];
    const real r2 = norm2_3(R), c2 = norm2_3(C);
    const real g = sqrt(sqrt(c2 / (det * det * r2)));
    const real hr = real(0.5) * g, hc = real(0.5) / (g * det);
    real diff2 = real(0);
    for (int k = 0; k < 9; ++k) {
      const real nk = hr * R[k] + hc * C[k];
      diff2 += (nk - R[k]) * (nk - R[k]);
      R[k] = nk;
    }
    if (diff2 < real(3) * REAL_EPS) return true;
  }
  return false;
}

void quat_to_matrix(in real q[4], out real R[9]) {
  const real x = q[0], y = q[1], z = q[2], w = q[3];
  R[0] = real(1) - real(2) * (y * y + z * z);
  R[1] = real(2) * (x * y - z * w);
  R[2] = real(2) * (x * z + y * w);
  R[3] = real(2) * (x * y + z * w);
  R[4] = real(1) - real(2) * (x * x + z * z);
  R[5] = real(2) * (y * z - x * w);
  R[6] = real(2) * (x * z - y * w);
  R[7] = real(2) * (y * z + x * w);
  R[8] = real(1) - real(2) * (x * x + y * y);
}

/* sin(h) and cos(h) in the shader's precision (GLSL has sin and cos in float only): h reduced to
 * [-pi, pi] (the step's angle is unbounded where F is inverted or flat: |tr R^T F| ~ 0), halved to
 * below 1/4, the Taylor series to h^17 there, doubled back up. Bounded for every finite h. */
void sin_cos(real h, out real sn, out real cs) {
  const real twoPi = real(6.283185307179586476925286766559);
  h -= twoPi * floor(h / twoPi + real(0.5));
  int halvings = 0;
  while (abs(h) > real(0.25) && halvings < 8) {
    h *= real(0.5);
    ++halvings;
  }
  const real h2 = h * h;
  real s = real(1), c = real(1);
  for (int k = 8; k >= 1; --k) {
    s = real(1) - h2 / real((2 * k) * (2 * k + 1)) * s;
    c = real(1) - h2 / real((2 * k - 1) * (2 * k)) * c;
  }
  s *= h;
  for (int k = 0; k < halvings; ++k) {
    const real s2 = real(2) * s * c;
    c = real(1) - real(2) * s * s;
    s = s2;
  }
  sn = s;
  cs = c;
}

/* omega = sum_i r_i x f_i / (|sum_i r_i . f_i| + 1e-9); q <- exp(omega) q (rotation.cl). */
void rotation_quaternion(in real F[9], inout real q[4], out real R[9]) {
  for (int it = 0; it < kQuatIters; ++it) {
    quat_to_matrix(q, R);
    real ox = real(0), oy = real(0), oz = real(0), dt = real(0);
    for (int c = 0; c < 3; ++c) {
      const real rx = R[c], ry = R[3 + c], rz = R[6 + c];
      const real fx = F[c], fy = F[3 + c], fz = F[6 + c];
      ox += ry * fz - rz * fy;
      oy += rz * fx - rx * fz;
      oz += rx * fy - ry * fx;
      dt += rx * fx + ry * fy + rz * fz;
    }
    const real inv = real(1) / (abs(dt) + real(1e-9));
    ox *= inv;
    oy *= inv;
    oz *= inv;
    const real w = sqrt(ox * ox + oy * oy + oz * oz);
    if (!(w > real(10) * REAL_EPS)) break;
    real sh, ch;
    sin_cos(real(0.5) * w, sh, ch);
    const real s = sh / w;
    const real dq[4] = real[4](s * ox, s * oy, s * oz, ch);
    real nq[4];
    nq[0] = dq[3] * q[0] + dq[0] * q[3] + dq[1] * q[2] - dq[2] * q[1];
    nq[1] = dq[3] * q[1] - dq[0] * q[2] + dq[1] * q[3] + dq[2] * q[0];
    nq[2] = dq[3] * q[2] + dq[0] * q[1] - dq[1] * q[0] + dq[2] * q[3];
    nq[3] = dq[3] * q[3] - dq[0] * q[0] - dq[1] * q[1] - dq[2] * q[2];
    const real nn = sqrt(nq[0] * nq[0] + nq[1] * nq[1] + nq[2] * nq[2] + nq[3] * nq[3]);
    for (int k = 0; k < 4; ++k) q[k] = nq[k] / nn;
  }
  quat_to_matrix(q, R);
}

/* Gram-Schmidt of F's first two columns, r_3 = r_1 x r_2; false for degenerate columns, which take
 * the SVD path (main()). */
bool rotation_qr(in real F[9], out real R[9]) {
  real r1[3] = real[3](F[0], F[3], F[6]);
  real r2[3] = real[3](F[1], F[4], F[7]);
  const real fn = sqrt(norm2_3(F));
  const real n1 = sqrt(r1[0] * r1[0] + r1[1] * r1[1] + r1[2] * r1[2]);
  if (!(n1 > real(1e-3) * fn)) return false;
  for (int j = 0; j < 3; ++j) r1[j] /= n1;
  const real d = r1[0] * r2[0] + r1[1] * r2[1] + r1[2] * r2[2];
  for (int j = 0; j < 3; ++j) r2[j] -= d * r1[j];
  const real n2 = sqrt(r2[0] * r2[0] + r2[1] * r2[1] + r2[2] * r2[2]);
  if (!(n2 > real(1e-3) * fn)) return false;
  for (int j = 0; j < 3; ++j) r2[j] /= n2;
  R[0] = r1[0];
  R[3] = r1[1];
  R[6] = r1[2];
  R[1] = r2[0];
  R[4] = r2[1];
  R[7] = r2[2];
  R[2] = r1[1] * r2[2] - r1[2] * r2[1];
  R[5] = r1[2] * r2[0] - r1[0] * r2[2];
  R[8] = r1[0] * r2[1] - r1[1] * r2[0];
  return true;
}

void main() {
  const uint e = gl_GlobalInvocationID.x, S = pc.S;
  const uint s = elemSeg[e / WG];
  if (seg_info(s, kSegActive) == 0u || e >= seg_info(s, kSegElemEnd)) return;
  /* F = sum_{i=1..3} (x_i - x_0) grad N_i^T (the differences keep float accurate far from the origin) */
  const uint n0 = corners[e];
  const real x0 = pos[3 * n0], y0 = pos[3 * n0 + 1], z0 = pos[3 * n0 + 2];
  real F[9];
  for (int k = 0; k < 9; ++k) F[k] = real(0);
  for (uint i = 1u; i < 4u; ++i) {
    const uint n = corners[i * S + e];
    const real d[3] = real[3](pos[3 * n] - x0, pos[3 * n + 1] - y0, pos[3 * n + 2] - z0);
    for (uint k = 0u; k < 3u; ++k) {
      const real g = geom[(3u * (i - 1u) + k) * S + e];
      for (int j = 0; j < 3; ++j) F[3 * j + k] += d[j] * g;
    }
  }
  real R[9];
  bool done = false;  /* false: the SVD path, once (Svd, and Polar's and Qr's fallbacks) */
  if (pc.rotation == 2u) {
    real q[4] = real[4](quat[e], quat[S + e], quat[2 * S + e], quat[3 * S + e]);
    rotation_quaternion(F, q, R);
    for (uint k = 0u; k < 4u; ++k) quat[k * S + e] = q[k];
    done = true;
  } else if (pc.rotation == 3u) {
    done = rotation_qr(F, R);
  } else if (pc.rotation != 1u) {
    done = rotation_polar(F, R);
  }
  if (!done) rotation_svd(F, R);
  if (has_flag(kFlagWriteR))
    for (uint k = 0u; k < 9u; ++k) rot[k * S + e] = R[k];
  real a[9];
  for (uint i = 0u; i < 3u; ++i) {
    const real g0 = geom[(3u * i) * S + e], g1 = geom[(3u * i + 1u) * S + e], g2 = geom[(3u * i + 2u) * S + e];
    for (uint j = 0u; j < 3u; ++j) {
      a[3 * i + j] = R[3 * j] * g0 + R[3 * j + 1] * g1 + R[3 * j + 2] * g2;
      rotGrad[(3u * i + j) * S + e] = a[3 * i + j];
    }
  }
  if (has_flag(kFlagWriteCorners)) {
    const real w = sqrt(geom[kGeomVolume * S + e]);
    for (uint k = 0u; k < 3u; ++k) elemOut[12u * e + k] = -w * (a[k] + a[3 + k] + a[6 + k]);
    for (uint c = 1u; c < 4u; ++c)
      for (uint k = 0u; k < 3u; ++k) elemOut[12u * e + 3u * c + k] = w * a[3 * (c - 1u) + k];
  }
}
