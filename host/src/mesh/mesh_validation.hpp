// The one place where every tet-mesh reader's output is checked and turned into a TetMesh:
// node numbering (file ids -> 0-based), index range, repeated nodes, orientation, zero volume.
#pragma once

#include <corofem/mesh.hpp>

#include <cstdint>
#include <string>
#include <vector>

namespace corofem::mesh {

/// A tet mesh as a reader found it, in the file's own numbering.
struct ParsedTetMesh {
  std::vector<double> nodes;                ///< 3 per node, finite (readers check with readCoordinates)
  std::vector<std::int64_t> nodeIds;        ///< file id of each node; empty: ids are nodeBase + i
  std::int64_t nodeBase = 0;                ///< id of the first node when nodeIds is empty
  std::vector<std::int64_t> tets;           ///< 4 per element, file node ids
  std::vector<std::int64_t> elementIds;     ///< file id of each element; empty: 1-based ordinal
  std::vector<std::uint32_t> elementLines;  ///< line of each element in the file (for messages)
  std::vector<std::uint32_t> nodeLines;     ///< line of each node (only needed when nodeIds is set)
  std::vector<std::int32_t> regions;        ///< one per element or empty
  const char* elementWord = "element";      ///< "element" or "cell" in messages
};

/// Maps ids, checks every element and reorients negative ones (see MeshValidation). Throws
/// BadInput naming the file, the line and the element on: unknown or out-of-range node, a node used
/// twice in one element, zero or near-zero volume, duplicate node ids.
TetMesh finalizeTetMesh(ParsedTetMesh&& parsed, const std::string& path, const MeshValidation& validation,
                        MeshReadReport* report);

/// What is wrong with the size of a box (BoxSpec with valid cells and tetsPerCell), or "": more
/// tetrahedra than limits.maxBoxTets, or more nodes than 32-bit indices reach. The text starts with
/// the number of tetrahedra and names the limit and the fix.
std::string boxSizeProblem(const BoxSpec& spec, const InputLimits& limits);

/// Reorients (swaps nodes 2 and 3 of) negatively oriented elements; returns how many. Used by
/// finalizeTetMesh and the generators.
std::size_t reorientElements(TetMesh& mesh);

}  // namespace corofem::mesh
