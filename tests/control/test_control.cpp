// Run-time control of a live Simulation (simulation.hpp, "Run-time control"), on every backend
// (reference double; OpenCL double and float on every device): each call is checked by the physics
// it must produce, not only by its status. A handle's nodes sit on its target (a hard constraint:
// to rounding), pinned nodes stay, released supports let the body fall freely (its momentum grows
// as M g t), applied forces change the momentum by F t, a teleport rotates the momentum and keeps the
// kinetic energy, and a batch of bodies under control steps like each body alone.
#include "extremes/extremes_support.hpp"

#include <corofem/simulation.hpp>

#include <Eigen/Geometry>
#include <Eigen/LU>
#include <nlohmann/json.hpp>
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <numeric>
#include <vector>

namespace corofem::test {
namespace {

constexpr double kH = 1.0 / 60.0;
const double kGravity[3] = {0.0, -9.81, 0.0};
const double kNoGravity[3] = {0.0, 0.0, 0.0};

/// A 0.5 x 0.1 x 0.1 m beam (E 1 MPa, 1000 kg/m^3), clamped at x = 0 when `clamped`, backward Euler
/// at 60 Hz, open-ended (analysis.steps = 0), under gravity when `gravity`.
Scene beamScene(const BackendCase& c, bool clamped, bool gravity) {
  BodyDesc body = makeBody(box({0, 0, 0}, {0.5, 0.1, 0.1}, {10, 2, 2}), 1e6, 0.3);
  if (clamped) body.fixed.push_back(planeSet(0, 0.0));
  if (gravity) {
    LoadDesc g;
    g.kind = LoadDesc::Kind::Gravity;
    g.vector = {0.0, -9.81, 0.0};
    body.loads.push_back(g);
  }
  Scene scene = dynamicScene(c, body, kH, 0);
  scene.analysis.dynamics.integrator = Integrator::BackwardEuler;
  return scene;
}

/// The options of the running case (Control's SetUp sets them).
SimulationOptions& caseOptions() {
  static SimulationOptions options;
  return options;
}

Simulation create(const Scene& scene) {
  Result<Simulation> sim = Simulation::create(scene, caseOptions());
  if (!sim) throw std::runtime_error(sim.message());
  if (caseOptions().vulkan.deviceStore == 1 && scene.analysis.kind == AnalysisDesc::Kind::Dynamic) {
    // The case runs what it says: its dynamics' vectors on the device.
    const nlohmann::json report = nlohmann::json::parse(sim->schedulerReport());
    EXPECT_GE(report.value("device_counters", nlohmann::json::object()).value("step_stores_made", 0LL), 1);
  }
  return std::move(sim.value());
}

std::vector<double> positions(const Simulation& sim, int body = 0) {
  std::vector<double> x;
  EXPECT_TRUE(sim.readPositions(body, x));
  return x;
}
std::vector<double> velocities(const Simulation& sim, int body = 0) {
  std::vector<double> v;
  EXPECT_TRUE(sim.readVelocities(body, v));
  return v;
}

/// The nodes of a mesh with coordinate `axis` within 1e-9 of `value`.
std::vector<std::uint32_t> nodesAt(const TetMesh& mesh, int axis, double value) {
  std::vector<std::uint32_t> out;
  for (std::size_t n = 0; n < mesh.nodeCount(); ++n)
    if (std::abs(mesh.nodes[3 * n + static_cast<std::size_t>(axis)] - value) < 1e-9) out.push_back(static_cast<std::uint32_t>(n));
  return out;
}

/// sum m v over the nodes (kg m/s), with the lumped mass rho V / 4 per node.
std::array<double, 3> momentum(const Simulation& sim, int body = 0) {
  const TetMesh& mesh = sim.restMesh(body);
  const double density = sim.scene().bodies[static_cast<std::size_t>(body)].material.density;
  std::vector<double> mass(mesh.nodeCount(), 0.0);
  for (std::size_t e = 0; e < mesh.tetCount(); ++e) {
    Eigen::Matrix3d D;
    for (int k = 1; k < 4; ++k)
      for (int a = 0; a < 3; ++a)
        D(a, k - 1) = mesh.nodes[3 * mesh.tets[4 * e + static_cast<std::size_t>(k)] + static_cast<std::size_t>(a)] -
                      mesh.nodes[3 * mesh.tets[4 * e] + static_cast<std::size_t>(a)];
    for (int k = 0; k < 4; ++k) mass[mesh.tets[4 * e + static_cast<std::size_t>(k)]] += density * std::abs(D.determinant()) / 24.0;
  }
  const std::vector<double> v = velocities(sim, body);
  std::array<double, 3> p{0, 0, 0};
  for (std::size_t n = 0; n < mass.size(); ++n)
    for (int a = 0; a < 3; ++a) p[static_cast<std::size_t>(a)] += mass[n] * v[3 * n + static_cast<std::size_t>(a)];
  return p;
}

/// Steps twins `frames` times each, in turns.
void stepBoth(Simulation& a, Simulation& b, int frames) {
  for (int frame = 0; frame < frames; ++frame) {
    ASSERT_TRUE(a.step(kH)) << "frame " << frame;
    ASSERT_TRUE(b.step(kH)) << "frame " << frame;
  }
}

double totalMass(const Simulation& sim) {
  const BodyDesc& b = sim.scene().bodies[0];
  return b.material.density * 0.5 * 0.1 * 0.1;
}

class Control : public ::testing::TestWithParam<BackendCase> {
 protected:
  void SetUp() override { caseOptions() = GetParam().options(); }
  void TearDown() override { caseOptions() = SimulationOptions{}; }
  /// Relative tolerance of what the linear solves decide (float devices solve to 1e-5).
  double solveTolerance() const { return GetParam().isFloat() ? 2e-3 : 1e-5; }
  /// How far from what was set a position may read back (m): 0, but float's resolution about the
  /// body's centroid where a float device keeps the state (BackendCase::deviceStore).
  double positionResolution() const { return GetParam().deviceStore && GetParam().isFloat() ? 1e-7 : 0.0; }
};

TEST_P(Control, AHandleHoldsItsNodesOnItsTargetAndBendsTheBeam) {
  COROFEM_SKIP_ABSENT(GetParam());
  Simulation sim = create(beamScene(GetParam(), true, true));
  const std::vector<std::uint32_t> tip = nodesAt(sim.restMesh(0), 0, 0.5);
  HandleDesc desc;
  desc.nodes = tip;
  Result<int> handle = sim.addHandle(desc);
  ASSERT_TRUE(handle) << handle.message();
  const std::vector<double> rest = positions(sim);
  // The handle's centroid at rest is (0.5, 0.05, 0.05); lift it 5 cm over 10 frames, then hold.
  for (int frame = 1; frame <= 20; ++frame) {
    const double lift = 0.05 * std::min(1.0, frame / 10.0);
    const double target[3] = {0.5, 0.05 + lift, 0.05};
    ASSERT_TRUE(sim.moveHandle(handle.value(), target));
    ASSERT_TRUE(sim.step(kH)) << "frame " << frame;
    const std::vector<double> x = positions(sim);
    for (std::uint32_t n : tip)
      for (int a = 0; a < 3; ++a) {
        const double expected = rest[3 * n + static_cast<std::size_t>(a)] + (a == 1 ? lift : 0.0);
        ASSERT_NEAR(x[3 * n + static_cast<std::size_t>(a)], expected, std::max(1e-9, positionResolution()))
            << "frame " << frame << ", node " << n;
      }
  }
  EXPECT_NEAR(sim.time(), 20 * kH, 1e-12);
  // The beam bends up between the clamp and the tip: its middle rose (gravity alone pulls it down).
  const std::vector<double> x = positions(sim);
  double middle = 0.0;
  const std::vector<std::uint32_t> mid = nodesAt(sim.restMesh(0), 0, 0.25);
  for (std::uint32_t n : mid) middle += x[3 * n + 1] - rest[3 * n + 1];
  EXPECT_GT(middle / static_cast<double>(mid.size()), 0.005);

  // Released, the tip falls back under gravity.
  ASSERT_TRUE(sim.removeHandle(handle.value()));
  for (int frame = 0; frame < 10; ++frame) ASSERT_TRUE(sim.step(kH));
  const std::vector<double> after = positions(sim);
  EXPECT_LT(after[3 * tip[0] + 1], x[3 * tip[0] + 1] - 0.005);
  EXPECT_FALSE(sim.moveHandle(handle.value(), x.data()));  // removed: BadInput
}

TEST_P(Control, PinnedNodesStayAndUnpinnedOnesMove) {
  COROFEM_SKIP_ABSENT(GetParam());
  Simulation sim = create(beamScene(GetParam(), true, true));
  const std::vector<std::uint32_t> tip = nodesAt(sim.restMesh(0), 0, 0.5);
  for (int frame = 0; frame < 5; ++frame) ASSERT_TRUE(sim.step(kH));
  const std::vector<double> x5 = positions(sim);
  ASSERT_TRUE(sim.pinNodes(0, tip));
  for (int frame = 0; frame < 10; ++frame) ASSERT_TRUE(sim.step(kH));
  const std::vector<double> x15 = positions(sim), v15 = velocities(sim);
  for (std::uint32_t n : tip)
    for (std::size_t a = 0; a < 3; ++a) {
      EXPECT_NEAR(x15[3 * n + a], x5[3 * n + a], 1e-12) << "node " << n;
      EXPECT_EQ(v15[3 * n + a], 0.0) << "node " << n;
    }
  ASSERT_TRUE(sim.unpinNodes(0, tip));
  for (int frame = 0; frame < 10; ++frame) ASSERT_TRUE(sim.step(kH));
  EXPECT_LT(positions(sim)[3 * tip[0] + 1], x15[3 * tip[0] + 1] - 1e-3);
}

TEST_P(Control, ReleasedSupportsLetTheBodyFallFreely) {
  COROFEM_SKIP_ABSENT(GetParam());
  Simulation sim = create(beamScene(GetParam(), true, false));
  const std::vector<std::uint32_t> clamp = nodesAt(sim.restMesh(0), 0, 0.0);
  ASSERT_FALSE(clamp.empty());
  ASSERT_TRUE(sim.unpinNodes(0, clamp));
  ASSERT_TRUE(sim.setGravity(kGravity));
  const int frames = 12;
  for (int frame = 0; frame < frames; ++frame) ASSERT_TRUE(sim.step(kH));
  // No support: the momentum grows as M g t (internal forces sum to zero).
  const std::array<double, 3> p = momentum(sim);
  const double expected = totalMass(sim) * -9.81 * frames * kH;
  EXPECT_NEAR(p[1], expected, solveTolerance() * std::abs(expected) * 10);
  EXPECT_NEAR(p[0], 0.0, solveTolerance() * std::abs(expected) * 10);
  // Gravity off: the momentum stays.
  ASSERT_TRUE(sim.setGravity(kNoGravity));
  for (int frame = 0; frame < 6; ++frame) ASSERT_TRUE(sim.step(kH));
  EXPECT_NEAR(momentum(sim)[1], p[1], solveTolerance() * std::abs(expected) * 10);
}

TEST_P(Control, AppliedForcesChangeTheMomentumByForceTimesTime) {
  COROFEM_SKIP_ABSENT(GetParam());
  Simulation sim = create(beamScene(GetParam(), false, false));
  AppliedForce atNode;
  atNode.node = 0;
  atNode.force[2] = 0.5;
  AppliedForce atPoint;  // inside the beam: spread over an element's nodes
  atPoint.point[0] = 0.31;
  atPoint.point[1] = 0.043;
  atPoint.point[2] = 0.072;
  atPoint.force[1] = 2.0;
  ASSERT_TRUE(sim.setForces(0, {atNode, atPoint}));
  const int frames = 8;
  for (int frame = 0; frame < frames; ++frame) ASSERT_TRUE(sim.step(kH));
  const std::array<double, 3> p = momentum(sim);
  const double t = frames * kH;
  EXPECT_NEAR(p[1], 2.0 * t, solveTolerance() * 2.0 * t * 10);
  EXPECT_NEAR(p[2], 0.5 * t, solveTolerance() * 2.0 * t * 10);
  EXPECT_NEAR(p[0], 0.0, solveTolerance() * 2.0 * t * 10);
  // Removed: the momentum stays where it is.
  ASSERT_TRUE(sim.setForces(0, {}));
  for (int frame = 0; frame < 4; ++frame) ASSERT_TRUE(sim.step(kH));
  EXPECT_NEAR(momentum(sim)[1], p[1], solveTolerance() * 2.0 * t * 10);
}

TEST_P(Control, AForceAtAPointIsSpreadByTheContainingElementsWeights) {
  // A force at the centroid of an element of the beam (bent by gravity first, so that the search
  // runs on current positions, not the rest mesh's) acts as a quarter of it on each of that
  // element's nodes; one at a node's position as the whole force on that node; one just outside a
  // boundary face as a third on each of its nodes; one far outside the body on the nearest
  // element's nodes (the momentum still changes by F t).
  COROFEM_SKIP_ABSENT(GetParam());
  Simulation a = create(beamScene(GetParam(), true, true)), b = create(beamScene(GetParam(), true, true));
  stepBoth(a, b, 5);
  const TetMesh& mesh = a.restMesh(0);
  const std::vector<double> x = positions(a);
  const std::size_t element = mesh.tetCount() / 2 + 3, node = mesh.tets[4 * 7 + 2];
  AppliedForce atCentroid, atNode;
  atCentroid.force[1] = 4.0;
  atCentroid.force[2] = -2.0;
  for (int k = 0; k < 4; ++k)
    for (int c = 0; c < 3; ++c) atCentroid.point[c] += 0.25 * x[3 * mesh.tets[4 * element + k] + static_cast<std::size_t>(c)];
  for (int c = 0; c < 3; ++c) atNode.point[c] = x[3 * node + static_cast<std::size_t>(c)];
  atNode.force[0] = 1.5;
  std::vector<AppliedForce> spread;
  for (int k = 0; k < 4; ++k) {
    AppliedForce q;
    q.node = static_cast<int>(mesh.tets[4 * element + k]);
    q.force[1] = 1.0;
    q.force[2] = -0.5;
    spread.push_back(q);
  }
  AppliedForce whole;
  whole.node = static_cast<int>(node);
  whole.force[0] = 1.5;
  spread.push_back(whole);
  ASSERT_TRUE(a.setForces(0, {atCentroid, atNode}));
  ASSERT_TRUE(b.setForces(0, spread));
  stepBoth(a, b, 3);
  const std::vector<double> xa = positions(a), xb = positions(b);
  const double tolerance = GetParam().isFloat() ? 1e-6 : 1e-10;  // the weights 0.25 and 1 to rounding
  for (std::size_t d = 0; d < xa.size(); ++d) ASSERT_NEAR(xa[d], xb[d], tolerance) << "dof " << d;

  // Just outside a bottom face (1e-7 m below its centroid, at the current positions): the nearest
  // element is the face's own, whose fourth weight clamps to 0: a third on each face node.
  std::size_t faceElement = mesh.tetCount();
  std::vector<std::uint32_t> face;
  std::uint32_t apex = 0;
  for (std::size_t e = mesh.tetCount() / 3; e < mesh.tetCount() && face.empty(); ++e) {
    std::vector<std::uint32_t> bottom;
    for (int k = 0; k < 4; ++k) {
      const std::uint32_t n = mesh.tets[4 * e + static_cast<std::size_t>(k)];
      if (std::abs(mesh.nodes[3 * n + 1]) < 1e-12) bottom.push_back(n);
      else apex = n;
    }
    if (bottom.size() == 3) {
      face = bottom;
      faceElement = e;
    }
  }
  ASSERT_EQ(face.size(), 3u) << "no element with a face on the bottom";
  const std::vector<double> now = positions(a);
  auto at = [&](std::uint32_t n) {
    return Eigen::Vector3d(now[3 * n], now[3 * n + 1], now[3 * n + 2]);
  };
  const Eigen::Vector3d centroid = (at(face[0]) + at(face[1]) + at(face[2])) / 3.0;
  Eigen::Vector3d normal = (at(face[1]) - at(face[0])).cross(at(face[2]) - at(face[0])).normalized();
  if (normal.dot(at(apex) - centroid) > 0.0) normal = -normal;  // outwards
  AppliedForce below;
  for (int c = 0; c < 3; ++c) below.point[c] = centroid[c] + 1e-7 * normal[c];
  below.force[0] = 0.9;
  below.force[1] = -3.0;
  std::vector<AppliedForce> thirds;
  for (std::uint32_t n : face) {
    AppliedForce q;
    q.node = static_cast<int>(n);
    q.force[0] = 0.3;
    q.force[1] = -1.0;
    thirds.push_back(q);
  }
  ASSERT_TRUE(a.setForces(0, {below}));
  ASSERT_TRUE(b.setForces(0, thirds));
  stepBoth(a, b, 3);
  const std::vector<double> ya = positions(a), yb = positions(b);
  for (std::size_t d = 0; d < ya.size(); ++d)
    ASSERT_NEAR(ya[d], yb[d], tolerance) << "outside face of element " << faceElement << ", dof " << d;

  // Far outside a free body: still the whole force (clamped, normalised weights).
  Simulation free = create(beamScene(GetParam(), false, false));
  AppliedForce outside;
  outside.point[0] = 2.0;
  outside.point[1] = -1.0;
  outside.point[2] = 0.3;
  outside.force[1] = 3.0;
  ASSERT_TRUE(free.setForces(0, {outside}));
  for (int frame = 0; frame < 4; ++frame) ASSERT_TRUE(free.step(kH));
  EXPECT_NEAR(momentum(free)[1], 3.0 * 4 * kH, solveTolerance() * 3.0 * 4 * kH * 10);
}

TEST_P(Control, TeleportMovesTheStateRigidly) {
  COROFEM_SKIP_ABSENT(GetParam());
  Simulation sim = create(beamScene(GetParam(), false, false));
  std::vector<double> v(positions(sim).size(), 0.0);
  for (std::size_t n = 0; n < v.size() / 3; ++n) v[3 * n] = 0.3;  // translating along x
  ASSERT_TRUE(sim.setVelocities(0, v));
  ASSERT_TRUE(sim.step(kH));
  const std::vector<double> x0 = positions(sim);
  const std::array<double, 3> p0 = momentum(sim);
  const double ke0 = sim.energies(0).kinetic;
  // A quarter turn about z, then 1 m up.
  const double R[9] = {0, -1, 0, 1, 0, 0, 0, 0, 1};
  const double t[3] = {0, 1, 0};
  ASSERT_TRUE(sim.teleport(0, R, t));
  const std::vector<double> x1 = positions(sim);
  const double resolution = std::max(1e-12, positionResolution());
  for (std::size_t n = 0; n < x0.size() / 3; ++n) {
    EXPECT_NEAR(x1[3 * n], -x0[3 * n + 1], resolution);
    EXPECT_NEAR(x1[3 * n + 1], x0[3 * n] + 1.0, resolution);
    EXPECT_NEAR(x1[3 * n + 2], x0[3 * n + 2], resolution);
  }
  const std::array<double, 3> p1 = momentum(sim);
  EXPECT_NEAR(p1[0], -p0[1], 1e-12);
  EXPECT_NEAR(p1[1], p0[0], 1e-12);
  EXPECT_NEAR(sim.energies(0).kinetic, ke0, 1e-12 * ke0);
  // It goes on moving along +y now, with its momentum.
  ASSERT_TRUE(sim.step(kH));
  EXPECT_NEAR(momentum(sim)[1], p0[0], solveTolerance() * std::abs(p0[0]) * 10);
  // A body the scene clamps cannot be teleported; a matrix that is no rotation is refused.
  Simulation clamped = create(beamScene(GetParam(), true, false));
  const Status refused = clamped.teleport(0, R, t);
  EXPECT_EQ(refused.code(), ErrorCode::BadInput);
  EXPECT_NE(refused.message().find("unpinNodes"), std::string::npos) << refused.message();
  const double shear[9] = {1, 0.1, 0, 0, 1, 0, 0, 0, 1};
  EXPECT_EQ(sim.teleport(0, shear, t).code(), ErrorCode::BadInput);
}

TEST_P(Control, StateCanBeSetAndReset) {
  COROFEM_SKIP_ABSENT(GetParam());
  Simulation sim = create(beamScene(GetParam(), true, true));
  for (int frame = 0; frame < 10; ++frame) ASSERT_TRUE(sim.step(kH));
  const std::vector<double> bent = positions(sim);
  ASSERT_TRUE(sim.resetBody(0));
  const std::vector<double> rest = positions(sim);
  for (std::size_t d = 0; d < rest.size(); ++d) EXPECT_NEAR(rest[d], sim.restMesh(0).nodes[d], positionResolution());
  for (double v : velocities(sim)) EXPECT_EQ(v, 0.0);
  ASSERT_TRUE(sim.setPositions(0, bent));
  const auto near = [&](const std::vector<double>& a, const std::vector<double>& b) {
    if (a.size() != b.size()) return false;
    for (std::size_t d = 0; d < a.size(); ++d)
      if (std::abs(a[d] - b[d]) > positionResolution()) return false;
    return true;
  };
  EXPECT_TRUE(near(positions(sim), bent));
  // Wrong sizes and non-finite values are refused, and nothing changes.
  EXPECT_EQ(sim.setPositions(0, std::vector<double>(3)).code(), ErrorCode::BadInput);
  std::vector<double> bad = bent;
  bad[4] = std::nan("");
  EXPECT_EQ(sim.setPositions(0, bad).code(), ErrorCode::BadInput);
  EXPECT_TRUE(near(positions(sim), bent));
  EXPECT_EQ(sim.setVelocities(7, bent).code(), ErrorCode::BadInput);
  ASSERT_TRUE(sim.step(kH));
}

TEST_P(Control, TheTimeStepIsGivenPerCallAndTheAnalysisIsOpenEnded) {
  COROFEM_SKIP_ABSENT(GetParam());
  Simulation sim = create(beamScene(GetParam(), true, true));
  EXPECT_EQ(sim.stepCount(), 0);
  double t = 0.0;
  for (int frame = 0; frame < 12; ++frame) {
    const double dt = frame % 3 == 0 ? 1.0 / 90.0 : 1.0 / 60.0;
    ASSERT_TRUE(sim.step(dt));
    t += dt;
    EXPECT_FALSE(sim.finished());
  }
  EXPECT_NEAR(sim.time(), t, 1e-12);
  EXPECT_EQ(sim.stepsTaken(), 12);
  EXPECT_EQ(sim.step(0.0).code(), ErrorCode::BadInput);
  EXPECT_EQ(sim.step(-kH).code(), ErrorCode::BadInput);
  EXPECT_EQ(sim.step(std::nan("")).code(), ErrorCode::BadInput);
  EXPECT_NEAR(sim.time(), t, 1e-12);
}

TEST_P(Control, AFailedStepIsNotTerminal) {
  COROFEM_SKIP_ABSENT(GetParam());
  Simulation sim = create(beamScene(GetParam(), true, true));
  for (int frame = 0; frame < 3; ++frame) ASSERT_TRUE(sim.step(kH));
  const std::vector<double> before = positions(sim);
  const double t = sim.time();
  AppliedForce huge;
  huge.node = static_cast<int>(nodesAt(sim.restMesh(0), 0, 0.5).front());
  huge.force[1] = 1e300;  // the step's forces overflow
  ASSERT_TRUE(sim.setForces(0, {huge}));
  const Status failed = sim.step(kH);
  ASSERT_EQ(failed.code(), ErrorCode::SolveFailed) << failed.message();
  EXPECT_EQ(positions(sim), before);
  EXPECT_EQ(sim.time(), t);
  // The application takes the force away and goes on; the next step starts at rest.
  ASSERT_TRUE(sim.setForces(0, {}));
  for (int frame = 0; frame < 5; ++frame) ASSERT_TRUE(sim.step(kH)) << "frame " << frame;
  EXPECT_NEAR(sim.time(), t + 5 * kH, 1e-12);
}

TEST_P(Control, ControlNeedsADynamicAnalysis) {
  COROFEM_SKIP_ABSENT(GetParam());
  Scene scene = beamScene(GetParam(), true, true);
  scene.analysis.kind = AnalysisDesc::Kind::Static;
  scene.analysis.statics.increments = 1;
  Simulation sim = create(scene);
  HandleDesc desc;
  desc.nodes = {1};
  const Result<int> handle = sim.addHandle(desc);
  ASSERT_FALSE(handle);
  EXPECT_EQ(handle.status().code(), ErrorCode::BadInput);
  EXPECT_EQ(sim.pinNodes(0, {1}).code(), ErrorCode::BadInput);
  EXPECT_EQ(sim.step(kH).code(), ErrorCode::BadInput);
  const Status increment = sim.step();
  EXPECT_NE(increment.code(), ErrorCode::BadInput) << increment.message();
}

TEST_P(Control, BadNodesAndHandlesAreRefused) {
  COROFEM_SKIP_ABSENT(GetParam());
  Simulation sim = create(beamScene(GetParam(), true, true));
  const std::uint32_t nodes = static_cast<std::uint32_t>(sim.restMesh(0).nodeCount());
  const Status pin = sim.pinNodes(0, {nodes});
  EXPECT_EQ(pin.code(), ErrorCode::BadInput);
  EXPECT_NE(pin.message().find(std::to_string(nodes)), std::string::npos) << pin.message();
  HandleDesc desc;
  desc.body = 3;
  EXPECT_EQ(sim.addHandle(desc).status().code(), ErrorCode::BadInput);
  EXPECT_EQ(sim.removeHandle(42).code(), ErrorCode::BadInput);
  // A handle by point and radius grabs the nodes near the point, at least the nearest one.
  HandleDesc near;
  near.point[0] = 0.52;
  near.point[1] = 0.05;
  near.point[2] = 0.05;
  near.radius = 0.0;
  Result<int> one = sim.addHandle(near);
  ASSERT_TRUE(one) << one.message();
  ASSERT_TRUE(sim.step(kH));
}

TEST_P(Control, AHandleOnASurfaceVertexMovesThatVertexExactly) {
  COROFEM_SKIP_ABSENT(GetParam());
  const char* mesh = "../shared/data/meshes/sofa/liver.msh";
  const char* surface = "../shared/data/meshes/sofa/liver-smooth.obj";
  if (!std::ifstream(mesh) || !std::ifstream(surface)) GTEST_SKIP() << mesh << " or " << surface << " is absent";
  BodyDesc body = makeBody(MeshSourceDesc{}, 3000, 0.45, 1.0);
  body.mesh.file = mesh;
  body.surface = surface;
  NodeSetDesc clamp;
  clamp.boxMin = {1.2, 0, -2};
  clamp.boxMax = {2, 6, 3};
  body.fixed.push_back(clamp);
  Simulation sim = create(dynamicScene(GetParam(), body, kH, 0));
  const int vertex = 100;
  std::vector<double> rest;
  ASSERT_TRUE(sim.readSurface(0, rest));
  HandleDesc desc;
  desc.surfaceVertex = vertex;
  Result<int> handle = sim.addHandle(desc);
  ASSERT_TRUE(handle) << handle.message();
  // The handle holds the four nodes the vertex is bound to, and its target places the vertex.
  const double c[3] = {rest[3 * vertex], rest[3 * vertex + 1], rest[3 * vertex + 2]};
  // Device surfaces hold float positions (the liver spans about 6 units).
  const double tolerance = GetParam().isDevice() ? 5e-5 : 1e-9;
  for (int frame = 1; frame <= 10; ++frame) {
    const double lift = 0.03 * frame;
    const double target[3] = {c[0], c[1] + lift, c[2]};
    ASSERT_TRUE(sim.moveHandle(handle.value(), target));
    ASSERT_TRUE(sim.step(kH)) << "frame " << frame;
    std::vector<double> now;
    ASSERT_TRUE(sim.readSurface(0, now));
    for (std::size_t a = 0; a < 3; ++a)
      ASSERT_NEAR(now[3 * vertex + a], rest[3 * vertex + a] + (a == 1 ? lift : 0.0), tolerance)
          << "frame " << frame << ", axis " << a;
  }
  // A vertex past the surface's, or a body without a surface, is refused.
  HandleDesc past;
  past.surfaceVertex = static_cast<int>(rest.size() / 3);
  EXPECT_EQ(sim.addHandle(past).status().code(), ErrorCode::BadInput);
  Simulation beam = create(beamScene(GetParam(), true, true));
  HandleDesc none;
  none.surfaceVertex = 0;
  EXPECT_EQ(beam.addHandle(none).status().code(), ErrorCode::BadInput);
}

TEST_P(Control, RemovingAHandleGivesItsNodesBackToWhatHeldThemBefore) {
  COROFEM_SKIP_ABSENT(GetParam());
  Simulation sim = create(beamScene(GetParam(), true, true));
  const std::vector<std::uint32_t> clamp = nodesAt(sim.restMesh(0), 0, 0.0);
  const std::vector<std::uint32_t> tip = nodesAt(sim.restMesh(0), 0, 0.5);
  // Released supports, grabbed, then let go: they stay released (the body falls), not back on the clamp.
  ASSERT_TRUE(sim.unpinNodes(0, clamp));
  HandleDesc both;
  both.nodes = clamp;
  both.nodes.insert(both.nodes.end(), tip.begin(), tip.end());
  Result<int> h = sim.addHandle(both);
  ASSERT_TRUE(h);
  for (int frame = 0; frame < 3; ++frame) ASSERT_TRUE(sim.step(kH));
  // A pin on the tip while the handle holds it takes the tip over; removing the handle then leaves
  // the tip pinned and the clamp nodes released.
  ASSERT_TRUE(sim.pinNodes(0, tip));
  ASSERT_TRUE(sim.removeHandle(h.value()));
  const std::vector<double> x0 = positions(sim);
  for (int frame = 0; frame < 6; ++frame) ASSERT_TRUE(sim.step(kH));
  const std::vector<double> x1 = positions(sim);
  for (std::uint32_t n : tip)
    for (std::size_t a = 0; a < 3; ++a) EXPECT_NEAR(x1[3 * n + a], x0[3 * n + a], 1e-12) << "tip node " << n;
  for (std::uint32_t n : clamp) EXPECT_LT(x1[3 * n + 1], x0[3 * n + 1] - 1e-4) << "clamp node " << n << " snapped back";
  // A handle that took nodes a pin held gives them back to the pin, where they are then.
  HandleDesc grabTip;
  grabTip.nodes = tip;
  Result<int> h2 = sim.addHandle(grabTip);
  ASSERT_TRUE(h2);
  const double up[3] = {0.5, 0.08, 0.05};
  ASSERT_TRUE(sim.moveHandle(h2.value(), up));
  ASSERT_TRUE(sim.step(kH));
  ASSERT_TRUE(sim.removeHandle(h2.value()));
  const std::vector<double> x2 = positions(sim);
  for (int frame = 0; frame < 4; ++frame) ASSERT_TRUE(sim.step(kH));
  const std::vector<double> x3 = positions(sim);
  for (std::uint32_t n : tip)
    for (std::size_t a = 0; a < 3; ++a) EXPECT_NEAR(x3[3 * n + a], x2[3 * n + a], 1e-12) << "re-pinned tip node " << n;
}

TEST_P(Control, AFailedStepRestartsTheFailedBodyAtRest) {
  COROFEM_SKIP_ABSENT(GetParam());
  // Twins: one fails a step and goes on; the other is stopped by hand at the same state.
  Simulation failing = create(beamScene(GetParam(), true, true)), twin = create(beamScene(GetParam(), true, true));
  stepBoth(failing, twin, 4);
  AppliedForce huge;
  huge.node = static_cast<int>(nodesAt(failing.restMesh(0), 0, 0.5).front());  // a free node
  huge.force[1] = 1e300;
  ASSERT_TRUE(failing.setForces(0, {huge}));
  ASSERT_EQ(failing.step(kH).code(), ErrorCode::SolveFailed);
  ASSERT_TRUE(failing.setForces(0, {}));
  ASSERT_TRUE(twin.setVelocities(0, std::vector<double>(positions(twin).size(), 0.0)));
  ASSERT_TRUE(failing.step(kH));
  ASSERT_TRUE(twin.step(kH));
  const std::vector<double> a = positions(failing), b = positions(twin);
  for (std::size_t d = 0; d < a.size(); ++d) ASSERT_EQ(a[d], b[d]) << "dof " << d;
}

TEST_P(Control, AStifferMaterialSagsLessAndMatchesTheSceneMaterial) {
  COROFEM_SKIP_ABSENT(GetParam());
  // Changed before the first step, the material is the scene's own: the same steps to the bit.
  Scene damped = beamScene(GetParam(), true, true);
  damped.bodies[0].material.rayleighMass = 30.0;
  Simulation changed = create(beamScene(GetParam(), true, true)), given = create(damped);
  ASSERT_TRUE(changed.setMaterial(0, 1e6, 0.3, 30.0, 0.0));
  stepBoth(changed, given, 20);
  EXPECT_EQ(positions(changed), positions(given));
  // Settled under gravity (mass damping 30 1/s), the tip sags as 1/E: four times stiffer, a quarter.
  const std::vector<std::uint32_t> tip = nodesAt(changed.restMesh(0), 0, 0.5);
  const auto sag = [&](const Simulation& sim) {
    const std::vector<double> x = positions(sim);
    double s = 0.0;
    for (std::uint32_t n : tip) s += sim.restMesh(0).nodes[3 * n + 1] - x[3 * n + 1];
    return s / static_cast<double>(tip.size());
  };
  for (int frame = 0; frame < 150; ++frame) ASSERT_TRUE(changed.step(kH));
  const double soft = sag(changed);
  ASSERT_TRUE(changed.setMaterial(0, 4e6, 0.3, 30.0, 0.0));
  for (int frame = 0; frame < 150; ++frame) ASSERT_TRUE(changed.step(kH));
  const double stiff = sag(changed);
  EXPECT_GT(soft, 0.01);
  EXPECT_NEAR(soft / stiff, 4.0, 0.4) << "sag " << soft << " m, then " << stiff << " m";
  // Out of range is refused and changes nothing.
  EXPECT_EQ(changed.setMaterial(0, -1.0, 0.3, 0.0, 0.0).code(), ErrorCode::BadInput);
  EXPECT_EQ(changed.setMaterial(0, 1e6, 0.5, 0.0, 0.0).code(), ErrorCode::BadInput);
  EXPECT_EQ(changed.setMaterial(0, 1e6, 0.3, -1.0, 0.0).code(), ErrorCode::BadInput);
  ASSERT_TRUE(changed.step(kH));
  EXPECT_NEAR(sag(changed), stiff, 1e-3 * stiff);
}

TEST_P(Control, AnAddedBodyStepsAsInAFreshSimulationAndTheOthersGoOn) {
  COROFEM_SKIP_ABSENT(GetParam());
  Scene scene = beamScene(GetParam(), true, true);
  scene.backend.batch = false;
  BodyDesc added = scene.bodies[0];
  added.name = "added";
  added.mesh.translate = {0.0, 0.0, 1.0};
  Simulation sim = create(scene), untouched = create(scene);
  Scene alone = scene;
  alone.bodies = {added};
  Simulation fresh = create(alone);
  stepBoth(sim, untouched, 5);
  Result<int> index = sim.addBody(added);
  ASSERT_TRUE(index) << index.message();
  EXPECT_EQ(index.value(), 1);
  EXPECT_EQ(sim.bodyCount(), 2);
  for (int frame = 0; frame < 10; ++frame) {
    ASSERT_TRUE(sim.step(kH));
    ASSERT_TRUE(untouched.step(kH));
    ASSERT_TRUE(fresh.step(kH));
  }
  EXPECT_EQ(positions(sim, 1), positions(fresh)) << "the added body differs from the same body alone";
  EXPECT_EQ(positions(sim, 0), positions(untouched)) << "adding a body changed the other one";
  // A second body of the same name, or one whose mesh cannot be read, is refused and changes nothing.
  EXPECT_EQ(sim.addBody(added).status().code(), ErrorCode::BadInput);
  BodyDesc broken = added;
  broken.name = "broken";
  broken.mesh = MeshSourceDesc{};
  broken.mesh.file = "no/such/mesh.msh";
  EXPECT_FALSE(sim.addBody(broken));
  EXPECT_EQ(sim.bodyCount(), 2);
  ASSERT_TRUE(sim.step(kH));
}

TEST_P(Control, ARemovedBodyTakesItsDeviceMemoryAndHandlesWithIt) {
  COROFEM_SKIP_ABSENT(GetParam());
  Scene scene = beamScene(GetParam(), true, true);
  scene.backend.batch = false;
  scene.bodies.push_back(scene.bodies[0]);
  scene.bodies[1].name = "second";
  scene.bodies[1].mesh.translate = {0.0, 0.0, 1.0};
  Simulation sim = create(scene);
  HandleDesc desc;
  desc.nodes = nodesAt(sim.restMesh(0), 0, 0.5);
  Result<int> handle = sim.addHandle(desc);
  ASSERT_TRUE(handle);
  for (int frame = 0; frame < 3; ++frame) ASSERT_TRUE(sim.step(kH));
  const std::vector<double> second = positions(sim, 1);
  const auto deviceBytes = [](const Simulation& s) {
    long long total = 0;
    const nlohmann::json plan = nlohmann::json::parse(s.planReport());
    for (const auto& b : plan["bodies"])
      if (b.contains("device_bytes_allocated")) total += b["device_bytes_allocated"].get<long long>();
    return total;
  };
  const long long before = deviceBytes(sim);
  ASSERT_TRUE(sim.removeBody(0));
  EXPECT_EQ(sim.bodyCount(), 1);
  EXPECT_EQ(positions(sim, 0), second);  // the second body is body 0 now, where it was
  if (GetParam().isDevice()) {
    EXPECT_GT(before, 0);
    EXPECT_LT(deviceBytes(sim), before) << "the removed body's device buffers were not freed";
  }
  EXPECT_EQ(sim.moveHandle(handle.value(), second.data()).code(), ErrorCode::BadInput);  // gone with its body
  ASSERT_TRUE(sim.step(kH));
  EXPECT_EQ(sim.removeBody(0).code(), ErrorCode::BadInput);  // the last body stays
}

TEST_P(Control, ASpringHandlePullsWithStiffnessTimesItsStretch) {
  // A free beam in no gravity, its tip nodes pulled 5 cm up at once by a spring handle of 200 N/m:
  // the internal forces sum to zero, so the momentum changes by exactly the spring's force, which
  // must be k times the stretch, the target minus the tip nodes' centroid (backward Euler: at the
  // step's end positions), frame after frame while the beam swings up.
  COROFEM_SKIP_ABSENT(GetParam());
  Scene scene = beamScene(GetParam(), false, false);
  scene.analysis.dynamics.newtonIterations = 6;
  scene.analysis.dynamics.newtonTolerance = 1e-10;
  Simulation sim = create(scene);
  const std::vector<std::uint32_t> tip = nodesAt(sim.restMesh(0), 0, 0.5);
  const double k = 200.0;
  HandleDesc desc;
  desc.nodes = tip;
  desc.stiffness = k;
  Result<int> handle = sim.addHandle(desc);
  ASSERT_TRUE(handle) << handle.message();
  const double target[3] = {0.5, 0.10, 0.05};  // the tip's centroid is at (0.5, 0.05, 0.05)
  ASSERT_TRUE(sim.moveHandle(handle.value(), target));
  std::array<double, 3> p = momentum(sim);
  double largest = 0.0;
  for (int frame = 1; frame <= 15; ++frame) {
    ASSERT_TRUE(sim.step(kH)) << "frame " << frame;
    const std::array<double, 3> next = momentum(sim);
    const std::vector<double> x = positions(sim);
    double centroid[3] = {0, 0, 0};
    for (std::uint32_t n : tip)
      for (int a = 0; a < 3; ++a) centroid[a] += x[3 * n + static_cast<std::size_t>(a)] / static_cast<double>(tip.size());
    for (int a = 0; a < 3; ++a) {
      const double force = k * (target[a] - centroid[a]);
      const double dpdt = (next[static_cast<std::size_t>(a)] - p[static_cast<std::size_t>(a)]) / kH;
      ASSERT_NEAR(dpdt, force, solveTolerance() * 10.0 + 1e-6) << "frame " << frame << ", axis " << a;
      largest = std::max(largest, std::abs(force));
    }
    p = next;
  }
  EXPECT_GT(largest, 5.0);  // the spring did pull (10 N at the first frame's stretch)
  // The tip rose towards the target, and the spring holds nothing: the nodes are not on it.
  const std::vector<double> x = positions(sim);
  EXPECT_GT(x[3 * tip[0] + 1], 0.06);
  EXPECT_GT(std::abs(x[3 * tip[0] + 1] - (target[1] - 0.05 + sim.restMesh(0).nodes[3 * tip[0] + 1])), 1e-4);
}

TEST_P(Control, AStiffSpringHandleActsAsAHardOneAndTheyTurnIntoEachOther) {
  // The clamped beam under gravity, its tip lifted 3 cm by a hard handle and, in a second
  // Simulation, by a spring of 1e8 N/m (stable: springs are implicit): the beams agree to the
  // spring's give, which falls as 1/k (on the reference: 5.6e-4 m at 1e6 N/m, 6.3e-5 m at 1e7, under
  // 2e-5 m from 1e8 on). Then the spring is
  // made hard (its nodes exactly on their targets) and the hard handle a spring (its nodes free:
  // gravity pulls them off by force / k with a soft one).
  COROFEM_SKIP_ABSENT(GetParam());
  Simulation hard = create(beamScene(GetParam(), true, true)), soft = create(beamScene(GetParam(), true, true));
  const std::vector<std::uint32_t> tip = nodesAt(hard.restMesh(0), 0, 0.5);
  HandleDesc desc;
  desc.nodes = tip;
  Result<int> hh = hard.addHandle(desc);
  desc.stiffness = 1e8;
  Result<int> sh = soft.addHandle(desc);
  ASSERT_TRUE(hh && sh);
  const std::vector<double> rest = positions(hard);
  for (int frame = 1; frame <= 12; ++frame) {
    const double target[3] = {0.5, 0.05 + 0.03 * std::min(1.0, frame / 6.0), 0.05};
    ASSERT_TRUE(hard.moveHandle(hh.value(), target));
    ASSERT_TRUE(soft.moveHandle(sh.value(), target));
    ASSERT_TRUE(hard.step(kH)) << "frame " << frame;
    ASSERT_TRUE(soft.step(kH)) << "frame " << frame;
  }
  std::vector<double> xh = positions(hard), xs = positions(soft);
  double worst = 0.0;
  for (std::size_t d = 0; d < xh.size(); ++d) worst = std::max(worst, std::abs(xh[d] - xs[d]));
  EXPECT_LT(worst, 2e-5);
  EXPECT_GT(std::abs(xs[3 * tip[0] + 1] - rest[3 * tip[0] + 1]), 0.029);  // it did lift

  // The spring made hard: its nodes on the targets exactly. The hard one made a soft spring: off.
  ASSERT_TRUE(soft.setHandleStiffness(sh.value(), 0.0));
  ASSERT_TRUE(hard.setHandleStiffness(hh.value(), 50.0));
  ASSERT_TRUE(soft.step(kH));
  ASSERT_TRUE(hard.step(kH));
  xh = positions(hard);
  xs = positions(soft);
  double onTarget = 0.0, off = 0.0;
  for (std::uint32_t n : tip) {
    onTarget = std::max(onTarget, std::abs(xs[3 * n + 1] - (rest[3 * n + 1] + 0.03)));
    off = std::max(off, std::abs(xh[3 * n + 1] - (rest[3 * n + 1] + 0.03)));
  }
  EXPECT_LT(onTarget, std::max(1e-9, positionResolution()));
  EXPECT_GT(off, 1e-4);

  // Pins win over a spring on the same nodes; bad stiffnesses are refused.
  ASSERT_TRUE(hard.pinNodes(0, tip));
  const std::vector<double> pinned = positions(hard);
  const double far[3] = {0.5, 0.5, 0.05};
  ASSERT_TRUE(hard.moveHandle(hh.value(), far));
  for (int frame = 0; frame < 3; ++frame) ASSERT_TRUE(hard.step(kH));
  const std::vector<double> after = positions(hard);
  for (std::uint32_t n : tip) EXPECT_NEAR(after[3 * n + 1], pinned[3 * n + 1], std::max(1e-9, positionResolution()));
  EXPECT_EQ(hard.setHandleStiffness(hh.value(), -1.0).code(), ErrorCode::BadInput);
  EXPECT_EQ(hard.setHandleStiffness(hh.value() + 100, 1.0).code(), ErrorCode::BadInput);
  desc.stiffness = std::nan("");
  EXPECT_EQ(hard.addHandle(desc).status().code(), ErrorCode::BadInput);
}

TEST_P(Control, AHandleTurnedSpringGivesUpTheNodesNewerHandlesTookFromIt) {
  // Hard handle A lifts the tip; hard handle B takes the same nodes; A becomes a spring; B goes:
  // the nodes must be free (the scene does not hold the tip), not held at a target nobody sets
  // (which would pull them back to rest), and stay free when A goes too.
  COROFEM_SKIP_ABSENT(GetParam());
  Simulation sim = create(beamScene(GetParam(), true, true));
  const std::vector<std::uint32_t> tip = nodesAt(sim.restMesh(0), 0, 0.5);
  HandleDesc desc;
  desc.nodes = tip;
  Result<int> a = sim.addHandle(desc);
  ASSERT_TRUE(a);
  const double up[3] = {0.5, 0.08, 0.05};
  ASSERT_TRUE(sim.moveHandle(a.value(), up));
  for (int frame = 0; frame < 3; ++frame) ASSERT_TRUE(sim.step(kH));
  Result<int> b = sim.addHandle(desc);
  ASSERT_TRUE(b);
  ASSERT_TRUE(sim.setHandleStiffness(a.value(), 1.0));  // a weak spring: gravity wins
  ASSERT_TRUE(sim.step(kH));
  const std::vector<double> held = positions(sim);
  ASSERT_TRUE(sim.removeHandle(b.value()));
  ASSERT_TRUE(sim.step(kH));
  std::vector<double> x = positions(sim);
  for (std::uint32_t n : tip) {
    const std::size_t d = 3 * n + 1;
    EXPECT_LT(x[d], held[d]) << "node " << n << " did not start to fall";
    EXPECT_GT(x[d], held[d] - 0.01) << "node " << n << " jumped (towards rest?)";
  }
  ASSERT_TRUE(sim.removeHandle(a.value()));
  for (int frame = 0; frame < 3; ++frame) ASSERT_TRUE(sim.step(kH));
  const std::vector<double> later = positions(sim);
  for (std::uint32_t n : tip) EXPECT_LT(later[3 * n + 1], x[3 * n + 1]) << "node " << n << " is held";
}

INSTANTIATE_TEST_SUITE_P(Backends, Control, ::testing::ValuesIn(backendCasesWithDeviceStores()), caseName);

/// Three copies of the beam in one batch (the OpenCL backend batches bodies that share a device):
/// body 0 pulled by a spring handle, body 1 pinned at its tip and pushed, body 2 dragged by a
/// handle; each steps as it does alone, and goes on so when body 1 leaves the batch.
TEST(ControlBatch, BodiesUnderControlInABatchStepAsAloneAndOneLeaves) {
  const std::vector<BackendCase> cases = backendCases();
  const BackendCase* c = nullptr;
  for (const BackendCase& k : cases)
    if (k.kind == BackendKind::OpenCL && k.absent.empty() && !k.isFloat()) c = &k;
  if (!c) GTEST_SKIP() << "no OpenCL device with fp64 here: the batch runs on OpenCL devices";
  Scene one = beamScene(*c, true, true);
  Scene three = one;
  for (const char* name : {"second", "third"}) {
    three.bodies.push_back(one.bodies[0]);
    three.bodies.back().name = name;
  }
  three.backend.batch = true;
  Simulation batch = create(three);
  ASSERT_NE(batch.schedulerReport().find("batch"), std::string::npos);
  Simulation alone[3] = {create(one), create(one), create(one)};
  const std::vector<std::uint32_t> tip = nodesAt(batch.restMesh(0), 0, 0.5);
  const std::vector<std::uint32_t> mid = nodesAt(batch.restMesh(0), 0, 0.25);
  HandleDesc desc;
  desc.body = 2;
  desc.nodes = tip;
  Result<int> hb = batch.addHandle(desc);
  desc.body = 0;
  Result<int> ha = alone[2].addHandle(desc);
  ASSERT_TRUE(hb && ha);
  // Body 0 pulled sideways by a spring handle on its tip.
  desc.stiffness = 80.0;
  Result<int> sb = batch.addHandle(desc);
  Result<int> sa = alone[0].addHandle(desc);
  ASSERT_TRUE(sb && sa);
  const double sideways[3] = {0.5, 0.05, 0.12};
  ASSERT_TRUE(batch.moveHandle(sb.value(), sideways));
  ASSERT_TRUE(alone[0].moveHandle(sa.value(), sideways));
  AppliedForce push;
  push.node = static_cast<int>(mid.front());
  push.force[2] = 1.5;
  ASSERT_TRUE(batch.pinNodes(1, tip));
  ASSERT_TRUE(alone[1].pinNodes(0, tip));
  ASSERT_TRUE(batch.setForces(1, {push}));
  ASSERT_TRUE(alone[1].setForces(0, {push}));
  for (int frame = 1; frame <= 12; ++frame) {
    const double target[3] = {0.5, 0.05 + 0.004 * frame, 0.05};
    ASSERT_TRUE(batch.moveHandle(hb.value(), target));
    ASSERT_TRUE(alone[2].moveHandle(ha.value(), target));
    ASSERT_TRUE(batch.step(kH));
    for (Simulation& s : alone) ASSERT_TRUE(s.step(kH));
  }
  for (int body = 0; body < 3; ++body) {
    const std::vector<double> b = positions(batch, body), a = positions(alone[body]);
    for (std::size_t d = 0; d < b.size(); ++d) ASSERT_NEAR(b[d], a[d], 1e-9) << "body " << body << ", dof " << d;
  }

  // The pinned, pushed body leaves the batch: the device is made again for the other two, with
  // their springs and handles, and the plan's device bytes go down; they go on as alone.
  const auto deviceBytes = [](const Simulation& s) {
    long long total = 0;
    const nlohmann::json plan = nlohmann::json::parse(s.planReport());
    for (const auto& b : plan["batches"]) total += b["allocated_bytes"].get<long long>();
    return total;
  };
  const long long before = deviceBytes(batch);
  ASSERT_TRUE(batch.removeBody(1));
  ASSERT_EQ(batch.bodyCount(), 2);
  EXPECT_GT(before, 0);
  EXPECT_LT(deviceBytes(batch), before) << "the removed body's device buffers were not freed";
  EXPECT_EQ(positions(batch, 1), positions(alone[2]));  // the dragged body is body 1 now, where it was
  const nlohmann::json batches = nlohmann::json::parse(batch.planReport())["batches"];
  ASSERT_EQ(batches.size(), 1u);
  EXPECT_EQ(batches[0]["active_bodies"], nlohmann::json({"body", "third"}));
  for (int frame = 13; frame <= 20; ++frame) {
    const double target[3] = {0.5, 0.05 + 0.004 * frame, 0.05};
    ASSERT_TRUE(batch.moveHandle(hb.value(), target));
    ASSERT_TRUE(alone[2].moveHandle(ha.value(), target));
    ASSERT_TRUE(batch.step(kH));
    ASSERT_TRUE(alone[0].step(kH));
    ASSERT_TRUE(alone[2].step(kH));
  }
  for (int body = 0; body < 2; ++body) {
    const std::vector<double> b = positions(batch, body), a = positions(alone[body == 0 ? 0 : 2]);
    for (std::size_t d = 0; d < b.size(); ++d)
      ASSERT_NEAR(b[d], a[d], 1e-9) << "after the removal, body " << body << ", dof " << d;
  }
  const std::vector<double> tipNow = positions(batch, 1);
  EXPECT_NEAR(tipNow[3 * tip[0] + 1], batch.restMesh(1).nodes[3 * tip[0] + 1] + 0.004 * 20, 1e-9);
}

/// Removing batched bodies where a body's scene index is not its slot index: a large body first
/// ("auto" gives it the multigrid, so it runs alone) and three small ones in a batch; the batch's
/// first slot leaves twice, then the last member; the body left steps as it does alone.
TEST(ControlBatch, BatchedBodiesLeaveOneByOneAndTheLastGoesOnAsAlone) {
  const std::vector<BackendCase> cases = backendCases();
  const BackendCase* c = nullptr;
  for (const BackendCase& k : cases)
    if (k.kind == BackendKind::OpenCL && k.absent.empty() && !k.isFloat()) c = &k;
  if (!c) GTEST_SKIP() << "no OpenCL device with fp64 here: the batch runs on OpenCL devices";
  Scene one = beamScene(*c, true, true);
  Scene scene = one;
  scene.bodies[0] = makeBody(box({0, 0, 2}, {1.0, 0.1, 2.1}, {40, 4, 4}), 1e6, 0.3);
  scene.bodies[0].name = "big";
  scene.bodies[0].fixed.push_back(planeSet(0, 0.0));
  for (const char* name : {"s0", "s1", "s2"}) {
    scene.bodies.push_back(one.bodies[0]);
    scene.bodies.back().name = name;
  }
  scene.backend.batch = true;
  Simulation sim = create(scene);
  const nlohmann::json batches = nlohmann::json::parse(sim.planReport())["batches"];
  ASSERT_EQ(batches.size(), 1u);
  ASSERT_EQ(batches[0]["bodies"], nlohmann::json({"s0", "s1", "s2"}));
  Simulation alone = create(one);
  auto steps = [&](int n) {
    for (int k = 0; k < n; ++k) {
      ASSERT_TRUE(sim.step(kH));
      ASSERT_TRUE(alone.step(kH));
    }
  };
  steps(3);
  ASSERT_TRUE(sim.removeBody(1));  // s0: the batch's slot 0
  steps(2);
  ASSERT_TRUE(sim.removeBody(1));  // s1, now slot 0 too
  ASSERT_EQ(sim.bodyCount(), 2);
  EXPECT_EQ(sim.scene().bodies[1].name, "s2");
  steps(3);
  const std::vector<double> x = positions(sim, 1), xa = positions(alone);
  for (std::size_t d = 0; d < x.size(); ++d) ASSERT_NEAR(x[d], xa[d], 1e-9) << "dof " << d;
  ASSERT_TRUE(sim.removeBody(1));  // the batch's last member
  ASSERT_EQ(sim.bodyCount(), 1);
  EXPECT_EQ(sim.scene().bodies[0].name, "big");
  ASSERT_TRUE(sim.step(kH));
  EXPECT_EQ(sim.removeBody(0).code(), ErrorCode::BadInput);
}

}  // namespace
}  // namespace corofem::test
