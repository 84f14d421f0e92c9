#version 450
/* The dynamics driver's per-dof passes on a device's step store (host/src/backends/vulkan/
 * vulkan_step_store.cpp; their meaning and the host's own version: host/src/solve/step_store.hpp
 * and host_step_store.cpp), pc.mode choosing the pass:
 *   kStepBegin      vb, xb, the constrained dofs' targets, f_ext(t1), Newton's starting v, Cv = 0
 *   kStepPositions  x = xb + kx v, a = ka (v - vb)
 *   kStepResidual   r = M a + C v + f_int + S (x - t) - f_ext, rhs = -r / ka, with |f_ext|^2
 *   kStepUpdate     v += dv
 *   kStepEnd        the reactions, the springs' pull joining f_ext, the work sums
 *   kStepDamping    Cv = alpha M v of the state kStepUFrom names (mass damping alone; alpha 0: none)
 * One invocation per node (its three dofs in order), work-groups of 64 nodes, each of one body (the
 * device's segments are whole node work-groups); a pass with sums writes its work-group's (the host
 * adds a body's work-groups in order, in double) to partials[8 g + k], a tree over its invocations:
 * the same bits for a body alone or in a set.
 *
 * Every vector is a whole device's dofs (pc.o0 = D reals, the device's numbering); positions (x,
 * the rest positions, held and spring targets) are stored relative to the body's origin, which the
 * differences the passes take do not see. A body's four states are physical states turned by its
 * table (a swap of two states swaps two entries there): vector v of state s of body b is
 * vecs[(5 slot(b, s) + v) D + d], scratch vector k vecs[(20 + k) D + d].
 *
 * This shader's bindings are its own (the host binds them in a descriptor set of its own over the
 * shared layout). */
#extension GL_GOOGLE_include_directive : require
#include "precision.glsl"

#define COROFEM_GLSL 1
#include "../shared/corofem_layout.h"

layout(local_size_x = 64) in;

layout(std430, binding = 0) readonly buffer WgBody { uint wgBody[]; };   /* per node work-group: its body, or ~0 */
layout(std430, binding = 1) readonly buffer BodyU { uint bodyU[]; };     /* kStepU* per body */
layout(std430, binding = 2) readonly buffer BodyR { real bodyR[]; };     /* pc.o3 per body: kStepR*, scales */
layout(std430, binding = 3) buffer Vecs { real vecs[]; };                /* 28 vectors of D */
layout(std430, binding = 4) readonly buffer Inputs { real inp[]; };      /* kStepIn* vectors of D */
layout(std430, binding = 5) readonly buffer Loads { real loads[]; };     /* pc.o1 load patterns of D */
layout(std430, binding = 6) readonly buffer Presc { uint presc[]; };     /* per dof: its prescribed group, or ~0 */
layout(std430, binding = 7) writeonly buffer Partials { real partials[]; };  /* 8 per work-group */

layout(push_constant) uniform Push {
  uint S, mode, flags, precond, rotation, rows;  /* common.glsl's; mode: the pass, corofem_layout.h's kStep* */
  uint o0, o1, o2, o3, o4, o5;                   /* D, load patterns, prescribed groups, reals per body */
} pc;

/* The passes, the per-body tables and the inputs: corofem_layout.h's kStep*. The state vectors
 * and the scratch (solve/step_store.hpp's StateVec and Scratch): */
const uint kX = 0u, kV = 1u, kA = 2u, kFext = 3u, kReaction = 4u;
const uint kVb = 0u, kXb = 1u, kTarget = 2u, kFint = 3u, kCv = 4u, kR = 5u, kDv = 6u, kRhs = 7u;
const uint kCommitted = 0u, kResult = 3u;

shared real sums[kStepSums][64];

uint body;

uint state_at(uint slot, uint v, uint d) { return (5u * bodyU[kStepUCount * body + kStepUSlot + slot] + v) * pc.o0 + d; }
uint scratch_at(uint k, uint d) { return (20u + k) * pc.o0 + d; }
real input_of(uint k, uint d) { return inp[k * pc.o0 + d]; }
real body_real(uint k) { return bodyR[pc.o3 * body + k]; }
bool body_flag(uint f) { return (bodyU[kStepUCount * body + kStepUFlags] & f) != 0u; }
bool not_finite(real v) { return isnan(v) || isinf(v); }

/* The work-group's sums k < count into partials (a tree; every invocation reaches it). */
void write_sums(uint count) {
  const uint lid = gl_LocalInvocationID.x;
  for (uint w = 32u; w > 0u; w >>= 1u) {
    barrier();
    if (lid < w)
      for (uint k = 0u; k < count; ++k) sums[k][lid] += sums[k][lid + w];
  }
  if (lid == 0u)
    for (uint k = 0u; k < count; ++k) partials[8u * gl_WorkGroupID.x + k] = sums[k][0];
}

void begin_dof(uint d) {
  const bool newmark = body_flag(kStepFlagNewmark);
  const real kx = body_real(kStepRKx);
  const real x = vecs[state_at(kCommitted, kX, d)], v = vecs[state_at(kCommitted, kV, d)];
  const real a = vecs[state_at(kCommitted, kA, d)];
  const real vb = newmark ? v + body_real(kStepRCv) * a : v;
  const real xb = newmark ? x + body_real(kStepRH) * v + body_real(kStepRCa) * a - kx * vb : x;
  vecs[scratch_at(kVb, d)] = vb;
  vecs[scratch_at(kXb, d)] = xb;
  const real free_d = input_of(kStepInFree, d);
  /* The targets: constrained dofs at rest, prescribed ones moved (the last group naming the dof),
   * then the application's held ones (NaN: not held), in proportion from the state kStepUFrom names. */
  real target = vecs[scratch_at(kTarget, d)];
  if (free_d == real(0)) target = input_of(kStepInRest, d);
  const uint g = presc[d];
  if (g != 0xFFFFFFFFu) target = input_of(kStepInRest, d) + body_real(kStepRCount + pc.o1 + g) * input_of(kStepInPresc, d);
  if (body_flag(kStepFlagHeld)) {
    const real held = input_of(kStepInHeld, d);
    if (!isnan(held)) {
      const real fraction = body_real(kStepRFraction);
      const real x0 = vecs[state_at(bodyU[kStepUCount * body + kStepUFrom], kX, d)];
      target = fraction == real(1) ? held : x0 + fraction * (held - x0);
    }
  }
  vecs[scratch_at(kTarget, d)] = target;
  real f = real(0);
  for (uint l = 0u; l < pc.o1; ++l) f += body_real(kStepRCount + l) * loads[l * pc.o0 + d];
  if (body_flag(kStepFlagApplied)) f += input_of(kStepInApplied, d);
  vecs[state_at(kResult, kFext, d)] = f;
  vecs[state_at(kResult, kV, d)] = free_d == real(0) ? (target - xb) / kx : v;
  vecs[scratch_at(kCv, d)] = real(0);
}

void positions_dof(uint d) {
  const real v = vecs[state_at(kResult, kV, d)];
  vecs[state_at(kResult, kX, d)] = vecs[scratch_at(kXb, d)] + body_real(kStepRKx) * v;
  vecs[state_at(kResult, kA, d)] = body_real(kStepRKa) * (v - vecs[scratch_at(kVb, d)]);
}

/* Adds dof d's terms to the invocation's sums (s[k]: k < 7). */
void residual_dof(uint d, inout real s[8]) {
  const real x = vecs[state_at(kResult, kX, d)], v = vecs[state_at(kResult, kV, d)];
  const real a = vecs[state_at(kResult, kA, d)];
  const real ma = input_of(kStepInMass, d) * a;
  const real k = input_of(kStepInSpring, d);
  const real spring = body_flag(kStepFlagSprings) && k != real(0) ? k * (x - input_of(kStepInSpringTarget, d)) : real(0);
  const real cv = vecs[scratch_at(kCv, d)], fint = vecs[scratch_at(kFint, d)];
  const real fext = vecs[state_at(kResult, kFext, d)];
  const real r = ma + cv + fint + spring - fext;
  vecs[scratch_at(kR, d)] = r;
  vecs[scratch_at(kRhs, d)] = -r / body_real(kStepRKa);
  const real f = input_of(kStepInFree, d);
  const real maf = ma * f, cvf = cv * f, fintf = fint * f, sf = spring * f, rf = r * f, ff = fext * f;
  s[0] += maf * maf;
  s[1] += cvf * cvf;
  s[2] += fintf * fintf;
  s[3] += sf * sf;
  s[4] += rf * rf;
  s[5] += not_finite(x) || not_finite(v) || not_finite(a) ? real(1) : real(0);
  s[6] += ff * ff;
}

void update_dof(uint d, inout real s[8]) {
  const real dv = vecs[scratch_at(kDv, d)];
  s[0] += not_finite(dv) ? real(1) : real(0);
  vecs[state_at(kResult, kV, d)] += dv;
}

void end_dof(uint d, inout real s[8]) {
  const real free_d = input_of(kStepInFree, d);
  const real rd = vecs[scratch_at(kR, d)] * (real(1) - free_d);
  vecs[state_at(kResult, kReaction, d)] = rd;
  const real x = vecs[state_at(kResult, kX, d)];
  const real k = input_of(kStepInSpring, d);
  real f = vecs[state_at(kResult, kFext, d)];
  if (body_flag(kStepFlagSprings) && k != real(0) && free_d != real(0)) {
    f += k * (input_of(kStepInSpringTarget, d) - x);
    vecs[state_at(kResult, kFext, d)] = f;
  }
  const real dx = x - vecs[state_at(kCommitted, kX, d)];
  const real fPrev = vecs[state_at(kCommitted, kFext, d)], rPrev = vecs[state_at(kCommitted, kReaction, d)];
  const real v = vecs[state_at(kResult, kV, d)];
  s[0] += (rPrev + rd) * dx;
  s[1] += (fPrev + f) * dx;
  s[2] += rPrev * dx;
  s[3] += rd * dx;
  s[4] += fPrev * dx;
  s[5] += f * dx;
  s[6] += input_of(kStepInMass, d) * (v * v);
}

void main() {
  body = wgBody[gl_WorkGroupID.x];
  if (body == 0xFFFFFFFFu || bodyU[kStepUCount * body + kStepUActive] == 0u) return;  /* the whole work-group */
  const uint lid = gl_LocalInvocationID.x;
  const uint n = 64u * gl_WorkGroupID.x + lid;  /* a node: its dofs 3 n .. 3 n + 2 */
  const bool real_node = 3u * n - bodyU[kStepUCount * body + kStepUDofBegin] < bodyU[kStepUCount * body + kStepUDofs];
  real s[8];
  for (uint k = 0u; k < 8u; ++k) s[k] = real(0);
  if (pc.mode == kStepBegin) {
    if (real_node)
      for (uint c = 0u; c < 3u; ++c) begin_dof(3u * n + c);
  } else if (pc.mode == kStepPositions) {
    if (real_node)
      for (uint c = 0u; c < 3u; ++c) positions_dof(3u * n + c);
  } else if (pc.mode == kStepDamping) {
    if (real_node)
      for (uint c = 0u; c < 3u; ++c) {
        const uint d = 3u * n + c;
        const real alpha = body_real(kStepRAlpha);  /* 0: no damping, Cv = 0 whatever v holds (the host's) */
        vecs[scratch_at(kCv, d)] =
            alpha == real(0) ? real(0) : alpha * (input_of(kStepInMass, d) * vecs[state_at(bodyU[kStepUCount * body + kStepUFrom], kV, d)]);
      }
  } else {
    /* The passes with sums: each invocation's three dofs in order, then the work-group's tree. */
    if (real_node)
      for (uint c = 0u; c < 3u; ++c) {
        if (pc.mode == kStepResidual) residual_dof(3u * n + c, s);
        else if (pc.mode == kStepUpdate) update_dof(3u * n + c, s);
        else end_dof(3u * n + c, s);
      }
    for (uint k = 0u; k < 7u; ++k) sums[k][lid] = s[k];
    write_sums(7u);
  }
}
