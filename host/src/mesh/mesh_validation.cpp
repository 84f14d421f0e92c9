// Validation on load, shared by every tet-mesh reader.
#include "mesh/mesh_validation.hpp"

#include "util/error.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <unordered_map>
#include <utility>

namespace corofem::mesh {
namespace {

/// 6 V = (b-a) . ((c-a) x (d-a)) for the element's four node positions.
double sixVolume(const double* nodes, const std::uint32_t* t) {
  const double* a = nodes + 3 * std::size_t(t[0]);
  const double* b = nodes + 3 * std::size_t(t[1]);
  const double* c = nodes + 3 * std::size_t(t[2]);
  const double* d = nodes + 3 * std::size_t(t[3]);
  const double e1[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
  const double e2[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
  const double e3[3] = {d[0] - a[0], d[1] - a[1], d[2] - a[2]};
  return e1[0] * (e2[1] * e3[2] - e2[2] * e3[1]) - e1[1] * (e2[0] * e3[2] - e2[2] * e3[0]) +
         e1[2] * (e2[0] * e3[1] - e2[1] * e3[0]);
}

/// File id -> 0-based node index.
class NodeIdMap {
 public:
  NodeIdMap(const ParsedTetMesh& parsed, const std::string& path) {
    const std::size_t n = parsed.nodes.size() / 3;
    count_ = n;
    if (parsed.nodeIds.empty()) {
      base_ = parsed.nodeBase;
      return;
    }
    // Fast path: consecutive ids (the usual case). Ids come from the file and may be anywhere in
    // the 64-bit range: every sum and difference below is checked or unsigned.
    const auto& ids = parsed.nodeIds;
    bool consecutive = true;
    for (std::size_t i = 0; i < n && consecutive; ++i) {
      // ids[0] + i without overflow (i >= 0; standard C++, no compiler builtin: MSVC has none).
      const auto step = static_cast<std::int64_t>(i);
      consecutive = ids[0] <= std::numeric_limits<std::int64_t>::max() - step && ids[i] == ids[0] + step;
    }
    if (consecutive) {
      base_ = n ? ids[0] : 0;
      return;
    }
    const auto [mn, mx] = std::minmax_element(ids.begin(), ids.end());
    min_ = *mn;
    max_ = *mx;
    auto lineOf = [&](std::size_t i) { return i < parsed.nodeLines.size() ? parsed.nodeLines[i] : 0u; };
    auto duplicate = [&](std::size_t first, std::size_t second) {
      detail::fail(ErrorCode::BadInput, "file ", path, " line ", lineOf(second), ": node ", ids[second],
                   " is defined twice (first on line ", lineOf(first), "); node ids must be unique");
    };
    if (span(min_, max_) <= 4 * std::uint64_t(n) + 1024) {
      dense_.assign(static_cast<std::size_t>(span(min_, max_) + 1), -1);
      for (std::size_t i = 0; i < n; ++i) {
        auto& slot = dense_[static_cast<std::size_t>(span(min_, ids[i]))];
        if (slot >= 0) duplicate(static_cast<std::size_t>(slot), i);
        slot = static_cast<std::int64_t>(i);
      }
      mode_ = Mode::Dense;
    } else {
      sparse_.reserve(n);
      for (std::size_t i = 0; i < n; ++i) {
        auto [it, inserted] = sparse_.emplace(ids[i], static_cast<std::int64_t>(i));
        if (!inserted) duplicate(static_cast<std::size_t>(it->second), i);
      }
      mode_ = Mode::Sparse;
    }
  }

  /// 0-based index, or -1 when no node has this id.
  std::int64_t find(std::int64_t id) const {
    switch (mode_) {
      case Mode::Offset: {
        if (id < base_) return -1;
        const std::uint64_t i = span(base_, id);
        return i < count_ ? static_cast<std::int64_t>(i) : -1;
      }
      case Mode::Dense:
        return (id >= min_ && id <= max_) ? dense_[static_cast<std::size_t>(span(min_, id))] : -1;
      case Mode::Sparse: {
        auto it = sparse_.find(id);
        return it == sparse_.end() ? -1 : it->second;
      }
    }
    return -1;
  }

  /// "the file defines nodes 1..354" for messages.
  std::string describe() const {
    if (count_ == 0) return "the file defines no nodes";
    if (mode_ == Mode::Offset)
      // (count - 1 first: base + count may pass INT64_MAX where the last id does not)
      return "the file defines nodes " + std::to_string(base_) + ".." +
             std::to_string(base_ + (std::int64_t(count_) - 1));
    return "the file defines " + std::to_string(count_) + " nodes with ids between " + std::to_string(min_) +
           " and " + std::to_string(max_) + ", not this one";
  }

 private:
  /// hi - lo for lo <= hi, exact over the whole 64-bit range (the signed difference may overflow).
  static std::uint64_t span(std::int64_t lo, std::int64_t hi) {
    return static_cast<std::uint64_t>(hi) - static_cast<std::uint64_t>(lo);
  }

  enum class Mode { Offset, Dense, Sparse };
  Mode mode_ = Mode::Offset;
  std::size_t count_ = 0;
  std::int64_t base_ = 0, min_ = 0, max_ = 0;
  std::vector<std::int64_t> dense_;
  std::unordered_map<std::int64_t, std::int64_t> sparse_;
};

}  // namespace

std::size_t reorientElements(TetMesh& mesh) {
  std::size_t swapped = 0;
  for (std::size_t e = 0; e < mesh.tetCount(); ++e) {
    std::uint32_t* t = &mesh.tets[4 * e];
    if (sixVolume(mesh.nodes.data(), t) < 0) {
      // Swapping two nodes reverses the sign of the triple product.
      std::swap(t[2], t[3]);
      ++swapped;
    }
  }
  return swapped;
}

TetMesh finalizeTetMesh(ParsedTetMesh&& parsed, const std::string& path, const MeshValidation& validation,
                        MeshReadReport* report) {
  const std::size_t elementCount = parsed.tets.size() / 4;
  if (parsed.nodes.empty())
    detail::fail(ErrorCode::BadInput, "file ", path, ": the mesh has no nodes");
  if (elementCount == 0) {
    std::string skipped;
    if (report && report->skippedElements)
      skipped = " (" + std::to_string(report->skippedElements) + " non-tetrahedral elements were skipped)";
    detail::fail(ErrorCode::BadInput, "file ", path, ": the mesh has no tetrahedra", skipped,
                 "; corofem needs a volume mesh of linear tetrahedra");
  }

  auto lineOf = [&](std::size_t e) -> std::uint32_t {
    return e < parsed.elementLines.size() ? parsed.elementLines[e] : 0u;
  };
  auto idOf = [&](std::size_t e) -> std::int64_t {
    return e < parsed.elementIds.size() ? parsed.elementIds[e] : std::int64_t(e + 1);
  };
  auto nodesOf = [&](std::size_t e) {
    const std::int64_t* t = &parsed.tets[4 * e];
    return "(nodes " + std::to_string(t[0]) + ", " + std::to_string(t[1]) + ", " + std::to_string(t[2]) + ", " +
           std::to_string(t[3]) + ")";
  };
  auto failAt = [&](std::size_t e, const auto&... parts) {
    detail::fail(ErrorCode::BadInput, "file ", path, " line ", lineOf(e), ": ", parsed.elementWord, " ", idOf(e), " ",
                 parts...);
  };

  TetMesh mesh;
  const NodeIdMap map(parsed, path);
  mesh.tets.resize(parsed.tets.size());
  for (std::size_t e = 0; e < elementCount; ++e) {
    for (int k = 0; k < 4; ++k) {
      const std::int64_t id = parsed.tets[4 * e + k];
      const std::int64_t i = map.find(id);
      if (i < 0)
        failAt(e, nodesOf(e), " refers to node ", id, ", but ", map.describe(),
               "; fix the element's node numbers or add the node");
      mesh.tets[4 * e + k] = static_cast<std::uint32_t>(i);
    }
    const std::uint32_t* t = &mesh.tets[4 * e];
    for (int a = 0; a < 4; ++a)
      for (int b = a + 1; b < 4; ++b)
        if (t[a] == t[b])
          failAt(e, nodesOf(e), " uses node ", parsed.tets[4 * e + a],
                 " twice; a tetrahedron needs four distinct nodes (remove the element or fix it)");
  }
  mesh.nodes = std::move(parsed.nodes);
  mesh.regions = std::move(parsed.regions);

  // Volumes: exactly zero is always an error; below minRelativeVolume x mean |V| is "near zero".
  std::vector<double> six(elementCount);
  double sumAbs = 0;
  for (std::size_t e = 0; e < elementCount; ++e) {
    six[e] = sixVolume(mesh.nodes.data(), &mesh.tets[4 * e]);
    sumAbs += std::abs(six[e]);
  }
  const double meanAbs = sumAbs / double(elementCount);
  const double threshold = validation.minRelativeVolume * meanAbs;
  std::size_t reoriented = 0;
  for (std::size_t e = 0; e < elementCount; ++e) {
    const double v = std::abs(six[e]);
    if (v == 0 || !std::isfinite(six[e]))
      failAt(e, "has zero volume ", nodesOf(e), "; remove it or fix the coordinates");
    if (v < threshold)
      failAt(e, "has near-zero volume ", v / 6, " ", nodesOf(e), ", below ", validation.minRelativeVolume,
             " of the mean element volume ", meanAbs / 6,
             "; remove it or fix the coordinates (MeshValidation::minRelativeVolume sets the limit)");
    if (six[e] < 0 && validation.reorient) {
      std::swap(mesh.tets[4 * e + 2], mesh.tets[4 * e + 3]);  // reverses the sign of the volume
      ++reoriented;
    }
  }
  if (report) report->reorientedElements = reoriented;
  return mesh;
}

}  // namespace corofem::mesh
