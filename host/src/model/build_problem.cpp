// buildProblem: a scene body + its mesh -> Problem (elements set up, masses lumped, node sets
// resolved into constraints and loads, initial velocity).
#include "model/problem.hpp"

#include "util/error.hpp"

#include <Eigen/Geometry>

#include <cmath>
#include <sstream>
#include <string>

namespace corofem::detail {

namespace {

std::vector<std::uint32_t> resolveOrThrow(const BodyDesc& body, const std::string& what,
                                          const NodeSetDesc& set, const TetMesh& mesh,
                                          const std::string& baseDir, const InputLimits& limits) {
  Result<std::vector<std::uint32_t>> nodes = resolveNodeSet(set, mesh, baseDir, limits);
  if (!nodes) {
    fail(nodes.status().code() == ErrorCode::Ok ? ErrorCode::BadInput : nodes.status().code(), "body '",
         body.name, "': ", what, ": ", nodes.message());
  }
  for (std::uint32_t n : *nodes)
    if (n >= mesh.nodeCount())
      fail(ErrorCode::BadInput, "body '", body.name, "': ", what, " selects node ", n, " but the mesh has only ",
           mesh.nodeCount(), " nodes (0-based indices)");
  return std::move(nodes).value();
}

void checkMaterial(const BodyDesc& body) {
  const MaterialDesc& m = body.material;
  if (!(std::isfinite(m.density) && m.density > 0.0))
    fail(ErrorCode::BadInput, "body '", body.name, "': density ", m.density,
         " kg/m^3 is invalid; it must be finite and > 0 (e.g. 1000 for water-like solids)");
  if (!(std::isfinite(m.rayleighMass) && m.rayleighMass >= 0.0))
    fail(ErrorCode::BadInput, "body '", body.name, "': Rayleigh mass coefficient ", m.rayleighMass,
         " 1/s is invalid; it must be finite and >= 0");
  if (!(std::isfinite(m.rayleighStiffness) && m.rayleighStiffness >= 0.0))
    fail(ErrorCode::BadInput, "body '", body.name, "': Rayleigh stiffness coefficient ", m.rayleighStiffness,
         " s is invalid; it must be finite and >= 0");
}

void checkMesh(const BodyDesc& body, const TetMesh& mesh) {
  if (mesh.nodes.size() % 3 != 0 || mesh.tets.size() % 4 != 0)
    fail(ErrorCode::BadInput, "body '", body.name, "': mesh arrays are malformed (", mesh.nodes.size(),
         " node coordinates, not a multiple of 3, or ", mesh.tets.size(), " element indices, not a multiple of 4)");
  if (mesh.tetCount() == 0)
    fail(ErrorCode::BadInput, "body '", body.name, "': the mesh has no tetrahedra; a body needs a volume mesh");
  for (std::size_t i = 0; i < mesh.nodes.size(); ++i)
    if (!std::isfinite(mesh.nodes[i]))
      fail(ErrorCode::BadInput, "body '", body.name, "': node ", i / 3, " has a non-finite coordinate");
  for (std::size_t e = 0; e < mesh.tetCount(); ++e)
    for (int k = 0; k < 4; ++k)
      if (mesh.tets[4 * e + k] >= mesh.nodeCount())
        fail(ErrorCode::BadInput, "body '", body.name, "': element ", e, " refers to node ", mesh.tets[4 * e + k],
             " but the mesh has only ", mesh.nodeCount(), " nodes (0-based indices)");
}

}  // namespace

Problem buildProblem(const BodyDesc& body, const TetMesh& mesh, const SolverDesc& solver,
                     const std::string& baseDir, const InputLimits& limits) {
  checkMaterial(body);
  checkMesh(body, mesh);

  Problem p;
  p.name = body.name;
  p.mesh = mesh;
  p.formulation = body.formulation;
  p.rotation = solver.rotation;
  p.density = body.material.density;
  p.rayleighMass = body.material.rayleighMass;
  p.rayleighStiffness = body.material.rayleighStiffness;
  try {
    p.lame = lameFromYoungPoisson(body.material.youngsModulus, body.material.poissonRatio);
  } catch (const Error& e) {
    fail(ErrorCode::BadInput, "body '", body.name, "': ", e.what());
  }

  const std::size_t nodeCount = mesh.nodeCount();
  const auto n3 = static_cast<Eigen::Index>(3 * nodeCount);
  p.restPositions = Eigen::Map<const Eigen::VectorXd>(mesh.nodes.data(), n3);

  // Elements: rest set-up (Eqs. 4-8 inputs), lumped mass rho V / 4 per node, volume-weighted centroid.
  p.elements.resize(mesh.tetCount());
  p.lumpedMass = Eigen::VectorXd::Zero(n3);
  std::vector<std::uint8_t> used(nodeCount, 0);
  Vec3d centroid = Vec3d::Zero();
  double totalVolume = 0.0;
  for (std::size_t e = 0; e < mesh.tetCount(); ++e) {
    std::array<Vec3d, 4> X;
    for (int k = 0; k < 4; ++k) X[k] = p.restPositions.segment<3>(3 * mesh.tets[4 * e + k]);
    const double v = signedVolume(X);
    const auto nodesOf = [&] {
      std::ostringstream os;
      os << "element " << e << " (nodes " << mesh.tets[4 * e] << ", " << mesh.tets[4 * e + 1] << ", "
         << mesh.tets[4 * e + 2] << ", " << mesh.tets[4 * e + 3] << ")";
      return os.str();
    };
    if (v == 0.0)
      fail(ErrorCode::BadInput, "body '", body.name, "': ", nodesOf(),
           " has zero volume; remove it or fix the coordinates");
    if (v < 0.0)
      fail(ErrorCode::BadInput, "body '", body.name, "': ", nodesOf(), " is inverted (signed volume ", v,
           " m^3); swap two of its nodes (the mesh readers reorient elements on load)");
    try {
      p.elements[e] = computeElementRest(X);
    } catch (const Error& err) {
      fail(ErrorCode::BadInput, "body '", body.name, "': ", nodesOf(), ": ", err.what());
    }
    const double m = lumpedNodeMass(p.elements[e], p.density);
    for (int k = 0; k < 4; ++k) {
      const std::uint32_t n = mesh.tets[4 * e + k];
      p.lumpedMass.segment<3>(3 * n).array() += m;
      used[n] = 1;
    }
    centroid += v * 0.25 * (X[0] + X[1] + X[2] + X[3]);
    totalVolume += v;
  }
  centroid /= totalVolume;

  // Constraints. Nodes that belong to no element carry no mass or stiffness: they are held fixed so
  // that the system stays non-singular.
  p.constrained.assign(static_cast<std::size_t>(n3), 0);
  for (std::size_t n = 0; n < nodeCount; ++n)
    if (!used[n]) p.constrained[3 * n] = p.constrained[3 * n + 1] = p.constrained[3 * n + 2] = 1;

  // What holds each node: 0 free, 1 fixed set, 2 + k displacement load k. Overlaps are ambiguous
  // (a node cannot be held at rest and dragged at once) and reported.
  std::vector<int> holder(nodeCount, 0);
  for (std::size_t s = 0; s < body.fixed.size(); ++s) {
    const auto nodes =
        resolveOrThrow(body, "fixed node set " + std::to_string(s), body.fixed[s], mesh, baseDir, limits);
    for (std::uint32_t n : nodes) {
      holder[n] = 1;
      p.constrained[3 * n] = p.constrained[3 * n + 1] = p.constrained[3 * n + 2] = 1;
    }
  }

  for (std::size_t l = 0; l < body.loads.size(); ++l) {
    const LoadDesc& load = body.loads[l];
    const std::string what = "load " + std::to_string(l);
    for (double c : load.vector)
      if (!std::isfinite(c)) fail(ErrorCode::BadInput, "body '", body.name, "': ", what, " has a non-finite vector");
    if (!(std::isfinite(load.rampTime) && load.rampTime >= 0.0))
      fail(ErrorCode::BadInput, "body '", body.name, "': ", what, " has ramp time ", load.rampTime,
           " s; it must be finite and >= 0");
    const Vec3d v(load.vector[0], load.vector[1], load.vector[2]);
    switch (load.kind) {
      case LoadDesc::Kind::Gravity: {
        p.forces.push_back(ExternalForce{gravityForce(p, load.vector.data()), load.rampTime, /*gravity=*/true});
        break;
      }
      case LoadDesc::Kind::Force: {
        const auto nodes = resolveOrThrow(body, what + " (force)", load.nodes, mesh, baseDir, limits);
        ExternalForce f{Eigen::VectorXd::Zero(n3), load.rampTime};
        const Vec3d share = v / static_cast<double>(nodes.size());  // total force spread equally
        for (std::uint32_t n : nodes) f.f.segment<3>(3 * n) += share;
        p.forces.push_back(std::move(f));
        break;
      }
      case LoadDesc::Kind::Displacement: {
        const auto nodes = resolveOrThrow(body, what + " (displacement)", load.nodes, mesh, baseDir, limits);
        PrescribedDisplacement d;
        d.rampTime = load.rampTime;
        for (std::uint32_t n : nodes) {
          if (holder[n] != 0)
            fail(ErrorCode::BadInput, "body '", body.name, "': node ", n, " is in ", what,
                 " (displacement) and also in ",
                 holder[n] == 1 ? std::string("a fixed node set") : "load " + std::to_string(holder[n] - 2),
                 "; a node can be held by only one of them, so make the node sets disjoint");
          holder[n] = 2 + static_cast<int>(l);
          for (int c = 0; c < 3; ++c) {
            d.dofs.push_back(3 * n + static_cast<std::uint32_t>(c));
            d.values.push_back(v[c]);
            p.constrained[3 * n + c] = 1;
          }
        }
        p.prescribed.push_back(std::move(d));
        break;
      }
    }
  }

  // Initial velocity: v_i = v0 + omega x (X_i - c), c the volume-weighted (mass) centroid at rest,
  // so a pure omega spins the body about its centre of mass without drift.
  const Vec3d v0(body.initialVelocity[0], body.initialVelocity[1], body.initialVelocity[2]);
  const Vec3d omega(body.initialAngularVelocity[0], body.initialAngularVelocity[1], body.initialAngularVelocity[2]);
  if (!v0.allFinite() || !omega.allFinite())
    fail(ErrorCode::BadInput, "body '", body.name, "': the initial velocity or angular velocity is not finite");
  p.initialVelocity.resize(n3);
  for (std::size_t n = 0; n < nodeCount; ++n) {
    const Vec3d X = p.restPositions.segment<3>(3 * static_cast<Eigen::Index>(n));
    p.initialVelocity.segment<3>(3 * static_cast<Eigen::Index>(n)) = v0 + omega.cross(X - centroid);
  }
  return p;
}

}  // namespace corofem::detail
