/* Small dense 3x3 helpers used by the element kernels. Scalar code on purpose: PoCL vectorises
 * across work-items, GPUs run one element per work-item; both prefer plain scalars to vector
 * shuffles. Matrices are row-major: m[3 * row + col]. */
#ifndef COROFEM_EMBEDDED
#include "../shared/corofem_layout.h"
#endif

typedef struct { real m[9]; } Mat3;

COROFEM_FN Mat3 mat3_identity(void) {
  Mat3 r;
  #pragma unroll
  for (int i = 0; i < 9; ++i) r.m[i] = (real)0;
  r.m[0] = r.m[4] = r.m[8] = (real)1;
  return r;
}

COROFEM_FN real mat3_det(const Mat3* a) {
  return a->m[0] * (a->m[4] * a->m[8] - a->m[5] * a->m[7]) -
         a->m[1] * (a->m[3] * a->m[8] - a->m[5] * a->m[6]) +
         a->m[2] * (a->m[3] * a->m[7] - a->m[4] * a->m[6]);
}

/* Cofactor matrix: cof(A) = det(A) A^-T, so A^-T = cof(A) / det(A) without a transpose. */
COROFEM_FN Mat3 mat3_cofactor(const Mat3* a) {
  Mat3 c;
  c.m[0] = a->m[4] * a->m[8] - a->m[5] * a->m[7];
  c.m[1] = a->m[5] * a->m[6] - a->m[3] * a->m[8];
  c.m[2] = a->m[3] * a->m[7] - a->m[4] * a->m[6];
  c.m[3] = a->m[2] * a->m[7] - a->m[1] * a->m[8];
  c.m[4] = a->m[0] * a->m[8] - a->m[2] * a->m[6];
  c.m[5] = a->m[1] * a->m[6] - a->m[0] * a->m[7];
  c.m[6] = a->m[1] * a->m[5] - a->m[2] * a->m[4];
  c.m[7] = a->m[2] * a->m[3] - a->m[0] * a->m[5];
  c.m[8] = a->m[0] * a->m[4] - a->m[1] * a->m[3];
  return c;
}

COROFEM_FN real mat3_norm2(const Mat3* a) {
  real s = (real)0;
  #pragma unroll
  for (int i = 0; i < 9; ++i) s += a->m[i] * a->m[i];
  return s;
}

/* C = A^T B */
COROFEM_FN Mat3 mat3_tmul(const Mat3* a, const Mat3* b) {
  Mat3 c;
  #pragma unroll
  for (int i = 0; i < 3; ++i)
    #pragma unroll
    for (int j = 0; j < 3; ++j)
      c.m[3 * i + j] = a->m[i] * b->m[j] + a->m[3 + i] * b->m[3 + j] + a->m[6 + i] * b->m[6 + j];
  return c;
}
