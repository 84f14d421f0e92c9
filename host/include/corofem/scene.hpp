// Scene description: what to simulate. Filled from a JSON scene file (docs/scene-format.md) or
// directly by an embedding application. Units are SI unless a field says otherwise.
#pragma once

#include <corofem/mesh.hpp>
#include <corofem/status.hpp>

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace corofem {

using Vec3 = std::array<double, 3>;

/// A set of mesh nodes, chosen geometrically or listed.
struct NodeSetDesc {
  enum class Kind { Box, Plane, List, BouFile };
  Kind kind = Kind::Box;
  Vec3 boxMin{0, 0, 0}, boxMax{0, 0, 0};  ///< Box: nodes with min <= x <= max on every axis (m)
  Vec3 planePoint{0, 0, 0};               ///< Plane: a point on the plane (m)
  Vec3 planeNormal{1, 0, 0};              ///< Plane: normal (need not be unit, must be non-zero)
  double planeTolerance = 1e-9;           ///< Plane: nodes with |distance| <= tolerance (m), >= 0
  std::vector<std::uint32_t> indices;     ///< List: 0-based node indices
  std::string bouFile;                    ///< BouFile: Vega .bou file (1-based ids), path as given
};

/// Material of a body (isotropic, linear elastic in the co-rotated frame).
struct MaterialDesc {
  double youngsModulus = 1e5;   ///< E in Pa, > 0
  double poissonRatio = 0.3;    ///< nu, -1 < nu < 0.5
  double density = 1000.0;      ///< rho in kg/m^3, > 0
  double rayleighMass = 0.0;    ///< alpha in C = alpha M + beta K, 1/s, >= 0
  double rayleighStiffness = 0.0;///< beta in C = alpha M + beta K, s, >= 0
};

enum class Formulation {
  Linear,             ///< small-displacement linear elasticity (R = I)
  Corotational,       ///< the paper's simplified co-rotational formulation (default)
  StVenantKirchhoff,  ///< total-Lagrangian St. Venant-Kirchhoff (reference backend only)
  NeoHookean,         ///< compressible Neo-Hookean (reference backend only)
};

/// Where a body's mesh comes from: a file or the box generator (exactly one).
struct MeshSourceDesc {
  std::string file;            ///< mesh file, resolved relative to the scene file's folder
  std::optional<BoxSpec> box;  ///< generated box when set
  /// A mesh the application holds in memory (API only; a scene file cannot name one), checked as a
  /// file's is (indices, repeated nodes, finite coordinates, zero volume) and reoriented where an
  /// element is inverted (MeshReadReport::reorientedElements). Exactly one of file, box and mesh.
  std::shared_ptr<const TetMesh> mesh;
  double scale = 1.0;          ///< multiplies node coordinates after loading, > 0
  Vec3 translate{0, 0, 0};     ///< added to node coordinates after scaling (m)
};

/// A load on a body.
struct LoadDesc {
  enum class Kind {
    Gravity,       ///< body force rho * vector on every element (m/s^2)
    Force,         ///< total force `vector` (N) spread equally over the nodes of `nodes`
    Displacement,  ///< prescribed displacement `vector` (m) of the nodes of `nodes` (a dragged handle)
  };
  Kind kind = Kind::Gravity;
  Vec3 vector{0, -9.81, 0};
  NodeSetDesc nodes;      ///< Force, Displacement: where
  double rampTime = 0.0;  ///< dynamics: the load grows linearly from 0 over this time (s), >= 0
};

/// How a body's render surface is laid out in its device buffer (OpenCL backend): one buffer of 6
/// float32 per vertex (position, normal), or two buffers of 3 (positions, normals) for renderers
/// that bind them as separate vertex streams. The same values either way, bit for bit.
enum class SurfaceLayout { Interleaved, Separate };

/// One deformable body.
struct BodyDesc {
  std::string name = "body";
  MeshSourceDesc mesh;
  MaterialDesc material;
  Formulation formulation = Formulation::Corotational;
  std::vector<NodeSetDesc> fixed;  ///< nodes held at their rest position
  std::vector<LoadDesc> loads;
  Vec3 initialVelocity{0, 0, 0};          ///< m/s, dynamics only
  Vec3 initialAngularVelocity{0, 0, 0};   ///< rad/s about the body's rest centroid, dynamics only
  std::string surface;                    ///< optional render surface (.obj) driven by the body
  SurfaceLayout surfaceLayout = SurfaceLayout::Interleaved;  ///< the surface's device buffers (no effect on the host path)
};

struct StaticDesc {
  int increments = 1;             ///< load increments (full load in one step by default), >= 1
  int maxNewtonIterations = 30;   ///< per increment, >= 1
  double residualTolerance = 1e-6;   ///< |f_ext - f_int| <= tol * max(|f_ext|, |f_int|, tiny)
  double displacementTolerance = 1e-8; ///< |du| <= tol * max(|u|, characteristic length)
};

/// Auto: Newmark (the paper's scheme) for an analysis with a step count, backward Euler for an
/// open-ended one (analysis.steps = 0: an application's frame loop), which stays stable under
/// abruptly dragged handles where the linearised Newmark step runs away (bench/bench_soak.cpp).
enum class Integrator { Newmark, BackwardEuler, Auto };

/// Bodies at rest sleep (analysis.sleep, dynamics): after `steps` consecutive steps with every free
/// node slower than `velocity` and loads steady, a body's solve is skipped (positions held,
/// velocities zero) until its loads or prescribed displacements move away from where they were
/// when it fell asleep. See docs/scene-format.md.
struct SleepDesc {
  bool enabled = false;
  double velocity = 1e-4;    ///< m/s, > 0: largest free-node speed of a quiet step
  double loadChange = 1e-6;  ///< > 0: relative change |f(t) - f_ref| / |f_ref| of the external load that counts as a change
  int steps = 10;            ///< >= 1: quiet steps before the body sleeps
};

struct DynamicDesc {
  Integrator integrator = Integrator::Auto;
  double timeStep = 1.0 / 60.0;  ///< s, > 0
  int steps = 100;               ///< >= 1, or 0: open-ended (the application steps until it stops)
  double newmarkBeta = 0.25;     ///< 0 < beta <= 0.5
  double newmarkGamma = 0.5;     ///< 0.5 <= gamma <= 1
  int newtonIterations = 1;      ///< Newton iterations per step (1 = linearised, as in the paper), >= 1
  double newtonTolerance = 1e-6; ///< relative residual that ends the Newton loop early
  int maxSubsteps = 1;           ///< a failed step is retried as 2, 4, ... substeps of timeStep/k, k <= this (1 = no retry), >= 1
  SleepDesc sleep;               ///< bodies at rest skip their solve (off by default)
};

/// The scheme a dynamic analysis runs: its integrator, with Auto resolved.
inline Integrator integratorOf(const DynamicDesc& d) {
  if (d.integrator != Integrator::Auto) return d.integrator;
  return d.steps > 0 ? Integrator::Newmark : Integrator::BackwardEuler;
}

struct AnalysisDesc {
  enum class Kind { Static, Dynamic };
  Kind kind = Kind::Dynamic;
  StaticDesc statics;
  DynamicDesc dynamics;
};

enum class LinearSolverKind { Pcg, Cholesky };  ///< Cholesky only on the reference backend
/// Amg: smoothed-aggregation multigrid over the rest operator, warped by the rotations of node aggregates.
/// WarpedCholesky: the rest operator factored once (sparse LDL^T), applied turned by per-node
/// rotations; reference backend only.
/// Auto (the default): per body, Amg where it was measured faster, Diagonal elsewhere
/// (preconditionerOf).
enum class PreconditionerKind { None, Diagonal, BlockDiagonal, Amg, WarpedCholesky, Auto };
/// Floating-point precision of a device backend (the reference backend always computes in double).
enum class Precision {
  Double,  ///< everything in double (needs cl_khr_fp64)
  Float,   ///< everything in float
  Mixed    ///< float vectors, element data and products; PCG dot products and scalars in double (needs cl_khr_fp64)
};
enum class RotationMethod { Polar, Svd, Quaternion, Qr };

struct SolverDesc {
  LinearSolverKind linearSolver = LinearSolverKind::Pcg;
  double tolerance = 1e-6;        ///< PCG relative residual |r| / |b|, > 0
  int maxIterations = 1000;       ///< PCG iteration cap, >= 1
  int checkEvery = 4;             ///< device backends: host read of the PCG state every k iterations (the device stops at convergence itself), >= 1
  PreconditionerKind preconditioner = PreconditionerKind::Auto;
  Precision precision = Precision::Double;
  RotationMethod rotation = RotationMethod::Polar;
};

/// "auto" gives "amg" to bodies of at least this many elements ... (docs/performance.md, "The
/// default preconditioner": on PoCL "amg" was 1.2x slower on a 1,620-tet beam and 2.5x slower on
/// 20 batched 2,000-tet cantilevers, where its cycle's launches cost more than the diagonal's extra
/// iterations, and 1.7-3x faster from 3,840 tets up on slender beams) ...
constexpr std::size_t kAutoAmgElements = 3000;
/// ... that are at least this slender: the longest extent L of the rest bounding box over the
/// side sqrt(V / L) of the square section a body of volume V would have over that length. The
/// diagonal preconditioner needs hundreds of iterations for the long, soft bending of a slender
/// body (a 1 x 0.1 x 0.1 m beam: 10; "amg" 2.5x faster at 12,960 tets) and a few tens for a compact
/// one, where "amg" does not pay (the 54,985-tet Armadillo, 3.8: "amg" 2.5x slower at tolerance
/// 1e-4; a cube, 1: even).
constexpr double kAutoAmgSlenderness = 6.0;

/// The preconditioner a body of `elements` tetrahedra, slenderness `slenderness` (as above) and
/// formulation `f` gets: the solver's, with Auto resolved to Amg for co-rotational and linear
/// bodies solved by PCG with at least kAutoAmgElements elements and kAutoAmgSlenderness (the
/// rigorous hyperelastic models stiffen past the spectrum bound amg's smoothing is set from),
/// Diagonal otherwise.
inline PreconditionerKind preconditionerOf(const SolverDesc& s, std::size_t elements, double slenderness, Formulation f) {
  if (s.preconditioner != PreconditionerKind::Auto) return s.preconditioner;
  if (s.linearSolver != LinearSolverKind::Pcg) return PreconditionerKind::Diagonal;  // unused: one kind for all
  const bool corotationalOrLinear = f == Formulation::Corotational || f == Formulation::Linear;
  return corotationalOrLinear && elements >= kAutoAmgElements && slenderness >= kAutoAmgSlenderness
             ? PreconditionerKind::Amg
             : PreconditionerKind::Diagonal;
}

enum class BackendKind { Auto, Reference, OpenCL, Vulkan };

struct BackendDesc {
  BackendKind kind = BackendKind::Auto;
  std::string device;  ///< device name substring or index ("" = the scheduler's choice)
  /// Bodies scheduled on one OpenCL or Vulkan device share its buffers and kernel launches; on the
  /// reference backend they share each call, their bodies run across the host's threads.
  bool batch = true;
  /// "auto": bodies with fewer elements than this run on the reference backend without a
  /// calibration (a device launch then costs more than the whole step), >= 0.
  std::size_t minDeviceElements = 512;
};

/// A probe: the mean displacement of a node set, written to probes.csv each step/increment.
struct ProbeDesc {
  std::string name;
  std::string body;     ///< body name ("" = the first body)
  NodeSetDesc nodes;
};

struct OutputDesc {
  std::vector<ProbeDesc> probes;
  int vtkEvery = 0;        ///< write a .vtu of every body every N steps (0 = only first and last)
  bool vtk = true;         ///< write the VTK series at all
  bool surfaceObj = false; ///< write deformed surfaces as OBJ (bodies with a surface)
  /// How the .vtu files of the series store their arrays ("vtu_format": ascii, base64, raw).
  VtuFormat vtuFormat = VtuFormat::Ascii;
  /// Compression of binary .vtu arrays ("vtu_compression": none, zlib); zlib needs a build with
  /// zlib (vtuZlibAvailable()) and a binary vtuFormat.
  VtuCompression vtuCompression = VtuCompression::None;
};

struct Scene {
  std::string name = "scene";
  std::string baseDir;  ///< folder against which relative paths are resolved (the scene file's)
  std::vector<BodyDesc> bodies;
  AnalysisDesc analysis;
  SolverDesc solver;
  BackendDesc backend;
  OutputDesc output;
};

/// Parses a JSON scene. `overrides` are "key.path=value" strings (the --set option) applied to the
/// JSON before validation; arrays are indexed by number ("bodies.0.material.youngs_modulus=1e6").
/// Errors give the key's path, and for a misspelt key the nearest valid one. A "box" mesh of more
/// than limits.maxBoxTets tetrahedra is refused here already.
Result<Scene> parseScene(const std::string& jsonText, const std::string& baseDir,
                         const std::vector<std::string>& overrides = {}, const InputLimits& limits = {});
/// Reads the scene file at `path` (at most limits.maxSceneBytes) and parses it as parseScene does,
/// relative paths in it taken from the file's folder. The limits apply to the scene file only: the
/// meshes, surfaces and .bou files it names are read by Simulation::create, under
/// SimulationOptions::inputLimits.
Result<Scene> loadScene(const std::string& path, const std::vector<std::string>& overrides = {},
                        const InputLimits& limits = {});

/// The 0-based node indices a node set selects on a mesh (sorted, unique). An empty selection is
/// an error naming the set, since it is almost always a typo in a coordinate. A .bou file is read
/// under limits.maxInputBytes.
Result<std::vector<std::uint32_t>> resolveNodeSet(const NodeSetDesc& set, const TetMesh& mesh,
                                                  const std::string& baseDir = "", const InputLimits& limits = {});

/// Loads (or generates) a body's mesh, applying scale and translation, under `limits` (a mesh file:
/// maxInputBytes; a box: maxBoxTets).
Result<TetMesh> loadBodyMesh(const BodyDesc& body, const std::string& baseDir, MeshReadReport* report = nullptr,
                             const InputLimits& limits = {});

/// The scene-file spelling of each enumerator ("corotational", "block_diagonal", ...). Safe to call
/// during static initialisation (no dependence on other globals).
const char* toString(Formulation f);
const char* toString(RotationMethod m);
const char* toString(BackendKind b);
const char* toString(Precision p);
const char* toString(PreconditionerKind p);
const char* toString(SurfaceLayout l);

}  // namespace corofem
