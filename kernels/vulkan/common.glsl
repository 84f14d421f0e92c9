/* What every corofem compute shader shares: the precision, the buffers (one descriptor set, the
 * same bindings in every shader, so one pipeline layout serves them all; a device writes three
 * descriptor sets once, which differ in the product's input and output, and amg.comp's own
 * bindings take some of the numbers for the multigrid's buffers), the push constants, and the
 * segment lookups. The data layout is
 * kernels/shared/corofem_layout.h, the same as the OpenCL kernels' with one element per invocation
 * (COROFEM_VEC = 1: element outputs are 12 contiguous reals per element) and work-groups of
 * COROFEM_WG = 64 invocations.
 *
 * Built twice by glslc (cmake/CompileShaders.cmake): float, and with -DCOROFEM_DOUBLE double (the
 * device needs shaderFloat64). */
#extension GL_GOOGLE_include_directive : require
#include "precision.glsl"

#define COROFEM_GLSL 1
#include "../shared/corofem_layout.h"

layout(local_size_x = 64) in;
#define WG 64u

/* pcg_group.comp passes values between the invocations of a work-group through these buffers within
 * one dispatch: it declares them coherent. pcg_fused.comp passes the partial sums between its
 * work-groups: it declares those alone coherent (COROFEM_COHERENT_SUMS: the segment table and the
 * partials). */
#ifndef COROFEM_COHERENT
#define COROFEM_COHERENT
#endif
#ifndef COROFEM_COHERENT_SUMS
#define COROFEM_COHERENT_SUMS COROFEM_COHERENT
#endif

/* Bindings (set 0); the host's Binding enum (vulkan_device_impl.hpp) lists the same numbers. */
layout(std430, binding = 0) COROFEM_COHERENT_SUMS buffer SegInfo { uint segInfo[]; };
layout(std430, binding = 1) readonly COROFEM_COHERENT buffer SegCoef { real segCoef[]; };
layout(std430, binding = 2) readonly COROFEM_COHERENT buffer ElemSeg { uint elemSeg[]; };
layout(std430, binding = 3) readonly COROFEM_COHERENT buffer NodeSeg { uint nodeSeg[]; };
layout(std430, binding = 4) readonly COROFEM_COHERENT buffer Corners { uint corners[]; };  /* node of corner c of e at c S + e */
layout(std430, binding = 5) readonly COROFEM_COHERENT buffer Geom { real geom[]; };        /* grad N_1..3, volume (k S + e) */
layout(std430, binding = 6) COROFEM_COHERENT buffer RotGrad { real rotGrad[]; };           /* a_i = R grad N_i (k S + e) */
layout(std430, binding = 7) readonly COROFEM_COHERENT buffer Pos { real pos[]; };          /* positions minus the centroid */
layout(std430, binding = 8) COROFEM_COHERENT buffer ElemOut { real elemOut[]; };           /* 12 per element */
layout(std430, binding = 9) readonly COROFEM_COHERENT buffer GatherStart { uint gatherStart[]; };
layout(std430, binding = 10) readonly COROFEM_COHERENT buffer GatherEntry { uint gatherEntry[]; }; /* 12 e + 3 c */
layout(std430, binding = 11) readonly COROFEM_COHERENT buffer Mass { real mass[]; };       /* lumped mass per dof */
layout(std430, binding = 12) readonly COROFEM_COHERENT buffer Free { real freeDof[]; };    /* 1 free, 0 constrained */
layout(std430, binding = 13) COROFEM_COHERENT buffer Blocks { real blocks[]; };            /* 6 per node: xx yy zz xy xz yz */
layout(std430, binding = 14) COROFEM_COHERENT buffer Minv { real minv[]; };                /* 9 per node */
layout(std430, binding = 15) readonly COROFEM_COHERENT buffer VecIn { real vin[]; };       /* a product's p */
layout(std430, binding = 16) COROFEM_COHERENT buffer VecOut { real vout[]; };              /* a product's y, the forces */
layout(std430, binding = 17) readonly COROFEM_COHERENT buffer VecB { real bvec[]; };
layout(std430, binding = 18) COROFEM_COHERENT buffer VecX { real xvec[]; };
layout(std430, binding = 19) COROFEM_COHERENT buffer VecR { real rvec[]; };
layout(std430, binding = 20) COROFEM_COHERENT buffer VecU { real uvec[]; };
layout(std430, binding = 21) COROFEM_COHERENT buffer VecP { real pvec[]; };
layout(std430, binding = 22) COROFEM_COHERENT buffer VecS { real svec[]; };
layout(std430, binding = 23) COROFEM_COHERENT buffer VecW { real wvec[]; };
layout(std430, binding = 24) COROFEM_COHERENT_SUMS buffer Partials { real partials[]; };        /* 3 per node work-group */
layout(std430, binding = 25) COROFEM_COHERENT_SUMS buffer PartialsW { real partialsW[]; };
layout(std430, binding = 26) COROFEM_COHERENT buffer Scalars { real scalars[]; };          /* kScalarCount per segment */
layout(std430, binding = 27) COROFEM_COHERENT buffer Energy { real energy[]; };            /* per element */
layout(std430, binding = 28) COROFEM_COHERENT buffer Quat { real quat[]; };                /* 4 per element (k S + e) */
layout(std430, binding = 29) COROFEM_COHERENT buffer Rot { real rot[]; };                  /* R row-major (k S + e) */
layout(std430, binding = 30) readonly COROFEM_COHERENT buffer Spring { real spring[]; };   /* spring stiffness per dof */

layout(push_constant) uniform Push {
  uint S;         /* element stride */
  uint mode;      /* what the shader computes (each shader's kMode*) */
  uint flags;     /* kFlag* */
  uint precond;   /* 0 none, 1 diagonal, 2 3x3 blocks */
  uint rotation;  /* 0 polar, 1 svd, 2 quaternion, 3 qr */
} pc;

const uint kFlagProject = 1u;       /* products: y = 0 on constrained dofs */
const uint kFlagMass = 2u;          /* some body has mass (the mass buffer is read) */
const uint kFlagZeroStart = 4u;     /* pcg set-up: x = 0 (q is not read) */
const uint kFlagWriteCorners = 8u;  /* rotations: sqrt(V) a_c into elemOut */
const uint kFlagWriteR = 16u;       /* rotations: R into rot */
const uint kFlagSprings = 32u;      /* some body has springs (the spring buffer is read) */
const uint kFlagCapLast = 64u;      /* pcg_group: its last iteration is the cap's last (no product) */

uint seg_info(uint s, uint k) { return segInfo[kSegInfoCount * s + k]; }
real seg_coef(uint s, uint k) { return segCoef[kSegCoefCount * s + k]; }
bool has_flag(uint f) { return (pc.flags & f) != 0u; }
