// Segments, device numbering and staging of the device backends (body_layout.hpp).
#include "device/body_layout.hpp"

#include "mesh/locality_order.hpp"
#include "util/error.hpp"

#include <optional>

namespace corofem::detail {

namespace {

std::size_t roundUp(std::size_t n, std::size_t m) { return (n + m - 1) / m * m; }

/// What a device reads of `p` (mesh, element rest states, rest positions, lumped mass,
/// constraints, material) in the numbering `order`; loads, prescribed displacements and initial
/// velocities stay with the solver and are not copied.
Problem reorderedProblem(const Problem& p, const LocalityOrder& order) {
  Problem q;
  q.name = p.name;
  q.lame = p.lame;
  q.density = p.density;
  q.rayleighMass = p.rayleighMass;
  q.rayleighStiffness = p.rayleighStiffness;
  q.formulation = p.formulation;
  q.rotation = p.rotation;
  const std::size_t nodes = order.nodes.size(), elements = order.elements.size();
  q.mesh.nodes.resize(3 * nodes);
  q.restPositions.resize(static_cast<Eigen::Index>(3 * nodes));
  const bool mass = static_cast<std::size_t>(p.lumpedMass.size()) == 3 * nodes;
  const bool constrained = p.constrained.size() == 3 * nodes;
  if (mass) q.lumpedMass.resize(static_cast<Eigen::Index>(3 * nodes));
  if (constrained) q.constrained.resize(3 * nodes);
  for (std::size_t i = 0; i < nodes; ++i)
    for (std::size_t k = 0; k < 3; ++k) {
      const std::size_t from = 3 * std::size_t{order.nodes[i]} + k, to = 3 * i + k;
      q.mesh.nodes[to] = p.mesh.nodes[from];
      q.restPositions[static_cast<Eigen::Index>(to)] = p.restPositions[static_cast<Eigen::Index>(from)];
      if (mass) q.lumpedMass[static_cast<Eigen::Index>(to)] = p.lumpedMass[static_cast<Eigen::Index>(from)];
      if (constrained) q.constrained[to] = p.constrained[from];
    }
  q.mesh.tets.resize(4 * elements);
  q.elements.reserve(elements);
  for (std::size_t i = 0; i < elements; ++i) {
    const std::uint32_t e = order.elements[i];
    for (std::size_t k = 0; k < 4; ++k) q.mesh.tets[4 * i + k] = order.nodeOf[p.mesh.tets[4 * std::size_t{e} + k]];
    q.elements.push_back(p.elements[e]);
    if (!p.mesh.regions.empty()) q.mesh.regions.push_back(p.mesh.regions[e]);
  }
  return q;
}

}  // namespace

BodyLayout::BodyLayout(const std::vector<const Problem*>& problems, int order, std::size_t elementAlign,
                       std::size_t nodeAlign, std::size_t maxComponents) {
  reordered_.resize(problems.size());
  for (std::size_t index = 0; index < problems.size(); ++index) {
    const Problem& original = *problems[index];
    if (original.elements.size() != original.mesh.tetCount() || original.dofCount() != 3 * original.mesh.nodeCount())
      fail(ErrorCode::Internal, "device layout: problem '", original.name, "' has ", original.elements.size(),
           " element rest states for ", original.mesh.tetCount(), " tets and ", original.dofCount(), " dofs for ",
           original.mesh.nodeCount(), " nodes");
    if (original.mesh.tetCount() == 0) fail(ErrorCode::BadInput, "body '", original.name, "' has no elements");
    BodySegment sg;
    sg.problem = &original;
    // Each body its own numbering, as alone (a batched body's bits are its own run's): copies of one
    // mesh that are only moved get the same order.
    const bool small = original.mesh.tetCount() * maxComponents < (std::size_t(1) << 32) / 2 &&
                       9 * original.mesh.nodeCount() < (std::size_t(1) << 32) / 2;
    if (order != 0 && small) {
      std::optional<LocalityOrder> o = order == 1 ? mortonOrder(original.mesh) : localityOrder(original.mesh);
      if (o) {
        reordered_[index] = std::make_unique<Problem>(reorderedProblem(original, *o));
        sg.hostNode = std::move(o->nodes);
        sg.deviceNode = std::move(o->nodeOf);
        sg.hostElem = std::move(o->elements);
      }
    }
    const Problem& p = reordered_[index] ? *reordered_[index] : original;
    sg.nodes = p.mesh.nodeCount();
    sg.elems = p.mesh.tetCount();
    sg.elemBegin = elementTotal;
    sg.elemSpan = roundUp(sg.elems, elementAlign);
    elementTotal += sg.elemSpan;
    sg.nodeBegin = nodeTotal;
    sg.nodeSpan = roundUp(std::max<std::size_t>(sg.nodes, 1), nodeAlign);
    nodeTotal += sg.nodeSpan;
    sg.corotational = p.formulation == Formulation::Corotational;
    sg.rayleighMass = p.rayleighMass;
    sg.rayleighStiffness = p.rayleighStiffness;
    sg.constrained.assign(3 * sg.nodes, 0);
    if (p.constrained.size() == 3 * sg.nodes) sg.constrained = p.constrained;
    segments.push_back(std::move(sg));
  }
}

std::vector<Eigen::Index> segmentFreeDofs(const BodySegment& sg, std::vector<std::size_t>* deviceDofs) {
  std::vector<std::uint8_t> constrained(sg.dofs());
  std::vector<std::size_t> deviceDof(sg.dofs());
  for (std::size_t d = 0; d < sg.dofs(); ++d) {
    constrained[sg.hostDof(d)] = sg.constrained[d];
    deviceDof[sg.hostDof(d)] = d;
  }
  std::vector<Eigen::Index> free;
  if (deviceDofs) deviceDofs->clear();
  for (std::size_t d = 0; d < constrained.size(); ++d)
    if (!constrained[d]) {
      free.push_back(static_cast<Eigen::Index>(d));
      if (deviceDofs) deviceDofs->push_back(deviceDof[d]);
    }
  return free;
}

void getReals(const unsigned char* base, bool isDouble, const BodySegment& sg, std::size_t chunk, Eigen::VectorXd& out) {
  out.resize(static_cast<Eigen::Index>(sg.dofs()));
  parallelChunks(sg.dofs(), chunk, [&](std::size_t, std::size_t lo, std::size_t hi) {
    withReals(base, isDouble, sg.dofBegin(), [&](const auto* in) {
      if (sg.hostNode.empty())
        for (std::size_t d = lo; d < hi; ++d) out[static_cast<Eigen::Index>(d)] = static_cast<double>(in[d]);
      else
        for (std::size_t d = lo; d < hi; ++d) out[static_cast<Eigen::Index>(sg.hostDof(d))] = static_cast<double>(in[d]);
    });
  });
}

}  // namespace corofem::detail
