/* The per-element and per-node operations every PCG path runs, written once so that the path of one
 * dispatch per phase (element.comp, gather.comp, pcg.comp, reduce.comp) and the path of whole
 * iterations in one work-group (pcg_group.comp) compute the same bits. Included after common.glsl.
 *
 * A product reads p from PRODUCT_IN and writes y to PRODUCT_OUT: by default the bindings vin and
 * vout, which the host points at different buffers per call. pcg_group.comp names u and w
 * themselves: it also writes u, and two bindings of one buffer may not be read and written in one
 * dispatch (SPIR-V takes distinct bindings not to alias: a compiler may keep a load of vin across
 * the barriers after a store to u). */
#ifndef PRODUCT_IN
#define PRODUCT_IN vin
#define PRODUCT_OUT vout
#endif

/* Fixed-order sums over the work-group: every invocation stores its values in s0..s3[lid], then
 * tree4() leaves the sums in s0..s3[0] (the same tree for every caller). */
shared real s0[64], s1[64], s2[64], s3[64];

void tree4() {
  const uint lid = gl_LocalInvocationID.x;
  barrier();
  for (uint h = WG / 2u; h > 0u; h >>= 1u) {
    if (lid < h) {
      s0[lid] += s0[lid + h];
      s1[lid] += s1[lid + h];
      s2[lid] += s2[lid + h];
      s3[lid] += s3[lid + h];
    }
    barrier();
  }
}

/* Element e's 12-vector V S_w a_i into elemOut (kernels/opencl/element_force.cl has the
 * derivation) from its corners' values v (3 per corner): with `forces`, f = R K (R^T x - X) from
 * the positions (E = sym(P) - I); else the product k R K R^T p_e from p (E = sym(P), lambda and mu
 * already times k). Returns the element's strain energy V/2 S_w : E (meaningful with `forces`). */
real element_pass_of(uint e, uint S, real lambda, real mu, bool forces, in real v[12]) {
  real a[9];
  for (uint k = 0u; k < 9u; ++k) a[k] = rotGrad[k * S + e];
  const real V = geom[kGeomVolume * S + e];
  const real shift = forces ? real(1) : real(0);
  real P[9];
  for (int k = 0; k < 9; ++k) P[k] = real(0);
  for (uint i = 1u; i < 4u; ++i)
    for (uint j = 0u; j < 3u; ++j) {
      const real d = v[3u * i + j] - v[j];
      for (uint k = 0u; k < 3u; ++k) P[3 * j + k] += d * a[3 * (i - 1u) + k];
    }
  const real exx = P[0] - shift, eyy = P[4] - shift, ezz = P[8] - shift;
  const real exy = real(0.5) * (P[1] + P[3]);
  const real exz = real(0.5) * (P[2] + P[6]);
  const real eyz = real(0.5) * (P[5] + P[7]);
  const real lt = lambda * (exx + eyy + ezz);
  const real m2 = real(2) * mu;
  const real sxx = V * (lt + m2 * exx), syy = V * (lt + m2 * eyy), szz = V * (lt + m2 * ezz);
  const real sxy = V * (m2 * exy), sxz = V * (m2 * exz), syz = V * (m2 * eyz);
  real y0x = real(0), y0y = real(0), y0z = real(0);
  for (uint i = 0u; i < 3u; ++i) {
    const real ax = a[3 * i], ay = a[3 * i + 1], az = a[3 * i + 2];
    const real yx = sxx * ax + sxy * ay + sxz * az;
    const real yy = sxy * ax + syy * ay + syz * az;
    const real yz = sxz * ax + syz * ay + szz * az;
    elemOut[12u * e + 3u * (i + 1u)] = yx;
    elemOut[12u * e + 3u * (i + 1u) + 1u] = yy;
    elemOut[12u * e + 3u * (i + 1u) + 2u] = yz;
    y0x -= yx;
    y0y -= yy;
    y0z -= yz;
  }
  elemOut[12u * e] = y0x;
  elemOut[12u * e + 1u] = y0y;
  elemOut[12u * e + 2u] = y0z;
  return real(0.5) * (sxx * exx + syy * eyy + szz * ezz + real(2) * (sxy * exy + sxz * exz + syz * eyz));
}

/* element_pass_of with the corner values v (3 per corner) read from the positions (`forces`) or
 * from p = PRODUCT_IN. */
real element_pass(uint e, uint S, real lambda, real mu, bool forces) {
  real v[12];
  for (uint c = 0u; c < 4u; ++c) {
    const uint n = corners[c * S + e];
    for (uint j = 0u; j < 3u; ++j) v[3u * c + j] = forces ? pos[3u * n + j] : PRODUCT_IN[3u * n + j];
  }
  return element_pass_of(e, S, lambda, mu, forces, v);
}

/* Node n's gathered element outputs (its CSR list in order). */
void gather_node(uint n, out real acc[3]) {
  acc[0] = real(0);
  acc[1] = real(0);
  acc[2] = real(0);
  const uint end = gatherStart[n + 1u];
  for (uint j = gatherStart[n]; j < end; ++j) {
    const uint at = gatherEntry[j];
    acc[0] += elemOut[at];
    acc[1] += elemOut[at + 1u];
    acc[2] += elemOut[at + 2u];
  }
}

/* (A p)_d of node n's dofs, p = PRODUCT_IN: massCoef M p + (gathered products) + k S p, with S the springs. */
void product_node(uint n, uint s, out real y[3]) {
  gather_node(n, y);
  const real massCoef = seg_coef(s, kCoefMass), springCoef = seg_coef(s, kCoefSpring);
  for (uint k = 0u; k < 3u; ++k) {
    const uint d = 3u * n + k;
    const real pd = PRODUCT_IN[d];
    if (has_flag(kFlagMass)) y[k] = massCoef * mass[d] * pd + y[k];
    if (has_flag(kFlagSprings)) y[k] += springCoef * spring[d] * pd;
  }
}

/* y = PRODUCT_OUT = A p for node n (projected with kFlagProject); returns p . y over its dofs. */
real gather_product_node(uint n, uint s) {
  real y[3];
  product_node(n, s, y);
  real py = real(0);
  for (uint k = 0u; k < 3u; ++k) {
    const uint d = 3u * n + k;
    if (has_flag(kFlagProject)) y[k] *= freeDof[d];
    PRODUCT_OUT[d] = y[k];
    py += PRODUCT_IN[d] * y[k];
  }
  return py;
}

/* z = M^-1 r for a node from its stored inverse m (row-major 3x3; the diagonal at 0, 4, 8).
 * `precise` (no fused multiply-adds of the compiler's choosing), as in pcg_update_values: the fused
 * element pass (pcg_corner_u) computes the u that the node pass stores, to the bit. */
void apply_inverse(in real m[9], in real r[3], out real z[3]) {
  precise real z0, z1, z2;
  if (pc.precond == 2u) {
    z0 = m[0] * r[0] + m[1] * r[1] + m[2] * r[2];
    z1 = m[3] * r[0] + m[4] * r[1] + m[5] * r[2];
    z2 = m[6] * r[0] + m[7] * r[1] + m[8] * r[2];
  } else {
    z0 = m[0] * r[0];
    z1 = m[4] * r[1];
    z2 = m[8] * r[2];
  }
  z[0] = z0;
  z[1] = z1;
  z[2] = z2;
}

/* The new s = w + beta s and r' = r - alpha s of dof d (PCG's update; pcg_update_node). */
void pcg_update_values(uint d, real alpha, real beta, out real sd, out real rd) {
  precise real s_ = wvec[d] + beta * svec[d];
  precise real r_ = rvec[d] - alpha * s_;
  sd = s_;
  rd = r_;
}

/* The u = M^-1 r' that pcg_update_node will store for node n, from the vectors before the update:
 * the fused element pass's product input at its corners. */
void pcg_corner_u(uint n, real alpha, real beta, out real un[3]) {
  real m[9];
  for (uint k = 0u; k < 9u; ++k) m[k] = pc.precond == 2u || k % 4u == 0u ? minv[9u * n + k] : real(0);
  real rn[3];
  for (uint k = 0u; k < 3u; ++k) {
    real sd;
    pcg_update_values(3u * n + k, alpha, beta, sd, rn[k]);
  }
  apply_inverse(m, rn, un);
}

/* PCG's vector update for node n: p = u + beta p, s = w + beta s, x += alpha p, r -= alpha s,
 * u = M^-1 r; sums[0] = r . u, sums[1] = r . r over its dofs. */
void pcg_update_node(uint n, real alpha, real beta, out real sums[2]) {
  real m[9];
  for (uint k = 0u; k < 9u; ++k) m[k] = minv[9u * n + k];
  real rn[3], un[3];
  for (uint k = 0u; k < 3u; ++k) {
    const uint d = 3u * n + k;
    const real pd = uvec[d] + beta * pvec[d];
    real sd;
    pcg_update_values(d, alpha, beta, sd, rn[k]);
    pvec[d] = pd;
    svec[d] = sd;
    xvec[d] += alpha * pd;
  }
  apply_inverse(m, rn, un);
  sums[0] = real(0);
  sums[1] = real(0);
  for (uint k = 0u; k < 3u; ++k) {
    const uint d = 3u * n + k;
    rvec[d] = rn[k];
    uvec[d] = un[k];
    sums[0] += rn[k] * un[k];
    sums[1] += rn[k] * rn[k];
  }
}

/* The sums of segment seg's partial triples (partials: r . u, r . r, b . b; partialsW: u . w) into
 * s0..s3[0]: strided lanes, then the tree. Every invocation of the work-group calls it. */
void segment_sums(uint seg) {
  const uint lid = gl_LocalInvocationID.x;
  const uint begin = 3u * seg_info(seg, kSegPartialBegin), count = seg_info(seg, kSegPartialCount);
  real a = real(0), b = real(0), c = real(0), d = real(0);
  for (uint g = lid; g < count; g += WG) {
    a += partials[begin + 3u * g];
    b += partials[begin + 3u * g + 1u];
    c += partials[begin + 3u * g + 2u];
    d += partialsW[begin + 3u * g];
  }
  s0[lid] = a;
  s1[lid] = b;
  s2[lid] = c;
  s3[lid] = d;
  tree4();
}

/* Segment seg's scalars from its sums (pcg.cl's update_scalars; the modes are kReduce*). Returns
 * why it stopped (kStop*; kStopRunning for kReduceResidual) and marks a stopped segment inactive. */
uint update_scalars(uint seg, uint mode, real gammaNew, real rr, real bbSum, real delta) {
  const uint at = kScalarCount * seg;
  if (mode == kReduceResidual) {
    scalars[at + kScalarRr] = rr;
    scalars[at + kScalarBb] = bbSum;
    return kStopRunning;
  }
  real bb = bbSum;
  if (mode == kReduceInit) {
    scalars[at + kScalarBb] = bb;
    scalars[at + kScalarIterations] = real(0);
  } else {
    bb = scalars[at + kScalarBb];
    scalars[at + kScalarIterations] += real(1);
  }
  bool breakdown = false;
  if (mode != kReduceLast) {
    real beta = real(0), pq = delta;
    if (mode == kReduceStep) {
      const real gamma = scalars[at + kScalarRho], alpha = scalars[at + kScalarAlpha];
      beta = gamma != real(0) ? gammaNew / gamma : real(0);
      pq = alpha != real(0) ? delta - beta * gammaNew / alpha : real(0);
    }
    scalars[at + kScalarBeta] = beta;
    scalars[at + kScalarPq] = pq;
    breakdown = !(pq > real(0));
    scalars[at + kScalarAlpha] = breakdown ? real(0) : gammaNew / pq;
    scalars[at + kScalarBreakdown] = breakdown ? real(1) : real(0);
  }
  scalars[at + kScalarRho] = gammaNew;
  scalars[at + kScalarRr] = rr;
  const real tol2 = scalars[at + kScalarTol2];
  const uint stop = (isnan(rr) || isinf(rr)) ? kStopNonFinite
                    : rr <= tol2 * bb        ? kStopConverged
                    : breakdown              ? kStopBreakdown
                                             : kStopRunning;
  scalars[at + kScalarStop] = real(stop);
  if (stop != kStopRunning) segInfo[kSegInfoCount * seg + kSegActive] = 0u;
  return stop;
}
