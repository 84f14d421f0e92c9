/* The PCG solves of packs of bodies with the same mesh, body l of a pack in vector lane l (CPU
 * devices: per-work-item partial sums, no COROFEM_TREE_REDUCE): the set-up's end (or, from a zero
 * start, the whole set-up from the node blocks on), pcg_iterate_group's iterations, the iteration
 * cap's last iteration and the true residual, each with the launched kernels' bits.
 *
 * pcg_iterate_group runs a body's element product on COROFEM_VEC elements per vector: every corner
 * of every element is a gather of VEC node values, and the gather to the nodes adds scalars. Where
 * several bodies share a mesh (a scene's copies of one object, each with its own material, rest
 * shape, mass, constraints and solve), element e of kPackLanes of them sits in one vector instead:
 * its corner nodes are one scalar index for all lanes, every load and store is a contiguous vector
 * (corofem_layout.h, "packs of bodies"), and the sums at the nodes add whole vectors. One
 * work-item runs a pack's solves until every lane has stopped or the launch's iterations are done
 * (then the cap's last and the residuals); the host copies the bodies' data in (pack_in) and their
 * vectors out (pack_out) around it.
 *
 * Same bits as pcg_iterate_group, lane by lane: each lane does the arithmetic of its body's work-
 * items in their order, written as the same expressions of element_force.cl, gather.cl and pcg.cl
 * (so that the compiler contracts the same products into fused multiply-adds), with the update's
 * partial sums in the order of pcg_update_nodes (the 4-wide vector branch's order for a whole chunk
 * where pcg_update_nodes takes it), the partials summed as segment_sums sums them (strided, then a
 * tree of COROFEM_WG), and the scalars by update_scalars itself; the set-up and the residual as
 * pcg_init, node_stiffness_blocks, node_preconditioner and gather_product_nodes form them. A lane that has stopped keeps its
 * vectors (the stores select the old value), as a stopped body's work-group does nothing.
 * tests/opencl/test_opencl_batch.cpp compares the two bit for bit.
 *
 * No `restrict`, as in pcg_group.cl. */
#ifndef COROFEM_EMBEDDED
#include "../../shared/corofem_layout.h"
#include "../../shared/corofem_reduce.h"
#include "../../shared/corofem_vector.h"
#include "../element_force.cl"
#include "../gather.cl"
#include "../pcg.cl"
#endif

#ifndef COROFEM_TREE_REDUCE
#define PACK_L 8 /* kPackLanes (the host checks that they agree) */
#ifdef COROFEM_DOUBLE
typedef double8 realp;
typedef long8 maskp;
#else
typedef float8 realp;
typedef int8 maskp;
#endif
#if defined(COROFEM_MIXED) && !defined(COROFEM_DOUBLE)
typedef double8 sump;
#define TO_SUMP(v) convert_double8(v)
#else
typedef realp sump;
#define TO_SUMP(v) (v)
#endif
/* A row of a pack array (global, at a multiple of PACK_L reals from the buffer's start, which
 * OpenCL aligns to at least the largest vector type): one aligned vector access. vload8/vstore8
 * compile to split stores there (PoCL: two 16-byte halves), and a 32-byte load of a node sum
 * just stored in halves waits for both instead of taking the stored value (store forwarding). */
#define LDP(ptr) (*(__global const realp*)(ptr))
#define STP(value, ptr) (*(__global realp*)(ptr) = (value))
/* 8 reals anywhere (private arrays, the bodies' own arrays). */
#define LDU(ptr) vload8(0, (ptr))
#define STU(value, ptr) vstore8((value), 0, (ptr))
/* Row r of a lane-interleaved array. */
#define ROW(base, r) ((base) + (size_t)(r) * PACK_L)
/* Node sum rows per node: the products' 3, or the node blocks' 6 of the block preconditioner when
 * a pack forms them (pack_fresh_setup); node n of a slot at PACK_SUMS (nodeBase + n). */
#ifdef COROFEM_PRECOND_BLOCK
#define PACK_SUMS 6
#else
#define PACK_SUMS 3
#endif
/* PCG vector v of a pack array of dofRows rows per vector: 0..6 = x r u p s w b. */
#define PACK_VEC(vec, dofRows, v) ((vec) + (size_t)(v) * (dofRows) * PACK_L)

/* A pack slot's extent (packInfo) and its lanes' segments (-1: no body). */
typedef struct {
  uint elems, nodes, partialCount, corners, elemBase, nodeBase, partialBase;
  int seg[PACK_L];
} PackSlot;

COROFEM_FN PackSlot pack_slot(__global const uint* packInfo, uint slot) {
  __global const uint* info = packInfo + kPackInfoCount * slot;
  PackSlot p;
  p.elems = info[kPackElems];
  p.nodes = info[kPackNodes];
  p.partialCount = info[kPackPartialCount];
  p.corners = info[kPackCorners];
  p.elemBase = info[kPackElemBase];
  p.nodeBase = info[kPackNodeBase];
  p.partialBase = info[kPackPartialBase];
  for (int l = 0; l < PACK_L; ++l) p.seg[l] = (int)info[kPackLane0 + l] - 1;
  return p;
}

/* Lane l = segment coefficient k of lane l's body (0 for an empty lane). */
COROFEM_FN realp lane_coef(const PackSlot* p, __global const real* segCoef, uint k) {
  real v[PACK_L];
  for (int l = 0; l < PACK_L; ++l) v[l] = p->seg[l] >= 0 ? seg_coef(segCoef, (uint)p->seg[l], k) : (real)0;
  return LDU(v);
}

/* Lane l = (real) scalar k of lane l's body. */
COROFEM_FN realp lane_scalar(const PackSlot* p, __global const sum_real* allScalars, uint k) {
  real v[PACK_L];
  for (int l = 0; l < PACK_L; ++l)
    v[l] = p->seg[l] >= 0 ? (real)allScalars[kScalarCount * (uint)p->seg[l] + k] : (real)0;
  return LDU(v);
}

/* -1 in the lanes whose body is still iterating (segInfo's flag, which update_scalars clears). */
COROFEM_FN maskp lane_running(const PackSlot* p, __global const uint* segInfo, int* any) {
  int v[PACK_L]; /* the mask's lane type: int, or long in double */
  *any = 0;
  for (int l = 0; l < PACK_L; ++l) {
    v[l] = p->seg[l] >= 0 && seg_info(segInfo, (uint)p->seg[l], kSegActive) != 0u ? -1 : 0;
    *any |= v[l];
  }
#ifdef COROFEM_DOUBLE
  return convert_long8(vload8(0, v));
#else
  return vload8(0, v);
#endif
}

/* The update of pcg_update_nodes for the nodes [first, last) of a pack, lane by lane; the sums of
 * r . u and r . r in its order (the 4-wide branch's for a whole chunk where it takes that branch). */
COROFEM_FN void pack_update_nodes(uint first, uint last, uint nodeBase, uint dofRows, realp alpha, realp beta,
                                  maskp run, __global real* vec, __global const real* minv, sump* sums) {
  __global real* X = vec;
  __global real* R = PACK_VEC(vec, dofRows, 1);
  __global real* U = PACK_VEC(vec, dofRows, 2);
  __global real* P = PACK_VEC(vec, dofRows, 3);
  __global real* S = PACK_VEC(vec, dofRows, 4);
  __global const real* W = PACK_VEC(vec, dofRows, 5);
  sump acc[4] = {(sump)0, (sump)0, (sump)0, (sump)0}, accR[4] = {(sump)0, (sump)0, (sump)0, (sump)0};
#if COROFEM_CHUNK == 4 && !defined(COROFEM_PRECOND_BLOCK)
  const bool four = last == first + 4;
#else
  const bool four = false;
#endif
  uint t = 0; /* the dof's place in the chunk: the 4-wide branch's lane t % 4 */
  for (uint n = first; n < last; ++n) {
    const size_t row = (size_t)3 * (nodeBase + n);
    realp rn[3], un[3], uo[3];
    #pragma unroll
    for (int k = 0; k < 3; ++k) {
      uo[k] = LDP(ROW(U, row + k));
      const realp po = LDP(ROW(P, row + k)), wo = LDP(ROW(W, row + k)), so = LDP(ROW(S, row + k)),
                  xo = LDP(ROW(X, row + k)), ro = LDP(ROW(R, row + k));
      const realp pd = uo[k] + beta * po, sd = wo + beta * so;
      STP(select(po, pd, run), ROW(P, row + k));
      STP(select(so, sd, run), ROW(S, row + k));
      STP(select(xo, xo + alpha * pd, run), ROW(X, row + k));
      rn[k] = ro - alpha * sd;
      STP(select(ro, rn[k], run), ROW(R, row + k));
    }
#if defined(COROFEM_PRECOND_BLOCK)
    realp m[9];
    #pragma unroll
    for (int k = 0; k < 9; ++k) m[k] = LDP(ROW(minv, (size_t)9 * (nodeBase + n) + k));
    un[0] = m[0] * rn[0] + m[1] * rn[1] + m[2] * rn[2];
    un[1] = m[3] * rn[0] + m[4] * rn[1] + m[5] * rn[2];
    un[2] = m[6] * rn[0] + m[7] * rn[1] + m[8] * rn[2];
#elif defined(COROFEM_PRECOND_DIAG)
    #pragma unroll
    for (int k = 0; k < 3; ++k) un[k] = LDP(ROW(minv, row + k)) * rn[k];
#else
    #pragma unroll
    for (int k = 0; k < 3; ++k) un[k] = rn[k];
#endif
    #pragma unroll
    for (int k = 0; k < 3; ++k) {
      STP(select(uo[k], un[k], run), ROW(U, row + k));
      const uint a = four ? t % 4 : 0;
      acc[a] += TO_SUMP(rn[k]) * TO_SUMP(un[k]);
      accR[a] += TO_SUMP(rn[k]) * TO_SUMP(rn[k]);
      ++t;
    }
  }
  if (four) {
    sums[0] = (acc[0] + acc[1]) + (acc[2] + acc[3]);
    sums[1] = (accR[0] + accR[1]) + (accR[2] + accR[3]);
  } else {
    sums[0] = acc[0];
    sums[1] = accR[0];
  }
}

/* Adds element e's 12-vector y to its corners' rows of the node sums (one row of 8 lanes each).
 * The elements come in order, which is the order of the gather lists (gather.cl): each node's sum
 * is then the gather's, 0 + y(first element) + y(next) ..., bit for bit. One work-item owns a
 * pack, so the adds do not race. */
COROFEM_FN void pack_add_corner(__global real* sums, size_t row, realp yx, realp yy, realp yz) {
  __global real* q = ROW(sums, row);
  STP(LDP(q) + yx, q);
  STP(LDP(q + PACK_L) + yy, q + PACK_L);
  STP(LDP(q + 2 * PACK_L) + yz, q + 2 * PACK_L);
}

/* element_product_items for element e of a pack: the same expressions on lanes of bodies, each
 * corner's part added to the node sums instead of stored for a gather (the element outputs of 8
 * lanes are 384 bytes an element, streamed out and back each iteration; the node sums stay in the
 * core's cache). */
COROFEM_FN __attribute__((always_inline)) void pack_product_element(uint e, const PackSlot* p, realp lambda, realp mu, uint dofRows,
                                     __global const uint* corners, __global const real* elem,
                                     __global const real* vec, uint in, __global real* sums) {
  __global const real* U = PACK_VEC(vec, dofRows, in); /* u, or x for the residual */
  __global const uint* c = corners + p->corners + 4 * e;
  const size_t n0 = (size_t)3 * (p->nodeBase + c[0]);
  __global const real* g = ROW(elem, (size_t)(p->elemBase + e) * kPackElemRows);
  realp a[9];
  #pragma unroll
  for (int k = 0; k < 9; ++k) a[k] = LDP(g + k * PACK_L);
  const realp V = LDP(g + 9 * PACK_L);
  /* corner_outer_sum */
  realp v0[3], P[9];
  #pragma unroll
  for (int j = 0; j < 3; ++j) v0[j] = LDP(ROW(U, n0 + j));
  #pragma unroll
  for (int k = 0; k < 9; ++k) P[k] = (realp)0;
  #pragma unroll
  for (int i = 1; i < 4; ++i) {
    const size_t ni = (size_t)3 * (p->nodeBase + c[i]);
    #pragma unroll
    for (int j = 0; j < 3; ++j) {
      const realp d = LDP(ROW(U, ni + j)) - v0[j];
      #pragma unroll
      for (int k = 0; k < 3; ++k) P[3 * j + k] += d * a[3 * (i - 1) + k];
    }
  }
  /* write_stress_times_gradients with shift 0 */
  const real shift = (real)0;
  const realp exx = P[0] - shift, eyy = P[4] - shift, ezz = P[8] - shift;
  const realp exy = (real)0.5 * (P[1] + P[3]);
  const realp exz = (real)0.5 * (P[2] + P[6]);
  const realp eyz = (real)0.5 * (P[5] + P[7]);
  const realp lt = lambda * (exx + eyy + ezz);
  const realp m2 = 2 * mu;
  const realp sxx = V * (lt + m2 * exx), syy = V * (lt + m2 * eyy), szz = V * (lt + m2 * ezz);
  const realp sxy = V * (m2 * exy), sxz = V * (m2 * exz), syz = V * (m2 * eyz);
  realp y0x = (realp)0, y0y = (realp)0, y0z = (realp)0;
  #pragma unroll
  for (int i = 0; i < 3; ++i) {
    const realp ax = a[3 * i], ay = a[3 * i + 1], az = a[3 * i + 2];
    const realp yx = sxx * ax + sxy * ay + sxz * az;
    const realp yy = sxy * ax + syy * ay + syz * az;
    const realp yz = sxz * ax + syz * ay + szz * az;
    pack_add_corner(sums, PACK_SUMS * (size_t)(p->nodeBase + c[i + 1]), yx, yy, yz);
    y0x -= yx;
    y0y -= yy;
    y0z -= yz;
  }
  pack_add_corner(sums, PACK_SUMS * (size_t)(p->nodeBase + c[0]), y0x, y0y, y0z);
}

/* Rows [row, row + count) of the node sums into acc, left at zero for the next sums. */
COROFEM_FN void pack_take_sums(__global real* sums, size_t row, int count, realp* acc) {
  for (int k = 0; k < count; ++k) {
    acc[k] = LDP(ROW(sums, row + k));
    STP((realp)0, ROW(sums, row + k));
  }
}

/* gather_product_nodes (projected, no right-hand side) for the nodes [first, last) of a pack, on
 * the node sums the element products made (left at zero for the next product): w = A u and the
 * sum of u . w, lane by lane. */
COROFEM_FN sump pack_finish_nodes(uint first, uint last, const PackSlot* p, realp massCoef, maskp run, uint dofRows,
                                  __global real* sums, __global const real* mass, __global const real* free,
                                  __global real* vec) {
  __global const real* U = PACK_VEC(vec, dofRows, 2);
  __global real* W = PACK_VEC(vec, dofRows, 5);
  sump dot = (sump)0;
  for (uint n = first; n < last; ++n) {
    const size_t row = (size_t)3 * (p->nodeBase + n);
    realp acc[3];
    pack_take_sums(sums, PACK_SUMS * (size_t)(p->nodeBase + n), 3, acc);
    #pragma unroll
    for (int k = 0; k < 3; ++k) {
      const realp pd = LDP(ROW(U, row + k));
      /* product_entry with project = 1 */
      const realp yd0 = (mass ? massCoef * LDP(ROW(mass, row + k)) * pd : (realp)0) + acc[k];
      const realp yd = yd0 * LDP(ROW(free, row + k));
      STP(select(LDP(ROW(W, row + k)), yd, run), ROW(W, row + k));
      dot += TO_SUMP(pd) * TO_SUMP(yd);
    }
  }
  return dot;
}

/* segment_sums of the pack's partial triples (r . u, r . r, u . w) in place: strided over
 * COROFEM_WG lanes, then the tree; the sums end in row 0. */
COROFEM_FN void pack_segment_sums(__global sump* rows, uint count) {
  /* rows[3 g + c]: component c of partial g */
  for (uint g0 = 0; g0 < COROFEM_WG; ++g0) {
    sump a = (sump)0, b = (sump)0, d = (sump)0;
    for (uint g = g0; g < count; g += COROFEM_WG) {
      a += rows[3 * g];
      b += rows[3 * g + 1];
      d += rows[3 * g + 2];
    }
    rows[3 * g0] = a;
    rows[3 * g0 + 1] = b;
    rows[3 * g0 + 2] = d;
  }
  for (uint s = COROFEM_WG / 2; s > 0; s >>= 1)
    for (uint i = 0; i < s; ++i) {
      rows[3 * i] += rows[3 * (i + s)];
      rows[3 * i + 1] += rows[3 * (i + s) + 1];
      rows[3 * i + 2] += rows[3 * (i + s) + 2];
    }
}

/* The product w = A u (pack_product_element, pack_finish_nodes) with the sums of u . w by chunk v
 * in rows[3 v + c] (the triples' other two components left as they are). */
COROFEM_FN void pack_product(const PackSlot* p, realp lambda, realp mu, realp massCoef, maskp run, uint dofRows,
                             __global const uint* corners, __global const real* elem, __global real* sums,
                             __global real* vec, __global const real* mass, __global const real* free,
                             __global sump* rows, uint c) {
  for (uint e = 0; e < p->elems; ++e) pack_product_element(e, p, lambda, mu, dofRows, corners, elem, vec, 2, sums);
  for (uint v = 0; v < p->partialCount; ++v) {
    const uint first = v * COROFEM_CHUNK, last = min(first + (uint)COROFEM_CHUNK, p->nodes);
    rows[3 * v + c] = pack_finish_nodes(first, max(first, last), p, massCoef, run, dofRows, sums, mass, free, vec);
  }
}

/* The true residual after the solve, for the nodes [first, last) of a pack on the node sums of
 * A x (left at zero): r = free b - A x as gather_product_nodes forms it with a right-hand side, in
 * the lanes of `present`, and the sums r . r, |free b|^2 into sums[0], sums[1]. */
COROFEM_FN void pack_residual_nodes(uint first, uint last, const PackSlot* p, realp massCoef, maskp present,
                                    uint dofRows, __global real* nodeSums, __global const real* mass,
                                    __global const real* free, __global real* vec, sump* sums) {
  __global const real* X = vec;
  __global real* R = PACK_VEC(vec, dofRows, 1);
  __global const real* B = PACK_VEC(vec, dofRows, 6);
  sump rr = (sump)0, bb = (sump)0;
  for (uint n = first; n < last; ++n) {
    const size_t row = (size_t)3 * (p->nodeBase + n);
    realp acc[3];
    pack_take_sums(nodeSums, PACK_SUMS * (size_t)(p->nodeBase + n), 3, acc);
    #pragma unroll
    for (int k = 0; k < 3; ++k) {
      const realp fd = LDP(ROW(free, row + k));
      /* product_entry with project = 1 on p = x, then the right-hand side's branch */
      const realp yd0 = (mass ? massCoef * LDP(ROW(mass, row + k)) * LDP(ROW(X, row + k)) : (realp)0) + acc[k];
      const realp yd = yd0 * fd;
      const realp bd = fd * LDP(ROW(B, row + k)), rd = bd - yd;
      STP(select(LDP(ROW(R, row + k)), rd, present), ROW(R, row + k));
      bb += TO_SUMP(bd) * TO_SUMP(bd);
      rr += TO_SUMP(rd) * TO_SUMP(rd);
    }
  }
  sums[0] = rr;
  sums[1] = bb;
}

#if defined(COROFEM_PRECOND_BLOCK) || defined(COROFEM_PRECOND_DIAG)
/* node_stiffness_blocks on a pack, element e's part: the corners sqrt(V) a_c as
 * store_corner_gradients forms them from the a_i, and V ((lambda + mu) a_c a_c^T + mu |a_c|^2 I) of
 * each added to its node's block rows of the node sums. The elements come in order, the order of
 * the gather lists that node_stiffness_blocks sums in: the same blocks, bit for bit. */
COROFEM_FN void pack_block_element(uint e, const PackSlot* p, realp lm, realp mu, __global const uint* corners,
                                   __global const real* elem, __global real* sums) {
  __global const uint* c = corners + p->corners + 4 * e;
  __global const real* g = ROW(elem, (size_t)(p->elemBase + e) * kPackElemRows);
  realp a[9];
  #pragma unroll
  for (int k = 0; k < 9; ++k) a[k] = LDP(g + k * PACK_L);
  const realp w = sqrt(LDP(g + 9 * PACK_L));
  realp corner[4][3];
  #pragma unroll
  for (int k = 0; k < 3; ++k) corner[0][k] = -w * (a[k] + a[3 + k] + a[6 + k]);
  #pragma unroll
  for (int i = 1; i < 4; ++i)
    #pragma unroll
    for (int k = 0; k < 3; ++k) corner[i][k] = w * a[3 * (i - 1) + k];
  #pragma unroll
  for (int i = 0; i < 4; ++i) {
    __global real* q = ROW(sums, PACK_SUMS * (size_t)(p->nodeBase + c[i]));
    const realp ax = corner[i][0], ay = corner[i][1], az = corner[i][2];
    const realp iso = mu * (ax * ax + ay * ay + az * az);
    STP(LDP(q) + (lm * ax * ax + iso), q);
    STP(LDP(q + PACK_L) + (lm * ay * ay + iso), q + PACK_L);
    STP(LDP(q + 2 * PACK_L) + (lm * az * az + iso), q + 2 * PACK_L);
#ifdef COROFEM_PRECOND_BLOCK
    STP(LDP(q + 3 * PACK_L) + lm * ax * ay, q + 3 * PACK_L);
    STP(LDP(q + 4 * PACK_L) + lm * ax * az, q + 4 * PACK_L);
    STP(LDP(q + 5 * PACK_L) + lm * ay * az, q + 5 * PACK_L);
#endif
  }
}

/* node_preconditioner (precond.cl) on lanes: the node's block b (PACK_SUMS rows) with the solve's
 * coefficients, inverted into m, its branches as selects (the same arithmetic in every lane). */
COROFEM_FN void pack_node_preconditioner(const realp* b, realp massCoef, realp stiffCoef, const realp* mv,
                                         const realp* f, realp* m) {
  const realp one = (realp)1, zero = (realp)0;
  realp d0 = stiffCoef * b[0] + massCoef * mv[0];
  realp d1 = stiffCoef * b[1] + massCoef * mv[1];
  realp d2 = stiffCoef * b[2] + massCoef * mv[2];
#ifdef COROFEM_PRECOND_BLOCK
  const realp f0 = f[0], f1 = f[1], f2 = f[2];
  const realp b01 = stiffCoef * b[3] * f0 * f1;
  const realp b02 = stiffCoef * b[4] * f0 * f2;
  const realp b12 = stiffCoef * b[5] * f1 * f2;
  d0 = select(d0, one, f0 == zero);
  d1 = select(d1, one, f1 == zero);
  d2 = select(d2, one, f2 == zero);
  const realp c00 = d1 * d2 - b12 * b12, c01 = b02 * b12 - b01 * d2, c02 = b01 * b12 - b02 * d1;
  const realp c11 = d0 * d2 - b02 * b02, c12 = b01 * b02 - d0 * b12, c22 = d0 * d1 - b01 * b01;
  const realp det = d0 * c00 + b01 * c01 + b02 * c02;
  const maskp good = det > zero && d0 > zero && d1 > zero && d2 > zero;
  const realp inv = one / det;
  const realp e0 = f0 * select(one, one / d0, d0 > zero), e1 = f1 * select(one, one / d1, d1 > zero),
              e2 = f2 * select(one, one / d2, d2 > zero);
  m[0] = select(e0, c00 * inv * f0, good);
  m[1] = select(zero, c01 * inv * f0 * f1, good);
  m[2] = select(zero, c02 * inv * f0 * f2, good);
  m[3] = select(zero, c01 * inv * f0 * f1, good);
  m[4] = select(e1, c11 * inv * f1, good);
  m[5] = select(zero, c12 * inv * f1 * f2, good);
  m[6] = select(zero, c02 * inv * f0 * f2, good);
  m[7] = select(zero, c12 * inv * f1 * f2, good);
  m[8] = select(e2, c22 * inv * f2, good);
#else
  m[0] = f[0] * select(one, one / d0, d0 > zero);
  m[1] = f[1] * select(one, one / d1, d1 > zero);
  m[2] = f[2] * select(one, one / d2, d2 > zero);
#endif
}
#endif

/* The PCG set-up of the bodies of a pack from their right-hand sides with x = 0 (the host's zero
 * start), as the launched set-up forms it: the node blocks (node_stiffness_blocks, for a
 * preconditioner), then pcg_init by chunk: M^-1 (node_preconditioner, into minv), r = free b,
 * u = M^-1 r, p = s = 0, and the partials r . u, r . r, |free b|^2 into rows. The lanes of no body
 * compute on zeros. */
COROFEM_FN void pack_fresh_setup(const PackSlot* p, realp lm, realp muMat, realp massCoef, realp stiffCoef,
                                 uint dofRows, __global const uint* corners, __global const real* elem,
                                 __global real* sums, __global real* vec, __global const real* mass,
                                 __global const real* free, __global real* minv, __global sump* rows) {
  __global real* R = PACK_VEC(vec, dofRows, 1);
  __global real* U = PACK_VEC(vec, dofRows, 2);
  __global real* P = PACK_VEC(vec, dofRows, 3);
  __global real* S = PACK_VEC(vec, dofRows, 4);
  __global const real* B = PACK_VEC(vec, dofRows, 6);
#if defined(COROFEM_PRECOND_BLOCK) || defined(COROFEM_PRECOND_DIAG)
  for (uint e = 0; e < p->elems; ++e) pack_block_element(e, p, lm, muMat, corners, elem, sums);
#endif
  for (uint v = 0; v < p->partialCount; ++v) {
    const uint first = v * COROFEM_CHUNK, last = min(first + (uint)COROFEM_CHUNK, p->nodes);
    sump ru = (sump)0, rr = (sump)0, bb = (sump)0;
    for (uint n = first; n < last; ++n) {
      const size_t row = (size_t)3 * (p->nodeBase + n);
      realp rn[3], un[3], f[3];
      #pragma unroll
      for (int k = 0; k < 3; ++k) f[k] = LDP(ROW(free, row + k));
#if defined(COROFEM_PRECOND_BLOCK) || defined(COROFEM_PRECOND_DIAG)
      realp b[PACK_SUMS], mv[3], m[COROFEM_NODE_INVERSE];
      pack_take_sums(sums, PACK_SUMS * (size_t)(p->nodeBase + n), PACK_SUMS, b);
      #pragma unroll
      for (int k = 0; k < 3; ++k) mv[k] = mass ? LDP(ROW(mass, row + k)) : (realp)0;
      pack_node_preconditioner(b, massCoef, stiffCoef, mv, f, m);
      #pragma unroll
      for (int k = 0; k < COROFEM_NODE_INVERSE; ++k) STP(m[k], ROW(minv, (size_t)COROFEM_NODE_INVERSE * (p->nodeBase + n) + k));
#endif
      #pragma unroll
      for (int k = 0; k < 3; ++k) {
        const realp bd = f[k] * LDP(ROW(B, row + k));
        rn[k] = bd;
        bb += TO_SUMP(bd) * TO_SUMP(bd);
      }
      /* apply_node_inverse */
#if defined(COROFEM_PRECOND_BLOCK)
      un[0] = m[0] * rn[0] + m[1] * rn[1] + m[2] * rn[2];
      un[1] = m[3] * rn[0] + m[4] * rn[1] + m[5] * rn[2];
      un[2] = m[6] * rn[0] + m[7] * rn[1] + m[8] * rn[2];
#elif defined(COROFEM_PRECOND_DIAG)
      un[0] = m[0] * rn[0];
      un[1] = m[1] * rn[1];
      un[2] = m[2] * rn[2];
#else
      un[0] = rn[0];
      un[1] = rn[1];
      un[2] = rn[2];
#endif
      #pragma unroll
      for (int k = 0; k < 3; ++k) {
        STP(rn[k], ROW(R, row + k));
        STP(un[k], ROW(U, row + k));
        STP((realp)0, ROW(P, row + k));
        STP((realp)0, ROW(S, row + k));
        ru += TO_SUMP(rn[k]) * TO_SUMP(un[k]);
        rr += TO_SUMP(rn[k]) * TO_SUMP(rn[k]);
      }
    }
    rows[3 * v] = ru;
    rows[3 * v + 1] = rr;
    rows[3 * v + 2] = bb;
  }
}

/* The end of the PCG set-up for the bodies of a pack, after pcg_init ran on their own vectors (and
 * pack_in copied them): w = A u, then reduce_finish(kReduceInit)'s sums and scalars, lane by lane:
 * r . u, r . r and b . b from pcg_init's partials (`initPartials`, each lane's segment's, in the
 * layout of the bodies' partials), u . w from the product, each summed as segment_sums sums it.
 * The same bits as product + reduce_finish launched for the bodies (productAndFinish). */
COROFEM_FN void pack_setup(const PackSlot* p, realp lambda, realp mu, realp massCoef, maskp run, uint dofRows,
                           __global uint* segInfo, __global const real* segCoef, __global const uint* corners,
                           __global const real* elem, __global real* sums, __global real* vec,
                           __global const real* mass, __global const real* free, __global real* minv,
                           __global sump* rows, __global const sum_real* initPartials, __global sum_real* allScalars,
                           uint fresh, sum_real tol2) {
  if (fresh != 0u) {
    pack_fresh_setup(p, lane_coef(p, segCoef, kCoefLambda) + lane_coef(p, segCoef, kCoefMu),
                     lane_coef(p, segCoef, kCoefMu), massCoef, lane_coef(p, segCoef, kCoefStiff), dofRows, corners,
                     elem, sums, vec, mass, free, minv, rows);
  } else {
    for (uint v = 0; v < p->partialCount; ++v)
      for (uint c = 0; c < 3; ++c) {
        sum_real t[PACK_L];
        for (int l = 0; l < PACK_L; ++l)
          t[l] = p->seg[l] >= 0
                     ? initPartials[kPartialComponents * (seg_info(segInfo, (uint)p->seg[l], kSegPartialBegin) + v) + c]
                     : (sum_real)0;
        rows[3 * v + c] = vload8(0, t);
      }
  }
  pack_segment_sums(rows, p->partialCount);
  sum_real ru[PACK_L], rr[PACK_L], bb[PACK_L], uw[PACK_L];
  STU(rows[0], ru);
  STU(rows[1], rr);
  STU(rows[2], bb);
  pack_product(p, lambda, mu, massCoef, run, dofRows, corners, elem, sums, vec, mass, free, rows, 0);
  pack_segment_sums(rows, p->partialCount);
  STU(rows[0], uw);
  for (int l = 0; l < PACK_L; ++l)
    if (p->seg[l] >= 0 && seg_info(segInfo, (uint)p->seg[l], kSegActive) != 0u)
      update_scalars(segInfo, (uint)p->seg[l], allScalars + kScalarCount * (uint)p->seg[l], kReduceInit, tol2, ru[l],
                     rr[l], bb[l], uw[l]);
}

/* The lanes of the pack's bodies (-1), present or not. */
COROFEM_FN maskp lane_present(const PackSlot* p) {
  int v[PACK_L];
  for (int l = 0; l < PACK_L; ++l) v[l] = p->seg[l] >= 0 ? -1 : 0;
#ifdef COROFEM_DOUBLE
  return convert_long8(vload8(0, v));
#else
  return vload8(0, v);
#endif
}

/* The end of a solve for the bodies of a pack, after its iterations: the iteration cap's last for
 * the lanes still running (pcgIteration(last): the update and reduce_finish(kReduceLast), no
 * product), then the true residual of every lane (queueResidual: the product of x with the
 * right-hand side and reduce_finish(kReduceResidual)), lane by lane with the same bits; the lanes'
 * segments are then made inactive, so that the launched last iteration and residual leave them. */
COROFEM_FN void pack_finish(const PackSlot* p, realp lambda, realp mu, realp massCoef, maskp run, int any,
                            uint dofRows, __global uint* segInfo, __global const uint* corners,
                            __global const real* elem, __global real* nodeSums, __global real* vec,
                            __global const real* mass, __global const real* free, __global const real* minv,
                            __global sump* rows, __global sum_real* allScalars, sum_real tol2) {
  sum_real a[PACK_L], b[PACK_L];
  if (any != 0) {
    const realp alpha = lane_scalar(p, allScalars, kScalarAlpha), beta = lane_scalar(p, allScalars, kScalarBeta);
    for (uint v = 0; v < p->partialCount; ++v) {
      const uint first = v * COROFEM_CHUNK, last = min(first + (uint)COROFEM_CHUNK, p->nodes);
      sump sums[2];
      pack_update_nodes(first, max(first, last), p->nodeBase, dofRows, alpha, beta, run, vec, minv, sums);
      rows[3 * v] = sums[0];
      rows[3 * v + 1] = sums[1];
      rows[3 * v + 2] = (sump)0;
    }
    pack_segment_sums(rows, p->partialCount);
    STU(rows[0], a);
    STU(rows[1], b);
    for (int l = 0; l < PACK_L; ++l)
      if (p->seg[l] >= 0 && seg_info(segInfo, (uint)p->seg[l], kSegActive) != 0u)
        update_scalars(segInfo, (uint)p->seg[l], allScalars + kScalarCount * (uint)p->seg[l], kReduceLast, tol2, a[l],
                       b[l], (sum_real)0, (sum_real)0);
  }
  const maskp present = lane_present(p);
  for (uint e = 0; e < p->elems; ++e) pack_product_element(e, p, lambda, mu, dofRows, corners, elem, vec, 0, nodeSums);
  for (uint v = 0; v < p->partialCount; ++v) {
    const uint first = v * COROFEM_CHUNK, last = min(first + (uint)COROFEM_CHUNK, p->nodes);
    sump sums[2];
    pack_residual_nodes(first, max(first, last), p, massCoef, present, dofRows, nodeSums, mass, free, vec, sums);
    rows[3 * v] = (sump)0;
    rows[3 * v + 1] = sums[0];
    rows[3 * v + 2] = sums[1];
  }
  pack_segment_sums(rows, p->partialCount);
  STU(rows[1], a);
  STU(rows[2], b);
  for (int l = 0; l < PACK_L; ++l)
    if (p->seg[l] >= 0) {
      update_scalars(segInfo, (uint)p->seg[l], allScalars + kScalarCount * (uint)p->seg[l], kReduceResidual, tol2,
                     (sum_real)0, a[l], b[l], (sum_real)0);
      segInfo[kSegInfoCount * (uint)p->seg[l] + kSegActive] = 0u;
    }
}

/* The whole PCG solve of the bodies of each pack slot (one work-item per slot), after pcg_init on
 * their own vectors (which pack_in copied in) or, with `fresh` (the zero start), from their
 * right-hand sides: the set-up's end (pack_setup; from the node blocks on with `fresh`),
 * `iterations` iterations of kReduceStep, then the cap's last iteration and the true residual
 * (pack_finish). Every body of a slot is in the solve: the pack marks its lanes' segments running
 * itself (the host leaves them inactive while it launches the other bodies' set-up, whose
 * reduce_finish may stop a body that a later upload of the table would revive), update_scalars
 * clears them at a stop and pack_finish at the end, so that the launched last iteration and
 * residual pass them by. */
COROFEM_FN void pack_solve(uint slot, __global const uint* packInfo, __global uint* segInfo,
                           __global const real* segCoef, __global const uint* corners, __global const real* elem,
                           __global real* sums, __global real* vec, __global const real* free,
                           __global const real* mass, __global real* minv, __global sump* partials,
                           __global const sum_real* initPartials, __global sum_real* allScalars, const uint dofRows,
                           const uint iterations, const uint fresh, const sum_real tol2) {
  const PackSlot p = pack_slot(packInfo, slot);
  for (int l = 0; l < PACK_L; ++l)
    if (p.seg[l] >= 0) segInfo[kSegInfoCount * (uint)p.seg[l] + kSegActive] = kSegRunningPacked;
  const realp lambda = lane_coef(&p, segCoef, kCoefProdLambda), mu = lane_coef(&p, segCoef, kCoefProdMu);
  const realp massCoef = lane_coef(&p, segCoef, kCoefMass);
  __global sump* rows = partials + (size_t)3 * p.partialBase;
  int any = 0;
  maskp run = lane_running(&p, segInfo, &any);
  if (any != 0)
    for (uint k = 0; k < PACK_SUMS * p.nodes; ++k) STP((realp)0, ROW(sums, PACK_SUMS * p.nodeBase + k));
  if (any != 0) {
    pack_setup(&p, lambda, mu, massCoef, run, dofRows, segInfo, segCoef, corners, elem, sums, vec, mass, free, minv,
               rows, initPartials, allScalars, fresh, tol2);
    run = lane_running(&p, segInfo, &any);
  }
  for (uint it = 0; it < iterations && any != 0; ++it) {
    const realp alpha = lane_scalar(&p, allScalars, kScalarAlpha), beta = lane_scalar(&p, allScalars, kScalarBeta);
    for (uint v = 0; v < p.partialCount; ++v) {
      const uint first = v * COROFEM_CHUNK, last = min(first + (uint)COROFEM_CHUNK, p.nodes);
      sump sums[2];
      pack_update_nodes(first, max(first, last), p.nodeBase, dofRows, alpha, beta, run, vec, minv, sums);
      rows[3 * v] = sums[0];
      rows[3 * v + 1] = sums[1];
    }
    pack_product(&p, lambda, mu, massCoef, run, dofRows, corners, elem, sums, vec, mass, free, rows, 2);
    pack_segment_sums(rows, p.partialCount);
    sum_real ru[PACK_L], rr[PACK_L], uw[PACK_L];
    STU(rows[0], ru);
    STU(rows[1], rr);
    STU(rows[2], uw);
    for (int l = 0; l < PACK_L; ++l)
      if (p.seg[l] >= 0 && seg_info(segInfo, (uint)p.seg[l], kSegActive) != 0u)
        update_scalars(segInfo, (uint)p.seg[l], allScalars + kScalarCount * (uint)p.seg[l], kReduceStep, tol2, ru[l],
                       rr[l], (sum_real)0, uw[l]);
    run = lane_running(&p, segInfo, &any);
  }
  pack_finish(&p, lambda, mu, massCoef, run, any, dofRows, segInfo, corners, elem, sums, vec, mass, free, minv, rows,
              allScalars, tol2);
}

/* pack_solve for each of the round's `packs` slots: a work-group (of one work-item) per compute
 * unit, each taking the next slot from the claim word until none is left. The host orders the
 * slots the costliest first, so this is the longest-first list schedule whatever the runtime does
 * with work-groups: PoCL hands a thread ceil(remaining / threads) work-groups at a time, which gave
 * one of 2 threads the 7 costliest of 13 packs (iterations 132 96 89 83 76 70 66 of a step of
 * bench_batch's varied set: 612 against 286 for the other thread). */
__kernel __attribute__((reqd_work_group_size(1, 1, 1)))
void pcg_iterate_pack(__global uint* packInfo, const uint packs, __global uint* segInfo,
                      __global const real* segCoef, __global const uint* corners, __global const real* elem,
                      __global real* sums, __global real* vec, __global const real* free,
                      __global const real* mass, __global real* minv, __global sump* partials,
                      __global const sum_real* initPartials, __global sum_real* allScalars, const uint dofRows,
                      const uint iterations, const uint fresh, const sum_real tol2) {
  for (;;) {
    const uint slot = atomic_inc(packInfo + kPackInfoCount * packs);
    if (slot >= packs) return;
    pack_solve(slot, packInfo, segInfo, segCoef, corners, elem, sums, vec, free, mass, minv, partials, initPartials,
               allScalars, dofRows, iterations, fresh, tol2);
  }
}

/* The 8 x 8 transpose, t[j] lane i = a[i] lane j, in three stages of shuffle2 with constant masks
 * (lane pairs, pairs of pairs, halves), which compile to a few permutes each (an 8-lane vector
 * literal of extracted lanes compiled to 64 inserts). */
#ifdef COROFEM_DOUBLE
typedef ulong8 shufmaskp;
#else
typedef uint8 shufmaskp;
#endif
COROFEM_FN void pack_transpose(const realp* a, realp* t) {
  const shufmaskp even = (shufmaskp)(0, 8, 2, 10, 4, 12, 6, 14), odd = (shufmaskp)(1, 9, 3, 11, 5, 13, 7, 15);
  const shufmaskp pairLo = (shufmaskp)(0, 1, 8, 9, 4, 5, 12, 13), pairHi = (shufmaskp)(2, 3, 10, 11, 6, 7, 14, 15);
  const shufmaskp halfLo = (shufmaskp)(0, 1, 2, 3, 8, 9, 10, 11), halfHi = (shufmaskp)(4, 5, 6, 7, 12, 13, 14, 15);
  realp b[8], c[8];
  for (int i = 0; i < 8; i += 2) {
    b[i] = shuffle2(a[i], a[i + 1], even);
    b[i + 1] = shuffle2(a[i], a[i + 1], odd);
  }
  for (int i = 0; i < 8; i += 4)
    for (int k = 0; k < 2; ++k) {
      c[i + k] = shuffle2(b[i + k], b[i + k + 2], pairLo);
      c[i + k + 2] = shuffle2(b[i + k], b[i + k + 2], pairHi);
    }
  for (int j = 0; j < 4; ++j) {
    t[j] = shuffle2(c[j], c[j + 4], halfLo);
    t[j + 4] = shuffle2(c[j], c[j + 4], halfHi);
  }
}

/* Work-item lid's share [*lo, *hi) of n blocks: consecutive blocks (PoCL runs a work-group's items
 * one after the other: blocks strided over the items read each cache line twice, far apart). */
COROFEM_FN void pack_share(uint n, uint lid, uint* lo, uint* hi) {
  const uint per = (n + COROFEM_WG - 1) / COROFEM_WG;
  *lo = min(n, lid * per);
  *hi = min(n, *lo + per);
}

/* Rows row + j * stride (j < 8) of a pack array from 8 consecutive reals of each lane's body: lane
 * l's at from + first[l] (no body: zeros). */
COROFEM_FN void pack_rows_in(__global const real* from, const long* first, __global real* to, size_t row,
                             uint stride) {
  realp a[PACK_L], t[PACK_L];
  for (int l = 0; l < PACK_L; ++l) a[l] = first[l] >= 0 ? LDU(from + first[l]) : (realp)0;
  pack_transpose(a, t);
  for (int j = 0; j < PACK_L; ++j) STP(t[j], ROW(to, row + (size_t)j * stride));
}

/* The bodies' data into their pack slots (one work-group per slot, 8 elements or 8 node rows per
 * step, an 8 x 8 transpose each): a_i and volumes, the PCG vectors x r u p s w and b (rhs), M^-1,
 * the mass and the free mask; zeros in the lanes of no body. The slots' rows are padded to 8 elements and 8
 * nodes, which the bodies' padded segments cover (their padding is never read by pcg_iterate_pack). */
__kernel __attribute__((reqd_work_group_size(COROFEM_WG, 1, 1)))
void pack_in(__global const uint* packInfo, __global const uint* segInfo, const uint S,
             __global const real* rotGrad, __global const real* geom, __global const real* x,
             __global const real* r, __global const real* u, __global const real* pv, __global const real* s,
             __global const real* w, __global const real* rhs, __global const real* minv, __global const real* mass,
             __global const real* free, __global real* elem, __global real* vec, __global real* packMinv,
             __global real* packMass, __global real* packFree, const uint dofRows, const uint fresh) {
  const PackSlot p = pack_slot(packInfo, get_group_id(0));
  const uint lid = get_local_id(0);
  long elemBegin[PACK_L], dofBegin[PACK_L], at[PACK_L];
  for (int l = 0; l < PACK_L; ++l) {
    elemBegin[l] = p.seg[l] >= 0 ? (long)seg_info(segInfo, (uint)p.seg[l], kSegElemBegin) : -1;
    dofBegin[l] = p.seg[l] >= 0 ? 3 * (long)seg_info(segInfo, (uint)p.seg[l], kSegNodeBegin) : -1;
  }
  /* Row-major order over (row k, block b): the work-group's items run one after the other on a CPU,
   * so each lane's row is read as one long stream (8 at a time, which the prefetchers follow) where
   * a block's 10 rows of 8 lanes made 80 short ones. */
  uint lo, hi;
  const uint elemBlocks = (p.elems + 7) / 8;
  pack_share(kPackElemRows * elemBlocks, lid, &lo, &hi);
  for (uint i = lo; i < hi; ++i) {
    const uint k = i / elemBlocks, b = i % elemBlocks;
    for (int l = 0; l < PACK_L; ++l) at[l] = elemBegin[l] < 0 ? -1 : (long)k * S + elemBegin[l] + 8 * b;
    /* a_i components 0..8 of rotGrad, the volume (9) of geom */
    pack_rows_in(k < 9 ? rotGrad : geom, at, elem, (size_t)(p.elemBase + 8 * b) * kPackElemRows + k, kPackElemRows);
  }
  /* The same over (array v, block b): x, r u p s w (not with `fresh`: pcg_iterate_pack forms them,
   * and M^-1), the free mask, the right-hand side, the mass. */
  __global const real* from[9] = {x, r, u, pv, s, w};
  __global real* to[9] = {PACK_VEC(vec, dofRows, 0), PACK_VEC(vec, dofRows, 1), PACK_VEC(vec, dofRows, 2),
                          PACK_VEC(vec, dofRows, 3), PACK_VEC(vec, dofRows, 4), PACK_VEC(vec, dofRows, 5)};
  uint arrays = fresh ? 1u : 6u;
  from[arrays] = free;
  to[arrays++] = packFree;
  from[arrays] = rhs;
  to[arrays++] = PACK_VEC(vec, dofRows, 6);
  if (mass) {
    from[arrays] = mass;
    to[arrays++] = packMass;
  }
  const uint dofBlocks = 3 * ((p.nodes + 7) / 8);
  pack_share(arrays * dofBlocks, lid, &lo, &hi);
  for (uint i = lo; i < hi; ++i) {
    const uint v = i / dofBlocks, b = i % dofBlocks;
    for (int l = 0; l < PACK_L; ++l) at[l] = dofBegin[l] < 0 ? -1 : dofBegin[l] + 8 * b;
    pack_rows_in(from[v], at, to[v], (size_t)3 * p.nodeBase + 8 * b, 1);
  }
#if defined(COROFEM_PRECOND_BLOCK) || defined(COROFEM_PRECOND_DIAG)
  const uint invBlocks = fresh ? 0u : COROFEM_NODE_INVERSE * ((p.nodes + 7) / 8);
  pack_share(invBlocks, lid, &lo, &hi);
  for (uint b = lo; b < hi; ++b) {
    for (int l = 0; l < PACK_L; ++l) at[l] = dofBegin[l] < 0 ? -1 : dofBegin[l] / 3 * COROFEM_NODE_INVERSE + 8 * b;
    pack_rows_in(minv, at, packMinv, (size_t)COROFEM_NODE_INVERSE * p.nodeBase + 8 * b, 1);
  }
#endif
}

/* The PCG vectors x r u p s w of the bodies back from their pack slots (the inverse transposes). */
__kernel __attribute__((reqd_work_group_size(COROFEM_WG, 1, 1)))
void pack_out(__global const uint* packInfo, __global const uint* segInfo, __global real* x, __global real* r,
              __global real* u, __global real* pv, __global real* s, __global real* w, __global const real* vec,
              const uint dofRows) {
  const PackSlot p = pack_slot(packInfo, get_group_id(0));
  const uint lid = get_local_id(0);
  long dofBegin[PACK_L];
  for (int l = 0; l < PACK_L; ++l)
    dofBegin[l] = p.seg[l] >= 0 ? 3 * (long)seg_info(segInfo, (uint)p.seg[l], kSegNodeBegin) : -1;
  __global real* to[6] = {x, r, u, pv, s, w};
  const uint dofBlocks = 3 * ((p.nodes + 7) / 8);
  uint lo, hi;
  pack_share(6 * dofBlocks, lid, &lo, &hi);  /* vector-major, as pack_in: each lane's vector one long stream */
  for (uint i = lo; i < hi; ++i) {
    const uint v = i / dofBlocks, b = i % dofBlocks;
    realp a[PACK_L], t[PACK_L];
    const size_t row = (size_t)3 * p.nodeBase + 8 * b;
    for (int j = 0; j < PACK_L; ++j) a[j] = LDP(ROW(PACK_VEC(vec, dofRows, v), row + j));
    pack_transpose(a, t);
    for (int l = 0; l < PACK_L; ++l)
      if (dofBegin[l] >= 0) STU(t[l], to[v] + dofBegin[l] + 8 * b);
  }
}
#endif /* !COROFEM_TREE_REDUCE */
