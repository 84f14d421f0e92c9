/* Device data layout of the OpenCL backend, shared by the host (C++) and the kernels (OpenCL C)
 * so that the two cannot drift. Everything per element is stored structure-of-arrays with a
 * padded stride S (a multiple of COROFEM_STRIDE_ALIGN >= element count): component k of element e
 * lives at k * S + e, so that consecutive work-items read consecutive addresses (coalesced on a
 * GPU, vectorised across work-items by PoCL on a CPU).
 *
 * Node vectors (positions, PCG vectors) are 3N reals, node-major (x0 y0 z0 x1 ...), exactly as on
 * the host.
 */
#ifndef COROFEM_LAYOUT_H
#define COROFEM_LAYOUT_H

/* ---------------------------------------------------------------- precision */
#ifdef __OPENCL_C_VERSION__
#ifdef COROFEM_DOUBLE
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
typedef double real;
typedef double3 real3;
typedef double4 real4;
#define REAL_EPS 2.220446049250313e-16
#define REAL_TINY 1e-280
#else
typedef float real;
typedef float3 real3;
typedef float4 real4;
#define REAL_EPS 1.1920929e-07f
#define REAL_TINY 1e-30f
#endif
/* sum_real: the type of the PCG dot products (per-item partials, their reduction) and of the PCG
 * scalars (rho, alpha, beta, norms). It is `real` except in mixed precision (COROFEM_MIXED, real =
 * float): there every term of a dot product is formed exactly (a float times a float fits a double)
 * and summed in double, so the rounding of the sum, ~ n eps_float |x||y| in float for n terms in
 * the worst case, drops to the float rounding of the vectors themselves. */
#if defined(COROFEM_MIXED) && !defined(COROFEM_DOUBLE)
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
typedef double sum_real;
#else
typedef real sum_real;
#endif
#define COROFEM_CONSTANT(type, name, value) enum { name = value }
/* Helper functions: `static inline`, so that no external definition is ever needed (C99 inline
 * semantics would leave an undefined symbol wherever a compiler declines to inline). */
#define COROFEM_FN static inline
#else
#define COROFEM_CONSTANT(type, name, value) static const type name = value
#endif

/* ---------------------------------------------------------------- per-element arrays (k * S + e) */
/* Node indices: corner c (0..3) at c * S + e.                                                    */
COROFEM_CONSTANT(unsigned, kElemNodeComponents, 4);
/* Rest geometry: shape-function gradients of corners 1..3 (grad N_0 = -(grad N_1 + grad N_2 +
 * grad N_3), the rows of the reference Grad43 sum to zero) and the rest volume.
 * grad N_i component k (i = 1..3) at (3 (i - 1) + k) * S + e, volume at 9 * S + e.               */
COROFEM_CONSTANT(unsigned, kGeomComponents, 10);
COROFEM_CONSTANT(unsigned, kGeomVolume, 9);
/* Rotation R (row-major, R(j,k) at (3 j + k) * S + e) and the rotated gradients a_i = R grad N_i
 * of corners 1..3 (a_i component k at (3 (i - 1) + k) * S + e). With a_i the co-rotational
 * element operators need no R at all (see element_force.cl).                                      */
COROFEM_CONSTANT(unsigned, kRotComponents, 9);
COROFEM_CONSTANT(unsigned, kRotGradComponents, 9);
/* Warm-start quaternion of the Quaternion rotation method (x, y, z, w) at k * S + e.             */
COROFEM_CONSTANT(unsigned, kQuatComponents, 4);
/* Stored element stiffness (stored-K_e variant): the upper triangle of the symmetric 12x12 K_e,
 * row by row (entry (r, c), c >= r, at index r * 12 - r (r - 1) / 2 + (c - r)), 78 components.   */
COROFEM_CONSTANT(unsigned, kStoredKComponents, 78);
/* Per-element output 12-vector (forces, products, preconditioner corner data), in blocks of
 * B = COROFEM_VEC elements so that a work-item writes whole vectors: component k of corner c of
 * element e at ((e / B) * 12 + 3 c + k) * B + e % B (B = 1 on GPUs: 12 contiguous per element).   */
COROFEM_CONSTANT(unsigned, kElemOutComponents, 12);

/* Node gather list (CSR over nodes, fixed order): entry = ((e / B) * 12 + 3 c) * B + e % B, the
 * x component of corner c of element e; y and z follow B and 2 B later.                          */

/* Per-node preconditioner input: symmetric 3x3 block sum of the rotated element stiffness blocks
 * sum_e R K_e,ii R^T (xx, yy, zz, xy, xz, yz) at 6 n + k.                                        */
COROFEM_CONSTANT(unsigned, kNodeBlockComponents, 6);
/* Per-node inverse preconditioner: 9 entries (row-major 3x3) for block diagonal, 3 for diagonal. */

/* ---------------------------------------------------------------- PCG scalars on the device (sum_real) */
COROFEM_CONSTANT(unsigned, kScalarRho, 0);      /* rho = r . z (current)               */
COROFEM_CONSTANT(unsigned, kScalarPq, 1);       /* p . A p                             */
COROFEM_CONSTANT(unsigned, kScalarAlpha, 2);    /* rho / (p . A p)                     */
COROFEM_CONSTANT(unsigned, kScalarBeta, 3);     /* rho_new / rho_old                   */
COROFEM_CONSTANT(unsigned, kScalarRr, 4);       /* r . r (free dofs)                   */
COROFEM_CONSTANT(unsigned, kScalarBb, 5);       /* b . b (free dofs)                   */
COROFEM_CONSTANT(unsigned, kScalarBreakdown, 6);/* 1 when p . A p <= 0 was met         */
COROFEM_CONSTANT(unsigned, kScalarCount, 8);

/* Modes of reduce_finish (which scalars the partial sums become). */
COROFEM_CONSTANT(unsigned, kReduceInit, 0);     /* partials (r.z, r.r, b.b) -> rho, rr, bb        */
COROFEM_CONSTANT(unsigned, kReduceAlpha, 1);    /* partial (p.Ap) -> pq, alpha = rho / pq         */
COROFEM_CONSTANT(unsigned, kReduceBeta, 2);     /* partials (r.z, r.r) -> beta = rho'/rho, rho, rr */
COROFEM_CONSTANT(unsigned, kPartialComponents, 3); /* partial sums per work-group: 3 sum_reals    */

/* Default work-group size (overridden by -DCOROFEM_WG). Reductions need a power of two. */
#ifndef COROFEM_WG
#define COROFEM_WG 64
#endif
COROFEM_CONSTANT(unsigned, kStrideAlign, 16);

#endif /* COROFEM_LAYOUT_H */
