// The plan of a body: where it runs, which terms and kernels its step needs, the buffers those
// need and an estimate of the bytes moved per step. Everything is estimated on the host from the
// Problem and the SolverDesc (the backends expose no introspection); the model is stated in the
// "bytes_model" field and in docs/scene-format.md.
//
// What the step requires (and so what the plan lists):
//   stiffness K_t            always
//   rotations R_e            co-rotational formulation only (linear: R = I, hyperelastic: F)
//   lumped mass M            dynamics only (statics solve K_t dx = -r)
//   damping C = aM + bK_t    dynamics with Rayleigh alpha or beta > 0
//   velocities, accelerations  dynamics only (host driver state)
//   preconditioner blocks    PCG with a preconditioner
//   surface update           bodies with a render surface
//
// Device buffers: the backend's own list where its registry entry gives one (BackendEntry::buffers:
// the Vulkan backend), else the buffer layout of the OpenCL backend (sizes from kernels/shared/corofem_layout.h: 4 node indices,
// 10 geometry reals (9 gradients + volume), 9 rotated-gradient reals (co-rotational), 9 rotation
// and 4 quaternion reals (Quaternion method), 12 element-output reals per element; 6 node-block
// reals per node) and of the
// reference backend (CSR matrix with 9 entries per node pair that shares an element).
//
// Bytes model (r = bytes per real: 8 double, 4 float; D = 3 N dofs; E elements):
//   OpenCL product q = A p: element pass E (16 + (10 + 12 + 12) r) [node ids, gradients + volume or
//     rotated gradients, p at the corners, element output], gather pass 16 E + 4 (N + 1) + 12 E r
//     + D r (p, q, free mask, + mass when the mass term is in use).
//   PCG iteration: one product + the vector updates (x, r, z, p, q, preconditioner) ~ 12 D r + 3 N
//     (or 9 N block) r.
//   Newton iteration without PCG: rotations E (16 + 22 r) (co-rotational only) + internal forces
//     (one product) + PCG set-up (one product) + host transfers 5 D r (positions, b, x both ways,
//     forces).
//   Reference product: the CSR matrix (nnz (8 + 4) + 4 (D + 1)) + 3 D 8; per Newton iteration the
//     assembly writes the matrix once and reads 144 8 bytes per element.
//   Upper bound per step = Newton iterations (dynamics: the scene's count; statics: the cap) x
//   (Newton iteration + PCG iteration cap x PCG iteration). Real steps stop PCG far earlier; the
//   per-iteration figures are the useful ones.
#include "device/registry.hpp"
#include "schedule/scheduler.hpp"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <set>
#include <utility>

namespace corofem::detail {

namespace {

using nlohmann::json;

/// The "warped_cholesky" factor's entries per entry of the system (its fill), as measured on the
/// 12,960-tet beam; larger meshes fill more.
constexpr double kWarpedFill = 4.2;

/// Distinct node pairs that share an element (the off-diagonal 3x3 blocks of K).
std::size_t edgeCount(const TetMesh& mesh) {
  std::set<std::pair<std::uint32_t, std::uint32_t>> edges;
  for (std::size_t e = 0; e < mesh.tetCount(); ++e)
    for (int i = 0; i < 4; ++i)
      for (int j = i + 1; j < 4; ++j) {
        std::uint32_t a = mesh.tets[4 * e + i], b = mesh.tets[4 * e + j];
        if (a > b) std::swap(a, b);
        edges.insert({a, b});
      }
  return edges.size();
}

}  // namespace

std::string planJson(const BodyDesc& desc, const Problem& problem, const Scene& scene, const BodySchedule& schedule,
                     const std::vector<std::string>& batchMates) {
  const bool dynamic = scene.analysis.kind == AnalysisDesc::Kind::Dynamic;
  const bool corot = problem.formulation == Formulation::Corotational;
  const bool hyper = problem.formulation == Formulation::StVenantKirchhoff || problem.formulation == Formulation::NeoHookean;
  const bool damping = dynamic && (problem.rayleighMass > 0 || problem.rayleighStiffness > 0);
  const bool pcg = scene.solver.linearSolver == LinearSolverKind::Pcg;
  const PreconditionerKind preconditioner = preconditionerOf(scene.solver, problem);
  const bool precond = pcg && preconditioner != PreconditionerKind::None;
  const bool amg = pcg && preconditioner == PreconditionerKind::Amg;
  const bool warped = pcg && preconditioner == PreconditionerKind::WarpedCholesky;  // reference and OpenCL
  // amg smooths with the node blocks' inverses: the block preconditioner's data on a device.
  const bool block = preconditioner == PreconditionerKind::BlockDiagonal || amg;
  // The multigrid's levels (precond/amg.hpp) per free dof of the body, as the Vega beam of
  // bench_precond (12,960 tets) has them: P_0 and P_0^T 21 entries each, the level-1 operator 17,
  // the coarser ones about 1; each entry a real and a 4-byte column (the coarsest inverse aside).
  const double amgEntriesPerDof = 2 * 21 + 17 + 1;
  const Candidate& c = schedule.choice();
  const bool device = c.backend != "reference";
  const double r = device && scene.solver.precision == Precision::Float ? 4.0 : 8.0;
  const double E = static_cast<double>(problem.elements.size());
  const double N = static_cast<double>(problem.mesh.nodeCount());
  const double D = 3.0 * N;

  json j;
  j["body"] = desc.name;
  j["backend"] = c.backend;
  j["device"] = c.device;
  j["choice"] = c.label();
  j["reason"] = schedule.reason;
  j["elements"] = problem.elements.size();
  j["nodes"] = problem.mesh.nodeCount();

  json f;
  f["formulation"] = toString(problem.formulation);
  if (corot)
    f["rotation_method"] = device ? toString(problem.rotation) : "polar (the reference backend computes every method as the polar decomposition)";
  f["precision"] = device ? (scene.solver.precision == Precision::Float ? "float" : "double") : "double";
  f["analysis"] = dynamic ? "dynamic" : "static";
  if (dynamic) f["integrator"] = integratorOf(scene.analysis.dynamics) == Integrator::Newmark ? "newmark" : "backward_euler";
  f["linear_solver"] = pcg ? "pcg" : "cholesky";
  if (pcg) {
    f["preconditioner"] = toString(preconditioner);
    if (scene.solver.preconditioner == PreconditionerKind::Auto) f["preconditioner_chosen_by"] = "auto";
  }
  f["mass_terms"] = dynamic;
  f["damping"] = damping;
  f["surface_update"] = !desc.surface.empty();
  f["prescribed_displacements"] = !problem.prescribed.empty();
  // Batching (solve/driver.hpp): the bodies of one device share its buffers and every launch;
  // the buffers and bytes below are this body's share (its segment of the shared buffers).
  const bool batched = batchMates.size() >= 2;
  if (batched) {
    std::string names;
    for (const std::string& n : batchMates) names += (names.empty() ? "" : ", ") + n;
    f["shared_launches"] = device ? "one launch sequence for " + std::to_string(batchMates.size()) + " bodies: " + names
                                  : "one call per operation for " + std::to_string(batchMates.size()) +
                                        " bodies, run across the host's threads: " + names;
    j["shared_launches"] = batchMates;
  } else {
    f["shared_launches"] = false;
  }
  json terms = json::array({"stiffness K_t"});
  if (dynamic) terms.push_back("lumped mass M");
  if (damping) terms.push_back("Rayleigh damping C = alpha M + beta K_t");
  j["terms"] = terms;
  j["features"] = f;

  json kernels = json::array();
  json buffers = json::array();
  auto buffer = [&](const std::string& name, const std::string& where, double bytes) {
    buffers.push_back({{"name", name}, {"where", where}, {"bytes", static_cast<long long>(bytes)}});
  };
  double product = 0, pcgIter = 0, newtonFixed = 0;
  // The backend names its own passes and buffers (BackendEntry::passes, ::buffers); else they are
  // named generically, the buffers as the OpenCL backend lays them out.
  PlanPasses step;
  step.corotational = corot;
  step.rotation = problem.rotation;
  step.dynamic = dynamic;
  step.damping = damping;
  step.preconditioner = pcg ? preconditioner : PreconditionerKind::None;
  const std::shared_ptr<const BackendEntry> entry = device ? findBackend(c.backend) : nullptr;
  if (device && entry && entry->buffers) {
    for (const PlanBuffer& b : entry->buffers(step, PlanSizes{E, N, r, amgEntriesPerDof})) buffer(b.name, "device", b.bytes);
  } else if (device) {
    const std::string dv = "device";
    buffer("element_nodes", dv, 16 * E);
    buffer("element_geometry", dv, 10 * E * r);
    if (corot) {
      // R itself only for the Quaternion method (every pass writes it: a pass cannot be run again
      // to read it back, it advances the warm start) and for "warped_cholesky" (its warp reads R
      // before every solve); the other kernels read a_i.
      if (problem.rotation == RotationMethod::Quaternion || warped) buffer("rotations", dv, 9 * E * r);
      if (problem.rotation == RotationMethod::Quaternion) buffer("quaternions", dv, 4 * E * r);
      buffer("rotated_gradients", dv, 9 * E * r);
    }
    buffer("element_output", dv, 12 * E * r);
    buffer("gather_lists", dv, 4 * (N + 1) + 16 * E);
    buffer("positions", dv, D * r);
    buffer("free_mask", dv, D * r);
    if (dynamic) buffer("lumped_mass", dv, D * r);
    if (precond && !warped) {  // warped_cholesky: the factor on the host
      buffer("node_blocks", dv, 6 * N * r);
      buffer("preconditioner_inverse", dv, (block ? 9 : 3) * N * r);
    }
    buffer("pcg_vectors (x b r u p w s)", dv, 7 * D * r);
    if (amg) {
      buffer("amg_levels (estimate: prolongations, coarse operators)", dv, amgEntriesPerDof * D * (r + 4));
      buffer("amg_vectors (level 0 scratch)", dv, 3 * D * r);
    }
  }
  // The factor's fill is known only once it is made: kWarpedFill times A's entries on the 12,960-tet
  // beam (1.41 M below the diagonal), and it grows faster than the mesh. K_0 is kept beside it, and
  // after a grab or a new time step the factor before it (the spare) too. A device backend keeps
  // them on the host too (device/device_warped.hpp).
  const double warpedEntries = warped ? 9 * (N + 2 * static_cast<double>(edgeCount(problem.mesh))) : 0.0;
  if (warped) {
    buffer("warped_cholesky_factor (estimate: 4.2x the system's entries, more on larger meshes; twice after a grab)",
           "host", kWarpedFill * warpedEntries * 12);
    buffer("rest_stiffness (K_0, kept)", "host", warpedEntries * 12);
  }
  if (device) {
    if (entry && entry->passes) {
      for (const std::string& k : entry->passes(step)) kernels.push_back(k);
    } else {
      if (corot) kernels.push_back(std::string("rotations (") + toString(problem.rotation) + ")");
      kernels.push_back("internal forces");
      kernels.push_back(std::string("matrix-free product of ") +
                        (dynamic ? (damping ? "M, C, K_t" : "M, K_t") : "K_t"));
      kernels.push_back("single-reduction PCG");
    }
    if (warped)
      kernels.push_back("warped_cholesky on the host's threads per PCG iteration: r read, the warp and the factor's two "
                        "triangular solves, z written");
    if (batched)
      for (auto& k : kernels)
        k = k.get<std::string>() + " [shared: one launch for the " + std::to_string(batchMates.size()) + " bodies]";
    product = E * (16 + 34 * r) + 16 * E + 4 * (N + 1) + 12 * E * r + D * r * (3 + (dynamic ? 1 : 0));
    pcgIter = product + 11 * D * r + (precond && !warped ? (block ? 9 : 3) * N * r : 0);
    // r read and z written; on the host the factor read twice and its vectors (as the reference's)
    if (warped) pcgIter += 2 * D * r + 2 * kWarpedFill * warpedEntries * 12 + 6 * D * 8;
    if (amg) pcgIter += 4 * product + 12 * D * r + (amgEntriesPerDof + 3 * 17) * D * (r + 4);
    newtonFixed = (corot ? E * (16 + 22 * r) : 0) + 2 * product + 5 * D * r;
  } else {
    const double nnz = 9 * (N + 2 * static_cast<double>(edgeCount(problem.mesh)));
    const std::string h = "host";
    buffer(dynamic ? "system_matrix (CSR: M, C, K_t combined)" : "stiffness_matrix (CSR)", h, nnz * 12 + 4 * (D + 1));
    if (corot) buffer("rotations", h, 9 * E * 8);
    if (hyper) buffer("deformation_gradients", h, 9 * E * 8);
    if (dynamic) buffer("lumped_mass", h, D * 8);
    buffer(pcg ? "cg_vectors" : "cholesky_factor (at least the matrix)", h, pcg ? 5 * D * 8 : nnz * 12);
    if (amg) buffer("amg_levels (estimate: prolongations, coarse operators)", h, amgEntriesPerDof * D * 12);
    if (corot) kernels.push_back("polar decomposition per element (Newton's iteration, the SVD where F is inverted or flat)");
    kernels.push_back("element forces");
    kernels.push_back("sparse assembly of " + std::string(dynamic ? "M + C + K_t" : "K_t"));
    kernels.push_back(pcg ? "single-reduction PCG" : "Eigen SimplicialLDLT");
    if (amg) kernels.push_back("amg V-cycle per iteration (4 products of the assembled matrix, the coarse levels)");
    if (warped) kernels.push_back("warped Cholesky per iteration (node rotations, two triangular solves of the rest factor)");
    product = nnz * 12 + 4 * (D + 1) + 3 * D * 8;
    pcgIter = product + 10 * D * 8;
    if (amg) pcgIter += 4 * product + 12 * D * 8 + (amgEntriesPerDof + 3 * 17) * D * 12;
    if (warped) pcgIter += 2 * kWarpedFill * warpedEntries * 12 + 6 * D * 8;  // the factor read twice
    newtonFixed = nnz * 8 + 144 * 8 * E + product;
  }
  // Driver state on the host (BodySolver): committed and rollback copies.
  buffer("state: positions (+ rollback)", "host", 2 * D * 8);
  if (dynamic) buffer("state: velocities, accelerations (+ rollback)", "host", 4 * D * 8);
  if (!desc.surface.empty())
    kernels.push_back(device ? std::string("surface positions + normals (on the device, ") +
                                   toString(desc.surfaceLayout) + " output; see \"surface\")"
                             : std::string("surface update (barycentric, host, on request)"));
  j["kernels"] = kernels;
  j["buffers"] = buffers;
  double total = 0;
  for (const json& b : buffers) total += b["bytes"].get<double>();
  j["buffer_bytes_total"] = static_cast<long long>(total);

  const int newton = dynamic ? std::max(1, scene.analysis.dynamics.newtonIterations)
                             : std::max(1, scene.analysis.statics.maxNewtonIterations);
  const int cap = pcg ? std::max(1, scene.solver.maxIterations) : 0;
  json bytes;
  bytes["per_product"] = static_cast<long long>(product);
  bytes["per_pcg_iteration"] = static_cast<long long>(pcg ? pcgIter : 0);
  bytes["per_newton_iteration_without_pcg"] = static_cast<long long>(newtonFixed);
  bytes["newton_iterations"] = newton;
  bytes["newton_iterations_is"] = dynamic ? "the scene's count" : "the cap (statics stop earlier)";
  bytes["pcg_iteration_cap"] = cap;
  bytes["per_step_upper_bound"] = static_cast<long long>(newton * (newtonFixed + cap * (pcg ? pcgIter : 0.0)));
  bytes["model"] = "bytes per step <= Newton iterations x (per_newton_iteration_without_pcg + pcg_iteration_cap x "
                   "per_pcg_iteration); per product: element pass + gather (see schedule/plan.cpp); r = " +
                   std::to_string(static_cast<int>(r)) + " bytes per real";
  j["bytes_moved"] = bytes;
  return j.dump();
}

}  // namespace corofem::detail
