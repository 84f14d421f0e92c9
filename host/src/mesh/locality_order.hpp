// A numbering of a tet mesh's elements and nodes for memory locality: what the OpenCL backend
// gives its kernels when the mesh's own numbering scatters their loads (meshes from Gmsh, TetGen
// and most files number elements in an order unrelated to space). Host vectors keep the user's
// numbering; only the device's layout changes (backends/opencl/segment_engine.cpp).
#pragma once

#include <corofem/mesh.hpp>

#include <cstdint>
#include <optional>
#include <vector>

namespace corofem::detail {

/// The new numbering, as lists of old indices: element i of the new order is old element
/// elements[i], node i is old node nodes[i]; nodeOf[old node] is its new index.
struct LocalityOrder {
  std::vector<std::uint32_t> elements;
  std::vector<std::uint32_t> nodes;
  std::vector<std::uint32_t> nodeOf;
};

/// Mean over consecutive elements of |lowest node index of e - lowest node index of e-1|: how far
/// the element kernels' node loads jump between neighbours in the element order (0.2 for the box
/// generator's layered numbering; thousands for the Gmsh meshes of ../shared/data).
double meanNodeJump(const std::vector<std::uint32_t>& tets, const std::vector<std::uint32_t>* elementOrder = nullptr,
                    const std::vector<std::uint32_t>* nodeOf = nullptr);

/// The 21 low bits of v spread to every third bit: one axis of a 63-bit Morton code.
std::uint64_t mortonSpreadBits(std::uint64_t v);

/// Whether a numbering with mean node jump `mortonJump` is worth taking over one with `ownJump`
/// (localityOrder's rule: at most half).
bool mortonIsMoreLocal(double ownJump, double mortonJump);

/// Elements sorted along a Morton (Z-order) curve of their centroids (ties: old index), nodes
/// numbered in the order those elements first use them. Deterministic: depends on the mesh only.
LocalityOrder mortonOrder(const TetMesh& mesh);

/// mortonOrder(mesh) where it at least halves meanNodeJump against the mesh's own numbering, else
/// nothing (the numbering is kept). Measured (bench_mesh_order, PoCL, 2 cores): the step with 20
/// PCG iterations 1.43-1.55x faster on Gmsh/VTK meshes reordered, while the box generator's
/// layered numbering (6 tets per cell: jump 0.2; 5: 2-16), which the Morton order does not beat
/// (forced on the 100k box: 12-18 % slower), stays as it is.
std::optional<LocalityOrder> localityOrder(const TetMesh& mesh);

}  // namespace corofem::detail
