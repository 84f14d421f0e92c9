// Run-time control of a live Simulation (simulation.hpp, "Run-time control"): handles, pins,
// applied forces, gravity and the bodies' state. Each call records what the application wants in
// the body's Hold; the next step hands the changes to the device (the constrained dofs, only when
// they changed) and to the driver (targets and forces), so that a call between two steps costs no
// device work. Held dofs are constrained dofs with targets of the application's (DynamicsDriver:
// their velocities follow from the target at the step's end), so a handle is exact, like the
// scene's prescribed displacements.
#include "api/simulation_impl.hpp"

#include "embed/element_locator.hpp"
#include "util/error.hpp"

#include <Eigen/LU>

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>

namespace corofem {

namespace {

using Vec3d = Eigen::Vector3d;
using Mat3d = Eigen::Matrix3d;

Vec3d vec3(const double v[3]) { return Vec3d(v[0], v[1], v[2]); }

bool finite3(const double v[3]) { return std::isfinite(v[0]) && std::isfinite(v[1]) && std::isfinite(v[2]); }

/// 9 doubles read and written row by row as a 3x3 matrix (the API's rotations, Handle::rotation).
using RowMajor3 = Eigen::Matrix<double, 3, 3, Eigen::RowMajor>;
Mat3d matrixOf(const double* r) { return Eigen::Map<const RowMajor3>(r); }
void store(const Mat3d& R, double* r) {
  Eigen::Map<RowMajor3> out(r);
  out = R;
}

/// R from 9 row-major doubles, checked to be a rotation (orthonormal, det +1, to 1e-6).
Mat3d rotationOf(const double* r, const char* call) {
  const Mat3d R = matrixOf(r);
  if (!R.allFinite() || (R.transpose() * R - Mat3d::Identity()).cwiseAbs().maxCoeff() > 1e-6 ||
      std::abs(R.determinant() - 1.0) > 1e-6)
    detail::fail(ErrorCode::BadInput, call, ": the rotation is not one (R^T R = I and det R = 1 to 1e-6 are needed); "
                 "give 9 numbers, row by row, of an orthonormal matrix");
  return R;
}

/// A handle's stiffness, checked: finite and >= 0 (N/m; 0: hard).
void checkStiffness(double stiffness, const char* call) {
  if (!(stiffness >= 0.0) || !std::isfinite(stiffness))
    detail::fail(ErrorCode::BadInput, call, ": the stiffness must be a finite number >= 0 (N/m; 0: a hard constraint), "
                 "got ", stiffness);
}

/// The node ids, checked against the body's node count.
void checkNodes(const std::vector<std::uint32_t>& nodes, std::size_t nodeCount, const std::string& body,
                const char* call) {
  for (std::uint32_t n : nodes)
    if (n >= nodeCount)
      detail::fail(ErrorCode::BadInput, call, ": node ", n, " is not a node of body '", body, "' (it has ", nodeCount,
                   " nodes, numbered from 0)");
}

/// Barycentric weights of p in element e at positions x (they sum to 1; all >= 0 inside).
Eigen::Vector4d barycentric(const TetMesh& mesh, const Eigen::VectorXd& x, std::size_t e, const Vec3d& p) {
  Vec3d c[4];
  for (int k = 0; k < 4; ++k) c[k] = x.segment<3>(3 * static_cast<Eigen::Index>(mesh.tets[4 * e + k]));
  Mat3d D;
  D << c[1] - c[0], c[2] - c[0], c[3] - c[0];
  const Vec3d w = D.partialPivLu().solve(p - c[0]);
  return Eigen::Vector4d(1.0 - w.sum(), w[0], w[1], w[2]);
}

}  // namespace

Simulation::Impl::Body& Simulation::Impl::controlled(int index, const char* call) {
  Body& b = const_cast<Body&>(body(index));
  if (isStatic())
    detail::fail(ErrorCode::BadInput, call, ": run-time control acts on a dynamic analysis; this scene's is static "
                 "(analysis.type \"static\"): use \"dynamic\" to hold bodies at run time");
  Body::Hold& h = b.hold;
  if (h.holder.empty()) {
    h.scene = b.problem->constrained;
    h.holder.assign(b.mesh.nodeCount(), Body::Hold::kScene);
    h.targets = Eigen::VectorXd::Constant(static_cast<Eigen::Index>(h.scene.size()), std::nan(""));
  }
  return b;
}

void Simulation::Impl::touched(Body& b) {
  b.sleep.asleep = false;
  b.sleep.quiet = 0;
  for (SurfaceSet& set : groups[b.group].surfaces) set.dirty = true;
}

void Simulation::Impl::applyHolds(Group& g) {
  detail::BodySet changed;
  for (std::size_t i : g.bodies) {
    Body& b = bodies[i];
    Body::Hold& h = b.hold;
    if (h.constraintsChanged) {
      // A dof is constrained when an application holds its node, or the scene does and the
      // application has not released it.
      std::vector<std::uint8_t>& c = b.problem->constrained;
      for (std::size_t d = 0; d < c.size(); ++d) {
        const int holder = h.holder[d / 3];
        c[d] = holder >= Body::Hold::kPinned || (h.scene[d] && holder == Body::Hold::kScene) ? 1 : 0;
      }
      changed.push_back(b.index);
    }
  }
  if (!changed.empty()) {
    g.slot->setConstraints(changed);
    for (std::size_t index : changed) g.driver->constraintsChanged(index);
  }
  detail::BodySet stiffened, sprung;
  for (std::size_t i : g.bodies) {
    if (bodies[i].hold.materialChanged) stiffened.push_back(bodies[i].index);
    if (bodies[i].hold.springsChanged) {
      bodies[i].problem->springStiffness = bodies[i].hold.springStiffness;
      sprung.push_back(bodies[i].index);
    }
  }
  if (!stiffened.empty()) {
    g.slot->setMaterial(stiffened);
    for (std::size_t index : stiffened) g.driver->materialChanged(index);
  }
  if (!sprung.empty()) {
    g.slot->setSprings(sprung);
    for (std::size_t index : sprung) g.driver->loadsChanged(index);
  }
  for (std::size_t i : g.bodies) {
    Body& b = bodies[i];
    Body::Hold& h = b.hold;
    h.constraintsChanged = h.materialChanged = h.springsChanged = false;
    if (h.controlsChanged) g.driver->setControls(b.index, detail::BodyControls{h.targets, h.forces, h.springTargets});
    h.controlsChanged = false;
    if (h.restart) {
      // The last step failed: this one starts from the last good positions at rest.
      const Eigen::VectorXd x = g.driver->positions(b.index);
      g.driver->setState(b.index, x, Eigen::VectorXd::Zero(x.size()));
      h.restart = false;
    }
  }
}

void Simulation::Impl::placeHandle(int id, const double target[3], const double* rotation) {
  Handle& handle = handles.at(id);
  Body& b = bodies[handle.body];
  Body::Hold& h = b.hold;
  const Mat3d R = rotation ? rotationOf(rotation, "moveHandle") : Mat3d::Identity();
  for (int k = 0; k < 3; ++k) handle.target[k] = target[k];
  store(R, handle.rotation);
  const Vec3d c = vec3(handle.centroid), t = vec3(target);
  if (handle.stiffness > 0.0) {
    rebuildSprings(b);
  } else {
    for (std::size_t k = 0; k < handle.nodes.size(); ++k) {
      const std::uint32_t n = handle.nodes[k];
      if (h.holder[n] != id) continue;  // taken by a newer handle or pin
      const Vec3d g(handle.grabbed[3 * k], handle.grabbed[3 * k + 1], handle.grabbed[3 * k + 2]);
      h.targets.segment<3>(3 * static_cast<Eigen::Index>(n)) = t + R * (g - c);
    }
  }
  h.controlsChanged = true;
  touched(b);
}

Simulation::Impl::Handle& Simulation::Impl::handleFor(int id, const char* call) {
  const auto it = handles.find(id);
  if (it == handles.end())
    detail::fail(ErrorCode::BadInput, call, ": there is no handle ", id,
                 "; use an id addHandle returned and that was not removed");
  return it->second;
}

void Simulation::Impl::takeNodes(int id) {
  Handle& handle = handles.at(id);
  Body::Hold& h = bodies[handle.body].hold;
  handle.previous.clear();
  for (std::uint32_t n : handle.nodes) {
    handle.previous.push_back(h.holder[n]);
    h.holder[n] = id;
  }
  h.constraintsChanged = true;
}

void Simulation::Impl::releaseNodes(int id) {
  // Each node the handle still holds goes back to what held it before: the scene (or its
  // release), a pin (where the node is now), or an older handle that still exists.
  const Handle& released = handles.at(id);
  Body& b = bodies[released.body];
  Body::Hold& h = b.hold;
  const Eigen::VectorXd& x = driverOf(b).positions(b.index);
  std::vector<int> regrab;
  for (std::size_t k = 0; k < released.nodes.size() && k < released.previous.size(); ++k) {
    const std::uint32_t n = released.nodes[k];
    if (h.holder[n] != id) continue;
    int previous = released.previous[k];
    if (previous > Body::Hold::kPinned && (handles.count(previous) == 0 || previous == id)) previous = Body::Hold::kScene;
    h.holder[n] = previous;
    const Eigen::Index d = 3 * static_cast<Eigen::Index>(n);
    if (previous == Body::Hold::kPinned) h.targets.segment<3>(d) = x.segment<3>(d);
    else h.targets.segment<3>(d).setConstant(std::nan(""));
    if (previous > Body::Hold::kPinned) regrab.push_back(previous);
  }
  // Newer handles that took nodes from this one will give them back to what held them before it:
  // it holds no node from now on (it goes, or becomes a spring).
  for (auto& [other, handle] : handles) {
    if (other == id || handle.body != released.body) continue;
    for (std::size_t j = 0; j < handle.previous.size(); ++j) {
      if (handle.previous[j] != id) continue;
      const auto k = std::find(released.nodes.begin(), released.nodes.end(), handle.nodes[j]) - released.nodes.begin();
      handle.previous[j] = static_cast<std::size_t>(k) < released.previous.size() ? released.previous[static_cast<std::size_t>(k)]
                                                                                    : Body::Hold::kScene;
    }
  }
  for (int older : regrab) {
    const Handle& o = handles.at(older);
    placeHandle(older, o.target, o.rotation);
  }
  h.constraintsChanged = h.controlsChanged = true;
}

void Simulation::Impl::rebuildSprings(Body& b) {
  Body::Hold& h = b.hold;
  const Eigen::Index dofs = static_cast<Eigen::Index>(3 * b.mesh.nodeCount());
  const std::size_t scene = static_cast<std::size_t>(&b - bodies.data());
  Eigen::VectorXd k = Eigen::VectorXd::Zero(dofs), kt = Eigen::VectorXd::Zero(dofs);
  bool any = false;
  for (const auto& [id, handle] : handles) {
    if (handle.body != scene || !(handle.stiffness > 0.0)) continue;
    any = true;
    const Mat3d R = matrixOf(handle.rotation);
    const Vec3d c = vec3(handle.centroid), t = vec3(handle.target);
    for (std::size_t j = 0; j < handle.nodes.size(); ++j) {
      const Eigen::Index d = 3 * static_cast<Eigen::Index>(handle.nodes[j]);
      const Vec3d g(handle.grabbed[3 * j], handle.grabbed[3 * j + 1], handle.grabbed[3 * j + 2]);
      const double kn = handle.stiffness * handle.weights[j];
      k.segment<3>(d).array() += kn;
      kt.segment<3>(d) += kn * (t + R * (g - c));
    }
  }
  if (!any) {
    h.springsChanged = h.springsChanged || h.springStiffness.size() != 0;
    h.springStiffness.resize(0);
    h.springTargets.resize(0);
  } else {
    // Where no spring pulls, the target is x's own (k = 0 there: never read).
    h.springTargets = (k.array() > 0.0).select(kt.array() / k.array(), 0.0).matrix();
    h.springsChanged = h.springsChanged || h.springStiffness.size() != k.size() || h.springStiffness != k;
    h.springStiffness = std::move(k);
  }
  h.controlsChanged = true;
}

Result<int> Simulation::addHandle(const HandleDesc& desc) {
  return detail::guardResult<int>([&] {
    Impl& s = *impl_;
    Impl::Body& b = s.controlled(desc.body, "addHandle");
    const Eigen::VectorXd& x = s.driverOf(b).positions(b.index);
    const std::size_t nodeCount = b.mesh.nodeCount();
    checkStiffness(desc.stiffness, "addHandle");
    Impl::Handle handle;
    handle.body = static_cast<std::size_t>(desc.body);
    handle.stiffness = desc.stiffness;
    handle.nodes = desc.nodes;
    if (handle.nodes.empty() && desc.surfaceVertex >= 0) {
      if (!b.binding)
        detail::fail(ErrorCode::BadInput, "addHandle: body '", b.problem->name, "' has no render surface; pick nodes or "
                     "a point instead of a surface vertex, or give the body a \"surface\"");
      const std::size_t v = static_cast<std::size_t>(desc.surfaceVertex);
      if (v >= b.binding->element.size())
        detail::fail(ErrorCode::BadInput, "addHandle: surface vertex ", v, " is not one of body '", b.problem->name,
                     "''s ", b.binding->element.size(), " surface vertices (numbered from 0)");
      handle.nodes.assign(b.binding->nodes.begin() + static_cast<std::ptrdiff_t>(4 * v),
                          b.binding->nodes.begin() + static_cast<std::ptrdiff_t>(4 * v + 4));
    }
    const bool onVertex = desc.nodes.empty() && desc.surfaceVertex >= 0;
    if (handle.nodes.empty()) {
      if (!finite3(desc.point) || !(desc.radius >= 0.0) || !std::isfinite(desc.radius))
        detail::fail(ErrorCode::BadInput, "addHandle: the point must be finite and the radius a finite number >= 0 (m)");
      const Vec3d p = vec3(desc.point);
      std::uint32_t nearest = 0;
      double best = std::numeric_limits<double>::infinity();
      for (std::size_t n = 0; n < nodeCount; ++n) {
        const double d = (x.segment<3>(3 * static_cast<Eigen::Index>(n)) - p).norm();
        if (d <= desc.radius) handle.nodes.push_back(static_cast<std::uint32_t>(n));
        if (d < best) {
          best = d;
          nearest = static_cast<std::uint32_t>(n);
        }
      }
      if (handle.nodes.empty()) handle.nodes.push_back(nearest);
    } else {
      checkNodes(handle.nodes, nodeCount, b.problem->name, "addHandle");
      std::sort(handle.nodes.begin(), handle.nodes.end());
      handle.nodes.erase(std::unique(handle.nodes.begin(), handle.nodes.end()), handle.nodes.end());
    }
    Vec3d c = Vec3d::Zero();
    for (std::uint32_t n : handle.nodes) {
      const Vec3d g = x.segment<3>(3 * static_cast<Eigen::Index>(n));
      handle.grabbed.insert(handle.grabbed.end(), {g[0], g[1], g[2]});
      c += g;
    }
    c /= static_cast<double>(handle.nodes.size());
    handle.weights.assign(handle.nodes.size(), 1.0 / static_cast<double>(handle.nodes.size()));
    if (onVertex) {
      // The target places the vertex itself: x_v = sum w_k x_k, and the weights sum to 1. A spring
      // pulls each node by its weight's share, clamped to >= 0 (a vertex outside the mesh has
      // negative ones): a rigid offset d of the element gives the force k d.
      c.setZero();
      const std::size_t v = static_cast<std::size_t>(desc.surfaceVertex);
      double sum = 0.0;
      for (std::size_t k = 0; k < 4; ++k) {
        const double w = b.binding->weights[4 * v + k];
        c += w * x.segment<3>(3 * static_cast<Eigen::Index>(b.binding->nodes[4 * v + k]));
        handle.weights[k] = std::max(0.0, w);
        sum += handle.weights[k];
      }
      for (double& w : handle.weights) w = sum > 0.0 ? w / sum : 0.25;
    }
    for (int k = 0; k < 3; ++k) handle.centroid[k] = c[k];
    const int id = s.nextHandle++;
    s.handles.emplace(id, std::move(handle));
    if (desc.stiffness == 0.0) s.takeNodes(id);
    s.placeHandle(id, s.handles.at(id).centroid, nullptr);  // held where they are
    return id;
  });
}

Status Simulation::moveHandle(int handle, const double target[3], const double* rotation) {
  return detail::guard([&] {
    Impl& s = *impl_;
    (void)s.handleFor(handle, "moveHandle");
    if (!finite3(target)) detail::fail(ErrorCode::BadInput, "moveHandle: the target must be finite (m)");
    s.placeHandle(handle, target, rotation);
  });
}

Status Simulation::removeHandle(int handle) {
  return detail::guard([&] {
    Impl& s = *impl_;
    const Impl::Handle& h = s.handleFor(handle, "removeHandle");
    Impl::Body& b = s.bodies[h.body];
    const bool spring = h.stiffness > 0.0;
    if (!spring) s.releaseNodes(handle);
    s.handles.erase(handle);
    if (spring) s.rebuildSprings(b);
    s.touched(b);
  });
}

Status Simulation::setHandleStiffness(int handle, double stiffness) {
  return detail::guard([&] {
    Impl& s = *impl_;
    Impl::Handle& h = s.handleFor(handle, "setHandleStiffness");
    checkStiffness(stiffness, "setHandleStiffness");
    Impl::Body& b = s.bodies[h.body];
    const bool wasHard = h.stiffness == 0.0;
    if (wasHard && stiffness > 0.0) s.releaseNodes(handle);
    h.stiffness = stiffness;
    if (!wasHard && stiffness == 0.0) s.takeNodes(handle);
    s.placeHandle(handle, h.target, h.rotation);  // a spring's: rebuildSprings
    if (!wasHard && stiffness == 0.0) s.rebuildSprings(b);  // a spring no more
  });
}

Status Simulation::pinNodes(int body, const std::vector<std::uint32_t>& nodes) {
  return detail::guard([&] {
    Impl& s = *impl_;
    Impl::Body& b = s.controlled(body, "pinNodes");
    checkNodes(nodes, b.mesh.nodeCount(), b.problem->name, "pinNodes");
    const Eigen::VectorXd& x = s.driverOf(b).positions(b.index);
    Impl::Body::Hold& h = b.hold;
    for (std::uint32_t n : nodes) {
      h.holder[n] = Impl::Body::Hold::kPinned;
      const Eigen::Index d = 3 * static_cast<Eigen::Index>(n);
      h.targets.segment<3>(d) = x.segment<3>(d);
    }
    h.constraintsChanged = h.controlsChanged = true;
    s.touched(b);
  });
}

Status Simulation::unpinNodes(int body, const std::vector<std::uint32_t>& nodes) {
  return detail::guard([&] {
    Impl& s = *impl_;
    Impl::Body& b = s.controlled(body, "unpinNodes");
    checkNodes(nodes, b.mesh.nodeCount(), b.problem->name, "unpinNodes");
    Impl::Body::Hold& h = b.hold;
    for (std::uint32_t n : nodes) {
      if (h.holder[n] > Impl::Body::Hold::kPinned) continue;  // a handle's
      h.holder[n] = Impl::Body::Hold::kReleased;
      h.targets.segment<3>(3 * static_cast<Eigen::Index>(n)).setConstant(std::nan(""));
    }
    h.constraintsChanged = h.controlsChanged = true;
    s.touched(b);
  });
}

Status Simulation::setForces(int body, const std::vector<AppliedForce>& forces) {
  return detail::guard([&] {
    Impl& s = *impl_;
    Impl::Body& b = s.controlled(body, "setForces");
    const Eigen::VectorXd& x = s.driverOf(b).positions(b.index);
    const TetMesh& mesh = b.problem->mesh;
    Eigen::VectorXd f = Eigen::VectorXd::Zero(x.size());
    TetMesh deformed;
    std::unique_ptr<detail::ElementLocator> locator;
    std::vector<std::uint32_t> stamp;
    std::uint32_t stampId = 0;
    bool triedLocator = false;
    for (std::size_t i = 0; i < forces.size(); ++i) {
      const AppliedForce& a = forces[i];
      if (!finite3(a.force) || (a.node < 0 && !finite3(a.point)))
        detail::fail(ErrorCode::BadInput, "setForces: force ", i, " has a non-finite force or point; give finite ",
                     "numbers (N, m)");
      if (a.node < -1)
        detail::fail(ErrorCode::BadInput, "setForces: force ", i, " has node ", a.node,
                     "; give a node index >= 0, or -1 for a force at its point");
      const Vec3d force = vec3(a.force);
      if (a.node >= 0) {
        checkNodes({static_cast<std::uint32_t>(a.node)}, mesh.nodeCount(), b.problem->name, "setForces");
        f.segment<3>(3 * static_cast<Eigen::Index>(a.node)) += force;
        continue;
      }
      // The element containing the point at the current positions, or outside the body the
      // nearest one, its weights clamped to >= 0 and normalised: found through a grid of the
      // deformed elements' boxes, made once per call (O(elements + forces)).
      const Vec3d p = vec3(a.point);
      if (!triedLocator) {
        triedLocator = true;
        deformed.nodes.assign(x.data(), x.data() + x.size());
        deformed.tets = mesh.tets;
        try {
          locator = std::make_unique<detail::ElementLocator>(deformed, 0.0);
        } catch (const detail::Error&) {
          // A flat element at the current positions: every element is tried instead.
        }
      }
      Eigen::Vector4d weights(0.25, 0.25, 0.25, 0.25);
      std::size_t element = 0;
      std::uint32_t found = detail::ElementLocator::kNone;
      if (locator) {
        const detail::Point3 q{p[0], p[1], p[2]};
        double w[4];
        found = locator->findContaining(q, w);
        if (found == detail::ElementLocator::kNone) {
          if (stamp.empty()) stamp.assign(locator->elementCount(), 0u);
          found = locator->findNearest(q, std::numeric_limits<double>::infinity(), stamp, stampId).element;
          if (found != detail::ElementLocator::kNone) locator->barycentric(found, q, w);
        }
        if (found != detail::ElementLocator::kNone) {
          element = found;
          weights = Eigen::Vector4d(w[0], w[1], w[2], w[3]);
        }
      }
      if (found == detail::ElementLocator::kNone) {
        double best = -std::numeric_limits<double>::infinity();
        for (std::size_t e = 0; e < mesh.tetCount(); ++e) {
          const Eigen::Vector4d w = barycentric(mesh, x, e, p);
          if (w.allFinite() && w.minCoeff() > best) {
            best = w.minCoeff();
            weights = w;
            element = e;
          }
        }
      }
      weights = weights.cwiseMax(0.0);
      weights /= weights.sum();
      for (int k = 0; k < 4; ++k)
        f.segment<3>(3 * static_cast<Eigen::Index>(mesh.tets[4 * element + k])) += weights[k] * force;
    }
    b.hold.forces = forces.empty() ? Eigen::VectorXd() : std::move(f);
    b.hold.controlsChanged = true;
    s.touched(b);
  });
}

Status Simulation::setMaterial(int body, double youngsModulus, double poissonRatio, double rayleighMass,
                               double rayleighStiffness) {
  return detail::guard([&] {
    Impl& s = *impl_;
    Impl::Body& b = s.controlled(body, "setMaterial");
    const detail::Lame lame = detail::lameFromYoungPoisson(youngsModulus, poissonRatio);  // BadInput when out of range
    if (!(rayleighMass >= 0.0) || !(rayleighStiffness >= 0.0) || !std::isfinite(rayleighMass) ||
        !std::isfinite(rayleighStiffness))
      detail::fail(ErrorCode::BadInput, "setMaterial: the Rayleigh coefficients must be finite and >= 0 (got ",
                   rayleighMass, " 1/s and ", rayleighStiffness, " s)");
    b.problem->lame = lame;
    b.problem->rayleighMass = rayleighMass;
    b.problem->rayleighStiffness = rayleighStiffness;
    b.hold.materialChanged = true;
    s.touched(b);
  });
}

Status Simulation::setGravity(const double gravity[3]) {
  return detail::guard([&] {
    Impl& s = *impl_;
    if (!finite3(gravity)) detail::fail(ErrorCode::BadInput, "setGravity: the gravity must be finite (m/s^2)");
    for (std::size_t i = 0; i < s.bodies.size(); ++i) (void)s.controlled(static_cast<int>(i), "setGravity");
    for (Impl::Body& b : s.bodies) {
      std::vector<detail::ExternalForce>& loads = b.problem->forces;
      loads.erase(std::remove_if(loads.begin(), loads.end(), [](const detail::ExternalForce& f) { return f.gravity; }),
                  loads.end());
      loads.push_back(detail::ExternalForce{detail::gravityForce(*b.problem, gravity), 0.0, /*gravity=*/true});
      s.driverOf(b).loadsChanged(b.index);
      s.touched(b);
    }
  });
}

Status Simulation::setPositions(int body, const std::vector<double>& positions) {
  return detail::guard([&] {
    Impl& s = *impl_;
    Impl::Body& b = s.controlled(body, "setPositions");
    detail::Driver& driver = s.driverOf(b);
    const Eigen::VectorXd x = Eigen::Map<const Eigen::VectorXd>(positions.data(), static_cast<Eigen::Index>(positions.size()));
    driver.setState(b.index, x, driver.velocities(b.index));
    b.hold.restart = false;  // the application's state replaces the failure's restart
    s.touched(b);
  });
}

Status Simulation::setVelocities(int body, const std::vector<double>& velocities) {
  return detail::guard([&] {
    Impl& s = *impl_;
    Impl::Body& b = s.controlled(body, "setVelocities");
    detail::Driver& driver = s.driverOf(b);
    const Eigen::VectorXd v = Eigen::Map<const Eigen::VectorXd>(velocities.data(), static_cast<Eigen::Index>(velocities.size()));
    driver.setState(b.index, driver.positions(b.index), v);
    b.hold.restart = false;
    s.touched(b);
  });
}

Status Simulation::resetBody(int body) {
  return detail::guard([&] {
    Impl& s = *impl_;
    Impl::Body& b = s.controlled(body, "resetBody");
    const Eigen::VectorXd& rest = b.problem->restPositions;
    s.driverOf(b).setState(b.index, rest, Eigen::VectorXd::Zero(rest.size()));
    b.hold.restart = false;
    s.touched(b);
  });
}

Status Simulation::teleport(int body, const double rotation[9], const double translation[3]) {
  return detail::guard([&] {
    Impl& s = *impl_;
    Impl::Body& b = s.controlled(body, "teleport");
    const Mat3d R = rotationOf(rotation, "teleport");
    if (!finite3(translation)) detail::fail(ErrorCode::BadInput, "teleport: the translation must be finite (m)");
    Impl::Body::Hold& h = b.hold;
    for (std::size_t d = 0; d < h.scene.size(); ++d)
      if (h.scene[d] && h.holder[d / 3] == Impl::Body::Hold::kScene)
        detail::fail(ErrorCode::BadInput, "teleport: body '", b.problem->name, "' is held by the scene at node ", d / 3,
                     " (a fixed or prescribed node); release its supports with unpinNodes first, or move it "
                     "with a handle");
    const Vec3d t = vec3(translation);
    detail::Driver& driver = s.driverOf(b);
    Eigen::VectorXd x = driver.positions(b.index), v = driver.velocities(b.index);
    for (Eigen::Index n = 0; n + 2 < x.size(); n += 3) {
      x.segment<3>(n) = R * x.segment<3>(n) + t;
      v.segment<3>(n) = R * v.segment<3>(n);
    }
    driver.setState(b.index, x, v);  // throws (nothing changed) for a non-finite result
    b.hold.restart = false;
    // The holds move with the body: held targets, and the handles' grab points, centroids and targets.
    for (Eigen::Index n = 0; n + 2 < x.size(); n += 3)
      if (!std::isnan(h.targets[n])) h.targets.segment<3>(n) = R * h.targets.segment<3>(n) + t;
    for (auto& [id, handle] : s.handles) {
      if (handle.body != static_cast<std::size_t>(body)) continue;
      for (std::size_t k = 0; k < handle.nodes.size(); ++k) {
        const Vec3d g = R * Vec3d(handle.grabbed[3 * k], handle.grabbed[3 * k + 1], handle.grabbed[3 * k + 2]) + t;
        for (int c = 0; c < 3; ++c) handle.grabbed[3 * k + static_cast<std::size_t>(c)] = g[c];
      }
      const Vec3d c = R * vec3(handle.centroid) + t, target = R * vec3(handle.target) + t;
      const Mat3d rotated = R * matrixOf(handle.rotation) * R.transpose();  // the handle's rotation seen in the moved frame
      for (int k = 0; k < 3; ++k) {
        handle.centroid[k] = c[k];
        handle.target[k] = target[k];
      }
      store(rotated, handle.rotation);
    }
    s.rebuildSprings(b);
    h.controlsChanged = true;
    s.touched(b);
  });
}

}  // namespace corofem
