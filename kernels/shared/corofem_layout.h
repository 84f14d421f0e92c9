/* Device data layout of the device backends, shared by the host (C++), the OpenCL kernels (OpenCL C)
 * and the Vulkan shaders (GLSL, which define COROFEM_GLSL before including it) so that they cannot
 * drift. Everything per element is stored structure-of-arrays with a
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
 * float): there every term of a dot product is formed exactly (a float times a float fits a double;
 * on CPU devices, which flush denormals, a denormal float entry counts as 0) and summed in double,
 * so the rounding of the sum, ~ n eps_float |x||y| in float for n terms in the worst case, drops to
 * the float rounding of the vectors themselves. */
#if defined(COROFEM_MIXED) && !defined(COROFEM_DOUBLE)
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
typedef double sum_real;
typedef double4 sum_real4;
#define TO_SUM4(v) convert_double4(v)
#else
typedef real sum_real;
typedef real4 sum_real4;
#define TO_SUM4(v) (v)
#endif
#define COROFEM_CONSTANT(type, name, value) enum { name = value }
/* Helper functions: `static inline`, so that no external definition is ever needed (C99 inline
 * semantics would leave an undefined symbol wherever a compiler declines to inline). */
#define COROFEM_FN static inline
#elif defined(COROFEM_GLSL)
/* Every constant here is unsigned. */
#define COROFEM_CONSTANT(type, name, value) const uint name = value
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
/* Per-element output 12-vector (forces, products, preconditioner corner data), in blocks of
 * B = COROFEM_VEC elements so that a work-item writes whole vectors: component k of corner c of
 * element e at ((e / B) * 12 + 3 c + k) * B + e % B (B = 1 on GPUs: 12 contiguous per element).   */
COROFEM_CONSTANT(unsigned, kElemOutComponents, 12);

/* Node gather list (CSR over nodes, fixed order): entry = ((e / B) * 12 + 3 c) * B + e % B, the
 * x component of corner c of element e; y and z follow B and 2 B later.                          */

/* Per-node preconditioner input: symmetric 3x3 block sum of the rotated element stiffness blocks
 * sum_e R K_e,ii R^T (xx, yy, zz, xy, xz, yz) at 6 n + k; its diagonal only, at 3 n + k, for the
 * diagonal preconditioner (precond.cl, COROFEM_NODE_BLOCK).                                      */
COROFEM_CONSTANT(unsigned, kNodeBlockComponents, 6);
/* Per-node inverse preconditioner: 9 entries (row-major 3x3) for block diagonal, 3 for diagonal. */

/* ---------------------------------------------------------------- PCG scalars on the device (sum_real) */
/* kScalarCount per segment: scalar k of segment s at kScalarCount * s + k.                        */
COROFEM_CONSTANT(unsigned, kScalarRho, 0);      /* gamma = r . u (current, u = M^-1 r) */
COROFEM_CONSTANT(unsigned, kScalarPq, 1);       /* p . A p (from the recurrence)       */
COROFEM_CONSTANT(unsigned, kScalarAlpha, 2);    /* gamma / (p . A p)                   */
COROFEM_CONSTANT(unsigned, kScalarBeta, 3);     /* gamma_new / gamma_old               */
COROFEM_CONSTANT(unsigned, kScalarRr, 4);       /* r . r (free dofs)                   */
COROFEM_CONSTANT(unsigned, kScalarBb, 5);       /* b . b (free dofs)                   */
COROFEM_CONSTANT(unsigned, kScalarBreakdown, 6);/* 1 when p . A p <= 0 was met         */
COROFEM_CONSTANT(unsigned, kScalarIterations, 7);/* iterations done (counted on the device) */
COROFEM_CONSTANT(unsigned, kScalarStop, 8);     /* why the segment stopped: kStop*     */
COROFEM_CONSTANT(unsigned, kScalarTol2, 9);     /* tolerance^2 of the solve (the Vulkan shaders read it
                                                   here; the OpenCL kernels take it as an argument) */
COROFEM_CONSTANT(unsigned, kScalarCount, 12);
/* Values of kScalarStop: reduce_finish tests every iteration and makes a stopped segment inactive
 * (segInfo), so that the iterations the host has already enqueued return at once for it. */
COROFEM_CONSTANT(unsigned, kStopRunning, 0);
COROFEM_CONSTANT(unsigned, kStopConverged, 1);   /* r . r <= tol^2 b . b                   */
COROFEM_CONSTANT(unsigned, kStopBreakdown, 2);   /* p . A p <= 0: no further progress       */
COROFEM_CONSTANT(unsigned, kStopNonFinite, 3);   /* r . r is NaN or Inf                     */

/* Modes of reduce_finish (pcg.cl: which scalars the partial sums become). */
COROFEM_CONSTANT(unsigned, kReduceInit, 0);     /* (r.u, r.r, b.b), u.w -> gamma, rr, bb, alpha, beta = 0 */
COROFEM_CONSTANT(unsigned, kReduceStep, 1);     /* (r.u, r.r), u.w -> beta, alpha, gamma, rr              */
COROFEM_CONSTANT(unsigned, kReduceResidual, 2); /* (r.u, r.r, b.b) -> rr, bb (the true residual)          */
COROFEM_CONSTANT(unsigned, kReduceLast, 3);     /* (r.u, r.r) -> gamma, rr: the cap's last iteration     */
COROFEM_CONSTANT(unsigned, kReduceEnergy, 4);   /* Vulkan: each element work-group's energy sum         */
COROFEM_CONSTANT(unsigned, kPartialComponents, 3); /* partial sums per work-group: 3 sum_reals    */
/* pcg_iterate_team's state per segment (uint, one cache line each): chunks done and members gone
 * (zero between launches), where the segment's chunk claim words start in the same buffer. */
COROFEM_CONSTANT(unsigned, kTeamStride, 16);
COROFEM_CONSTANT(unsigned, kTeamDone, 0);
COROFEM_CONSTANT(unsigned, kTeamLeft, 1);
COROFEM_CONSTANT(unsigned, kTeamFlags, 2);

/* Default work-group size (overridden by -DCOROFEM_WG). Reductions need a power of two. */
#ifndef COROFEM_WG
#define COROFEM_WG 64
#endif
COROFEM_CONSTANT(unsigned, kStrideAlign, 16);

/* ---------------------------------------------------------------- segments (one per body) */
/* One device can hold many bodies in the same buffers and launches (solve/batch.hpp); a single
 * body is the case of one segment. Segment s owns the elements [elemBegin_s, elemBegin_s + E_s)
 * and the nodes [nodeBegin_s, nodeBegin_s + N_s) of the shared arrays, where E_s is its element
 * count padded to a multiple of COROFEM_WG * COROFEM_VEC and N_s its node count padded to a
 * multiple of COROFEM_WG * COROFEM_CHUNK. So every work-group of every kernel lies in exactly one
 * segment: an element work-group g in elemSeg[g], a node work-group in nodeSeg[first node / WG]
 * (one entry per WG nodes). Element and node indices in the gather lists and corner lists are
 * global. Padding elements have zero gradients and volume and the segment's first node as corners;
 * padding nodes belong to no element, have zero mass and are constrained (free = 0), so they add
 * exact zeros to every sum. The PCG partial sums of segment s are the triples
 * [partialBegin_s, partialBegin_s + partialCount_s) and its PCG scalars kScalarCount * s + k.
 * Per segment (uint) at segInfo[kSegInfoCount * s + k]:                                          */
COROFEM_CONSTANT(unsigned, kSegActive, 0);       /* 0: the segment's work-groups return at once  */
/* Values of kSegActive besides 0 (every kernel takes any nonzero value as active): */
COROFEM_CONSTANT(unsigned, kSegRunning, 1);      /* active                                        */
COROFEM_CONSTANT(unsigned, kSegRunningPacked, 2);/* active, its PCG iterations in pcg_iterate_pack
                                                    (pcg_iterate_group and _team leave it alone)   */
COROFEM_CONSTANT(unsigned, kSegElemEnd, 1);      /* one past its last real element (global)       */
COROFEM_CONSTANT(unsigned, kSegNodeEnd, 2);      /* one past its last real node (global)          */
COROFEM_CONSTANT(unsigned, kSegPartialBegin, 3); /* its first PCG partial triple                  */
COROFEM_CONSTANT(unsigned, kSegPartialCount, 4); /* its number of PCG partial triples             */
COROFEM_CONSTANT(unsigned, kSegElemBegin, 5);    /* its first element (global)                    */
COROFEM_CONSTANT(unsigned, kSegElemSpan, 6);     /* its elements, padding included                */
COROFEM_CONSTANT(unsigned, kSegNodeBegin, 7);    /* its first node (global)                       */
COROFEM_CONSTANT(unsigned, kSegArrived, 8);      /* Vulkan's fused PCG node pass: its work-groups
                                                    done so far (0 between dispatches)             */
COROFEM_CONSTANT(unsigned, kSegInfoCount, 9);
/* Per segment (real) at segCoef[kSegCoefCount * s + k]: the material and the coefficients of the
 * current system A = m M + c C + k K^R with Rayleigh C = alpha M + beta K^R folded in.           */
COROFEM_CONSTANT(unsigned, kCoefLambda, 0);      /* Lame lambda (forces, energy, preconditioner)  */
COROFEM_CONSTANT(unsigned, kCoefMu, 1);          /* Lame mu                                       */
COROFEM_CONSTANT(unsigned, kCoefProdLambda, 2);  /* (k + c beta) lambda (element products)        */
COROFEM_CONSTANT(unsigned, kCoefProdMu, 3);      /* (k + c beta) mu                               */
COROFEM_CONSTANT(unsigned, kCoefMass, 4);        /* m + c alpha                                   */
COROFEM_CONSTANT(unsigned, kCoefStiff, 5);       /* k + c beta                                    */
COROFEM_CONSTANT(unsigned, kCoefSpring, 6);      /* k: the springs' coefficient (Vulkan; OpenCL folds
                                                    the springs into the mass)                     */
COROFEM_CONSTANT(unsigned, kSegCoefCount, 8);

/* ---------------------------------------------------------------- packs of bodies (pcg_pack.cl) */
/* On CPU devices the PCG iterations of up to kPackLanes bodies with the same mesh (element corners
 * and node count alike, each with its own material, rest shape, mass, constraints and PCG scalars)
 * run in one work-item, body l of the pack in vector lane l. A pack slot holds, in lane-interleaved
 * rows of kPackLanes reals (row r at r * kPackLanes): element rows (elemBase + e) * kPackElemRows
 * + k (a_i components 0..8, the volume at 9) and node rows (nodeBase + n) * 3 + k of each node
 * vector (x r u p s w b: vector v at v * 3 * packNodes rows; free, mass and M^-1 in buffers of their
 * own, M^-1 with COROFEM_NODE_INVERSE rows per node), and of the node sums, which the element
 * products add to element by element (the order of the bodies' gather lists, so the same sums).
 * The element corners (4 per element, the pack's own node numbers) are shared by all packs of one
 * mesh. Per pack slot (uint) at packInfo[kPackInfoCount * p + k], and after the round's P slots
 * the claim word packInfo[kPackInfoCount * P] (0 when uploaded; pcg_iterate_pack's work-groups
 * take the slots in order from it):                                                              */
COROFEM_CONSTANT(unsigned, kPackLanes, 8);
COROFEM_CONSTANT(unsigned, kPackElemRows, 10);
COROFEM_CONSTANT(unsigned, kPackVectors, 7);       /* x r u p s w b                               */
COROFEM_CONSTANT(unsigned, kPackElems, 0);         /* E: elements of the mesh                      */
COROFEM_CONSTANT(unsigned, kPackNodes, 1);         /* N: nodes of the mesh                         */
COROFEM_CONSTANT(unsigned, kPackPartialCount, 2);  /* the bodies' PCG partial triples (alike)      */
COROFEM_CONSTANT(unsigned, kPackCorners, 3);       /* the mesh's first corner entry (4 per element) */
COROFEM_CONSTANT(unsigned, kPackElemBase, 4);      /* the slot's first element row group           */
COROFEM_CONSTANT(unsigned, kPackNodeBase, 5);      /* the slot's first node                        */
COROFEM_CONSTANT(unsigned, kPackPartialBase, 6);   /* the slot's first partial triple              */
COROFEM_CONSTANT(unsigned, kPackLane0, 7);         /* lane l's segment + 1 at kPackLane0 + l (0: no body) */
COROFEM_CONSTANT(unsigned, kPackInfoCount, 15);

/* ---------------------------------------------------------------- the Vulkan step store
 * kernels/vulkan/step.comp and host/src/backends/vulkan/vulkan_step_store.cpp. The passes (pc.mode): */
COROFEM_CONSTANT(unsigned, kStepBegin, 0);
COROFEM_CONSTANT(unsigned, kStepPositions, 1);
COROFEM_CONSTANT(unsigned, kStepResidual, 2);
COROFEM_CONSTANT(unsigned, kStepUpdate, 3);
COROFEM_CONSTANT(unsigned, kStepEnd, 4);
COROFEM_CONSTANT(unsigned, kStepDamping, 5);
/* Per body (uint) at bodyU[kStepUCount * b + k]: running, first dof, dofs, the physical state of
 * each of the four StateSlots (kStepUSlot + slot), the StateSlot the held targets start from (and
 * the damping's v is read from), kStepFlag* flags. */
COROFEM_CONSTANT(unsigned, kStepUActive, 0);
COROFEM_CONSTANT(unsigned, kStepUDofBegin, 1);
COROFEM_CONSTANT(unsigned, kStepUDofs, 2);
COROFEM_CONSTANT(unsigned, kStepUSlot, 3);
COROFEM_CONSTANT(unsigned, kStepUFrom, 7);
COROFEM_CONSTANT(unsigned, kStepUFlags, 8);
COROFEM_CONSTANT(unsigned, kStepUCount, 12);
COROFEM_CONSTANT(unsigned, kStepFlagNewmark, 1);
COROFEM_CONSTANT(unsigned, kStepFlagSprings, 2);
COROFEM_CONSTANT(unsigned, kStepFlagApplied, 4);
COROFEM_CONSTANT(unsigned, kStepFlagHeld, 8);
/* Per body (real) at bodyR[reals per body * b + k]: the scheme's maps h, ka, kx, cv, ca, the held
 * targets' fraction, the mass damping's alpha; then the load scales and the prescribed groups'. */
COROFEM_CONSTANT(unsigned, kStepRH, 0);
COROFEM_CONSTANT(unsigned, kStepRKa, 1);
COROFEM_CONSTANT(unsigned, kStepRKx, 2);
COROFEM_CONSTANT(unsigned, kStepRCv, 3);
COROFEM_CONSTANT(unsigned, kStepRCa, 4);
COROFEM_CONSTANT(unsigned, kStepRFraction, 5);
COROFEM_CONSTANT(unsigned, kStepRAlpha, 6);
COROFEM_CONSTANT(unsigned, kStepRCount, 7);
/* The per-dof inputs, each a vector of every dof: rest positions, lumped mass, 1 on free dofs,
 * spring stiffness, held targets (NaN: not held), applied forces, spring targets, prescribed values. */
COROFEM_CONSTANT(unsigned, kStepInRest, 0);
COROFEM_CONSTANT(unsigned, kStepInMass, 1);
COROFEM_CONSTANT(unsigned, kStepInFree, 2);
COROFEM_CONSTANT(unsigned, kStepInSpring, 3);
COROFEM_CONSTANT(unsigned, kStepInHeld, 4);
COROFEM_CONSTANT(unsigned, kStepInApplied, 5);
COROFEM_CONSTANT(unsigned, kStepInSpringTarget, 6);
COROFEM_CONSTANT(unsigned, kStepInPresc, 7);
COROFEM_CONSTANT(unsigned, kStepInputs, 8);
COROFEM_CONSTANT(unsigned, kStepSums, 8);  /* partial sums per node work-group */

#ifdef __OPENCL_C_VERSION__
/* Segment lookups. Work-group indices are taken as global id / WG (not get_group_id) so that the
 * host may launch only the span of work-groups of the active segments with a global offset. */
COROFEM_FN uint element_segment(__global const uint* elemSeg) { return elemSeg[get_global_id(0) / COROFEM_WG]; }
COROFEM_FN uint node_segment(__global const uint* nodeSeg, uint node) { return nodeSeg[node / COROFEM_WG]; }
COROFEM_FN uint seg_info(__global const uint* segInfo, uint s, uint k) { return segInfo[kSegInfoCount * s + k]; }
COROFEM_FN real seg_coef(__global const real* segCoef, uint s, uint k) { return segCoef[kSegCoefCount * s + k]; }
/* The node of this work-item of a one-node-per-item kernel and its segment; false when there is
 * nothing to do (inactive segment: the whole work-group; a padding node). */
COROFEM_FN bool node_item(__global const uint* nodeSeg, __global const uint* segInfo, uint* n, uint* s) {
  *n = get_global_id(0);
  *s = node_segment(nodeSeg, *n);
  return seg_info(segInfo, *s, kSegActive) != 0u && *n < seg_info(segInfo, *s, kSegNodeEnd);
}
#endif

#endif /* COROFEM_LAYOUT_H */
