/* Explicit SIMD width of the element kernels (OpenCL C only): each work-item processes
 * COROFEM_VEC consecutive elements with realv = real<VEC> vectors, loading the structure-of-arrays
 * element data with vloadN. CPU devices (PoCL) get 8: PoCL did not vectorise the scalar element
 * kernels across work-items (WG 1 and 64 ran equally fast), while explicit vectors compile straight
 * to AVX. GPUs get 1 (one element per work-item, coalesced by the SoA layout).
 * The element stride S is a multiple of 16, so a vector never leaves the arrays; lanes past the
 * element count read the zero padding (node 0, zero gradients and volume) and write zeros that the
 * node gather never reads. */
#ifndef COROFEM_VECTOR_H
#define COROFEM_VECTOR_H
#ifdef __OPENCL_C_VERSION__

#ifndef COROFEM_VEC
#define COROFEM_VEC 1
#endif

/* maskv: the result type of a vector comparison of realv (-1 = true per lane). */
#if COROFEM_VEC == 1
typedef real realv;
typedef uint uintv;
#define VLOAD(ptr) (*(ptr))
#define VSTORE(value, ptr) (*(ptr) = (value))
#elif COROFEM_VEC == 4
#ifdef COROFEM_DOUBLE
typedef double4 realv;
typedef long4 maskv;
#else
typedef float4 realv;
typedef int4 maskv;
#endif
typedef uint4 uintv;
#define VLOAD(ptr) vload4(0, (ptr))
#define VSTORE(value, ptr) vstore4((value), 0, (ptr))
#elif COROFEM_VEC == 8
#ifdef COROFEM_DOUBLE
typedef double8 realv;
typedef long8 maskv;
#else
typedef float8 realv;
typedef int8 maskv;
#endif
typedef uint8 uintv;
#define VLOAD(ptr) vload8(0, (ptr))
#define VSTORE(value, ptr) vstore8((value), 0, (ptr))
#elif COROFEM_VEC == 16
#ifdef COROFEM_DOUBLE
typedef double16 realv;
typedef long16 maskv;
#else
typedef float16 realv;
typedef int16 maskv;
#endif
typedef uint16 uintv;
#define VLOAD(ptr) vload16(0, (ptr))
#define VSTORE(value, ptr) vstore16((value), 0, (ptr))
#else
#error "COROFEM_VEC must be 1, 4, 8 or 16"
#endif

/* Node indices of VEC consecutive elements (one corner's stream of the SoA layout) as a vector.
 * COROFEM_GATHER forms the node's address in size_t (v + 3 idx) and then adds the component: in
 * 32-bit arithmetic (3 idx + c, which may wrap) the compiler recomputed and zero-extended every
 * address, two integer instructions per loaded real. */
#if COROFEM_VEC == 1
#define VLOAD_INDEX(ptr) (*(ptr))
#define COROFEM_GATHER(v, i, c) (((v) + 3 * (size_t)(i))[c])
#elif COROFEM_VEC == 4
#define VLOAD_INDEX(ptr) vload4(0, (ptr))
#define COROFEM_GATHER(v, i, c) \
  ((realv)(((v) + 3 * (size_t)(i).s0)[c], ((v) + 3 * (size_t)(i).s1)[c], ((v) + 3 * (size_t)(i).s2)[c], ((v) + 3 * (size_t)(i).s3)[c]))
#elif COROFEM_VEC == 8
#define VLOAD_INDEX(ptr) vload8(0, (ptr))
#define COROFEM_GATHER(v, i, c)                                                                        \
  ((realv)(((v) + 3 * (size_t)(i).s0)[c], ((v) + 3 * (size_t)(i).s1)[c], ((v) + 3 * (size_t)(i).s2)[c], ((v) + 3 * (size_t)(i).s3)[c], \
           ((v) + 3 * (size_t)(i).s4)[c], ((v) + 3 * (size_t)(i).s5)[c], ((v) + 3 * (size_t)(i).s6)[c], ((v) + 3 * (size_t)(i).s7)[c]))
#else
#define VLOAD_INDEX(ptr) vload16(0, (ptr))
#define COROFEM_GATHER(v, i, c)                                                                        \
  ((realv)(((v) + 3 * (size_t)(i).s0)[c], ((v) + 3 * (size_t)(i).s1)[c], ((v) + 3 * (size_t)(i).s2)[c], ((v) + 3 * (size_t)(i).s3)[c], \
           ((v) + 3 * (size_t)(i).s4)[c], ((v) + 3 * (size_t)(i).s5)[c], ((v) + 3 * (size_t)(i).s6)[c], ((v) + 3 * (size_t)(i).s7)[c], \
           ((v) + 3 * (size_t)(i).s8)[c], ((v) + 3 * (size_t)(i).s9)[c], ((v) + 3 * (size_t)(i).sa)[c], ((v) + 3 * (size_t)(i).sb)[c], \
           ((v) + 3 * (size_t)(i).sc)[c], ((v) + 3 * (size_t)(i).sd)[c], ((v) + 3 * (size_t)(i).se)[c], ((v) + 3 * (size_t)(i).sf)[c]))
#endif

/* Component `comp` of the node vector v (3N) at the VEC nodes idx: a gather, built as a vector
 * literal. (Writing the lanes to a private array and loading it as a vector, as this did first,
 * made PoCL keep the arrays on the stack and stall on store forwarding: the element kernels ran
 * 1.7x slower.) */
COROFEM_FN realv gather_node_component(__global const real* v, uintv idx, uint comp) {
  return COROFEM_GATHER(v, idx, comp);
}

/* Element output 12-vectors in blocks of COROFEM_VEC elements (corofem_layout.h): component k of
 * corner c of element e at ((e / VEC) * 12 + 3 c + k) * VEC + e % VEC. A work-item stores each
 * component of its VEC elements with one contiguous vector store; the gather finds the three
 * components of a corner VEC reals apart (one or two cache lines). */
COROFEM_FN void store_corner(__global real* out, uint e0, int c, realv x, realv y, realv z) {
  __global real* base = out + ((e0 / COROFEM_VEC) * 12 + 3 * c) * COROFEM_VEC;
  VSTORE(x, base);
  VSTORE(y, base + COROFEM_VEC);
  VSTORE(z, base + 2 * COROFEM_VEC);
}

/* The first element of this work-item of an element kernel and its segment (corofem_layout.h);
 * false when the work-item has nothing to do (inactive segment: the whole work-group; past the
 * segment's last element). */
COROFEM_FN bool element_items(__global const uint* elemSeg, __global const uint* segInfo, uint* e0, uint* s) {
  *s = element_segment(elemSeg);
  *e0 = get_global_id(0) * COROFEM_VEC;
  return seg_info(segInfo, *s, kSegActive) != 0u && *e0 < seg_info(segInfo, *s, kSegElemEnd);
}

/* Sum of the lanes in a fixed order (deterministic). */
COROFEM_FN real lane_sum(realv v) {
  real lanes[COROFEM_VEC];
  VSTORE(v, lanes);
  real s = (real)0;
  #pragma unroll
  for (int l = 0; l < COROFEM_VEC; ++l) s += lanes[l];
  return s;
}

#endif /* __OPENCL_C_VERSION__ */
#endif /* COROFEM_VECTOR_H */
