#version 450
/* The dynamics driver's per-dof passes on a device's step store (host/src/backends/vulkan/
 * vulkan_step_store.cpp; their meaning and the host's own version: host/src/solve/step_store.hpp
 * and host_step_store.cpp), one invocation per dof, pc.mode choosing the pass:
 *   kModeBegin      vb, xb, the constrained dofs' targets, f_ext(t1), Newton's starting v, Cv = 0
 *   kModePositions  x = xb + kx v, a = ka (v - vb)
 *   kModeResidual   r = M a + C v + f_int + S (x - t) - f_ext, rhs = -r / ka
 *   kModeUpdate     v += dv
 *   kModeEnd        the reactions, the springs' pull joining f_ext, the work sums
 *   kModeDamping    Cv = alpha M v of the state kUFrom names (mass damping alone; alpha 0: none)
 * Each work-group of 64 dofs belongs to one body (the device's segments are whole node work-groups,
 * 192 dofs); it writes its sums (the host adds a body's work-groups in order, in double) to
 * partials[8 g + k], a tree over its invocations: the same bits for a body alone or in a set.
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

layout(std430, binding = 0) readonly buffer WgBody { uint wgBody[]; };   /* per work-group: its body, or ~0 */
layout(std430, binding = 1) readonly buffer BodyU { uint bodyU[]; };     /* kU* per body */
layout(std430, binding = 2) readonly buffer BodyR { real bodyR[]; };     /* pc.o3 per body: kR*, scales */
layout(std430, binding = 3) buffer Vecs { real vecs[]; };                /* 28 vectors of D */
layout(std430, binding = 4) readonly buffer Inputs { real inp[]; };      /* kIn* vectors of D */
layout(std430, binding = 5) readonly buffer Loads { real loads[]; };     /* pc.o1 load patterns of D */
layout(std430, binding = 6) readonly buffer Presc { uint presc[]; };     /* per dof: its prescribed group, or ~0 */
layout(std430, binding = 7) writeonly buffer Partials { real partials[]; };  /* 8 per work-group */

layout(push_constant) uniform Push {
  uint S, mode, flags, precond, rotation, rows;  /* common.glsl's; mode: kMode* below */
  uint o0, o1, o2, o3, o4, o5;                   /* D, load patterns, prescribed groups, reals per body */
} pc;

const uint kModeBegin = 0u, kModePositions = 1u, kModeResidual = 2u, kModeUpdate = 3u, kModeEnd = 4u,
           kModeDamping = 5u;
/* Per body (uint): running, first dof, dofs, the physical state of each StateSlot, the state the
 * held targets start from, kU* flags. */
const uint kUActive = 0u, kUDofBegin = 1u, kUDofs = 2u, kUSlot = 3u, kUFrom = 7u, kUFlags = 8u, kUCount = 12u;
const uint kFlagNewmark = 1u, kFlagSprings = 2u, kFlagApplied = 4u, kFlagHeld = 8u;
/* Per body (real): the scheme's maps, the held targets' fraction, the mass damping's alpha, then the
 * load scales (pc.o1) and the prescribed groups' scales (pc.o2). */
const uint kRH = 0u, kRKa = 1u, kRKx = 2u, kRCv = 3u, kRCa = 4u, kRFraction = 5u, kRAlpha = 6u, kRCount = 7u;
/* The state vectors and the scratch (solve/step_store.hpp's StateVec and Scratch). */
const uint kX = 0u, kV = 1u, kA = 2u, kFext = 3u, kReaction = 4u;
const uint kVb = 0u, kXb = 1u, kTarget = 2u, kFint = 3u, kCv = 4u, kR = 5u, kDv = 6u, kRhs = 7u;
const uint kCommitted = 0u, kResult = 3u;
/* The inputs per dof. */
const uint kInRest = 0u, kInMass = 1u, kInFree = 2u, kInSpring = 3u, kInHeld = 4u, kInApplied = 5u,
           kInSpringTarget = 6u, kInPresc = 7u;

shared real sums[8][64];

uint body;

uint state_at(uint slot, uint v, uint d) { return (5u * bodyU[kUCount * body + kUSlot + slot] + v) * pc.o0 + d; }
uint scratch_at(uint k, uint d) { return (20u + k) * pc.o0 + d; }
real input_of(uint k, uint d) { return inp[k * pc.o0 + d]; }
real body_real(uint k) { return bodyR[pc.o3 * body + k]; }
bool body_flag(uint f) { return (bodyU[kUCount * body + kUFlags] & f) != 0u; }
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

void main() {
  body = wgBody[gl_WorkGroupID.x];
  if (body == 0xFFFFFFFFu || bodyU[kUCount * body + kUActive] == 0u) return;  /* the whole work-group */
  const uint lid = gl_LocalInvocationID.x;
  const uint d = 64u * gl_WorkGroupID.x + lid;
  const bool real_dof = d - bodyU[kUCount * body + kUDofBegin] < bodyU[kUCount * body + kUDofs];
  for (uint k = 0u; k < 8u; ++k) sums[k][lid] = real(0);
  const real ka = body_real(kRKa), kx = body_real(kRKx);

  if (pc.mode == kModeBegin) {
    if (real_dof) {
      const bool newmark = body_flag(kFlagNewmark);
      const real x = vecs[state_at(kCommitted, kX, d)], v = vecs[state_at(kCommitted, kV, d)];
      const real a = vecs[state_at(kCommitted, kA, d)];
      const real vb = newmark ? v + body_real(kRCv) * a : v;
      const real xb = newmark ? x + body_real(kRH) * v + body_real(kRCa) * a - kx * vb : x;
      vecs[scratch_at(kVb, d)] = vb;
      vecs[scratch_at(kXb, d)] = xb;
      const real free_d = input_of(kInFree, d);
      /* The targets: constrained dofs at rest or prescribed (the last group on the dof), then the
       * application's held ones (NaN: not held), in proportion from the state kUFrom names. */
      real target = vecs[scratch_at(kTarget, d)];
      if (free_d == real(0)) target = input_of(kInRest, d);
      const uint g = presc[d];
      if (g != 0xFFFFFFFFu) target = input_of(kInRest, d) + body_real(kRCount + pc.o1 + g) * input_of(kInPresc, d);
      if (body_flag(kFlagHeld)) {
        const real held = input_of(kInHeld, d);
        if (!isnan(held)) {
          const real fraction = body_real(kRFraction);
          const real x0 = vecs[state_at(bodyU[kUCount * body + kUFrom], kX, d)];
          target = fraction == real(1) ? held : x0 + fraction * (held - x0);
        }
      }
      vecs[scratch_at(kTarget, d)] = target;
      real f = real(0);
      for (uint l = 0u; l < pc.o1; ++l) f += body_real(kRCount + l) * loads[l * pc.o0 + d];
      if (body_flag(kFlagApplied)) f += input_of(kInApplied, d);
      vecs[state_at(kResult, kFext, d)] = f;
      const real ff = f * free_d;
      sums[0][lid] = ff * ff;
      vecs[state_at(kResult, kV, d)] = free_d == real(0) ? (target - xb) / kx : v;
      vecs[scratch_at(kCv, d)] = real(0);
    }
    write_sums(1u);
  } else if (pc.mode == kModePositions) {
    if (real_dof) {
      const real v = vecs[state_at(kResult, kV, d)];
      vecs[state_at(kResult, kX, d)] = vecs[scratch_at(kXb, d)] + kx * v;
      vecs[state_at(kResult, kA, d)] = ka * (v - vecs[scratch_at(kVb, d)]);
    }
  } else if (pc.mode == kModeResidual) {
    if (real_dof) {
      const real x = vecs[state_at(kResult, kX, d)], v = vecs[state_at(kResult, kV, d)];
      const real a = vecs[state_at(kResult, kA, d)];
      const real ma = input_of(kInMass, d) * a;
      const real k = input_of(kInSpring, d);
      const real spring = body_flag(kFlagSprings) && k != real(0) ? k * (x - input_of(kInSpringTarget, d)) : real(0);
      const real cv = vecs[scratch_at(kCv, d)], fint = vecs[scratch_at(kFint, d)];
      const real r = ma + cv + fint + spring - vecs[state_at(kResult, kFext, d)];
      vecs[scratch_at(kR, d)] = r;
      vecs[scratch_at(kRhs, d)] = -r / ka;
      const real f = input_of(kInFree, d);
      const real maf = ma * f, cvf = cv * f, fintf = fint * f, sf = spring * f, rf = r * f;
      sums[0][lid] = maf * maf;
      sums[1][lid] = cvf * cvf;
      sums[2][lid] = fintf * fintf;
      sums[3][lid] = sf * sf;
      sums[4][lid] = rf * rf;
      sums[5][lid] = not_finite(x) || not_finite(v) || not_finite(a) ? real(1) : real(0);
    }
    write_sums(6u);
  } else if (pc.mode == kModeUpdate) {
    if (real_dof) {
      const real dv = vecs[scratch_at(kDv, d)];
      sums[0][lid] = not_finite(dv) ? real(1) : real(0);
      vecs[state_at(kResult, kV, d)] += dv;
    }
    write_sums(1u);
  } else if (pc.mode == kModeEnd) {
    if (real_dof) {
      const real free_d = input_of(kInFree, d);
      const real rd = vecs[scratch_at(kR, d)] * (real(1) - free_d);
      vecs[state_at(kResult, kReaction, d)] = rd;
      const real x = vecs[state_at(kResult, kX, d)];
      const real k = input_of(kInSpring, d);
      real f = vecs[state_at(kResult, kFext, d)];
      if (body_flag(kFlagSprings) && k != real(0) && free_d != real(0)) {
        f += k * (input_of(kInSpringTarget, d) - x);
        vecs[state_at(kResult, kFext, d)] = f;
      }
      const real dx = x - vecs[state_at(kCommitted, kX, d)];
      const real fPrev = vecs[state_at(kCommitted, kFext, d)], rPrev = vecs[state_at(kCommitted, kReaction, d)];
      const real v = vecs[state_at(kResult, kV, d)];
      sums[0][lid] = (rPrev + rd) * dx;
      sums[1][lid] = (fPrev + f) * dx;
      sums[2][lid] = rPrev * dx;
      sums[3][lid] = rd * dx;
      sums[4][lid] = fPrev * dx;
      sums[5][lid] = f * dx;
      sums[6][lid] = input_of(kInMass, d) * (v * v);
    }
    write_sums(7u);
  } else if (pc.mode == kModeDamping) {
    if (real_dof)
      vecs[scratch_at(kCv, d)] = body_real(kRAlpha) * (input_of(kInMass, d) * vecs[state_at(bodyU[kUCount * body + kUFrom], kV, d)]);
  }
}
