// generateBox: an axis-aligned box of nx x ny x nz cells, each split into 5 or 6 tetrahedra.
//
// Both splits are conforming (neighbouring cells cut their shared face along the same diagonal):
//  - 6 tets (Kuhn / Freudenthal): every cell is cut around its main diagonal (0,0,0)-(1,1,1) into the
//    tets {v000, v000 + e_a, v000 + e_a + e_b, v111} for the 6 permutations (a, b, c) of the axes. The
//    face diagonals all run in the +,+ direction, the same in every cell, so faces match.
//  - 5 tets: a central tet on the 4 corners of even global parity (i + j + k even), plus the 4 corner
//    tets cut off at the odd corners. Whether a local corner is "even" alternates from cell to cell,
//    so the pattern alternates, and every face diagonal joins the face's two globally even corners:
//    the two cells sharing a face cut it the same way.
// Every tet is then oriented positively ((b-a).((c-a)x(d-a)) > 0) by swapping two nodes if needed.
#include "mesh/input_file.hpp"
#include "mesh/mesh_validation.hpp"
#include "util/error.hpp"

#include <corofem/mesh.hpp>

#include <cmath>
#include <iomanip>
#include <limits>
#include <sstream>

namespace corofem {

std::string mesh::boxSizeProblem(const BoxSpec& spec, const InputLimits& limits) {
  const double nodes = double(spec.cells[0] + 1.0) * double(spec.cells[1] + 1.0) * double(spec.cells[2] + 1.0);
  const double tets = double(spec.cells[0]) * double(spec.cells[1]) * double(spec.cells[2]) * spec.tetsPerCell;
  const std::uint64_t limit = limits.maxBoxTets;
  std::ostringstream os;
  os << spec.cells[0] << " x " << spec.cells[1] << " x " << spec.cells[2] << " cells of " << spec.tetsPerCell
     << " tetrahedra give " << std::setprecision(15) << tets << " tetrahedra";
  if (tets > double(limit)) {
    os << ", more than the limit of " << limit << " (" << limitInUse(kMaxBoxTets, limit)
       << "); use fewer cells, or raise the limit if the machine has the memory: " << howToRaise(kMaxBoxTets);
    return os.str();
  }
  if (nodes >= double(std::numeric_limits<std::uint32_t>::max())) {
    os << " on " << nodes << " nodes, more than 32-bit node indices reach; use fewer cells";
    return os.str();
  }
  return "";
}

Result<TetMesh> generateBox(const BoxSpec& spec, const InputLimits& limits) {
  return detail::guardResult<TetMesh>([&] {
    static const char* kAxis[3] = {"x", "y", "z"};
    for (int a = 0; a < 3; ++a) {
      if (!std::isfinite(spec.min[a]) || !std::isfinite(spec.max[a]) || !(spec.max[a] > spec.min[a]))
        detail::fail(ErrorCode::BadInput, "box: max.", kAxis[a], " (", spec.max[a], ") must be greater than min.",
                     kAxis[a], " (", spec.min[a], ") and both finite");
      if (spec.cells[a] < 1)
        detail::fail(ErrorCode::BadInput, "box: cells.", kAxis[a], " is ", spec.cells[a], "; it must be at least 1");
    }
    if (spec.tetsPerCell != 5 && spec.tetsPerCell != 6)
      detail::fail(ErrorCode::BadInput, "box: tetsPerCell is ", spec.tetsPerCell,
                   "; use 5 (alternating split) or 6 (Kuhn split)");
    const std::string tooLarge = mesh::boxSizeProblem(spec, limits);
    if (!tooLarge.empty()) detail::fail(ErrorCode::BadInput, "box: ", tooLarge);
    const std::size_t nx = std::size_t(spec.cells[0]), ny = std::size_t(spec.cells[1]), nz = std::size_t(spec.cells[2]);
    const double nodes = double(nx + 1) * double(ny + 1) * double(nz + 1);
    const double tets = double(nx) * double(ny) * double(nz) * spec.tetsPerCell;

    TetMesh mesh;
    mesh.nodes.reserve(3 * std::size_t(nodes));
    auto coord = [&](int a, std::size_t i, std::size_t n) {
      // The last layer is exactly max (no rounding drift), so the volume matches the box.
      return i == n ? spec.max[a] : spec.min[a] + (spec.max[a] - spec.min[a]) * (double(i) / double(n));
    };
    for (std::size_t k = 0; k <= nz; ++k)
      for (std::size_t j = 0; j <= ny; ++j)
        for (std::size_t i = 0; i <= nx; ++i) {
          mesh.nodes.push_back(coord(0, i, nx));
          mesh.nodes.push_back(coord(1, j, ny));
          mesh.nodes.push_back(coord(2, k, nz));
        }
    auto node = [&](std::size_t i, std::size_t j, std::size_t k) {
      return static_cast<std::uint32_t>(i + (nx + 1) * (j + (ny + 1) * k));
    };

    // Local corner c = dx + 2 dy + 4 dz.
    static const int kKuhn[6][4] = {{0, 1, 3, 7}, {0, 1, 5, 7}, {0, 2, 3, 7},
                                    {0, 2, 6, 7}, {0, 4, 5, 7}, {0, 4, 6, 7}};
    static const int kFiveEven[5][4] = {{0, 3, 5, 6}, {1, 0, 3, 5}, {2, 0, 3, 6}, {4, 0, 5, 6}, {7, 3, 5, 6}};
    static const int kFiveOdd[5][4] = {{1, 2, 4, 7}, {0, 1, 2, 4}, {3, 1, 2, 7}, {5, 1, 4, 7}, {6, 2, 4, 7}};
    mesh.tets.reserve(4 * std::size_t(tets));
    for (std::size_t k = 0; k < nz; ++k)
      for (std::size_t j = 0; j < ny; ++j)
        for (std::size_t i = 0; i < nx; ++i) {
          std::uint32_t corner[8];
          for (int c = 0; c < 8; ++c) corner[c] = node(i + (c & 1), j + ((c >> 1) & 1), k + ((c >> 2) & 1));
          if (spec.tetsPerCell == 6) {
            for (const auto& t : kKuhn)
              for (int v : t) mesh.tets.push_back(corner[v]);
          } else {
            const auto& split = ((i + j + k) % 2 == 0) ? kFiveEven : kFiveOdd;
            for (const auto& t : split)
              for (int v : t) mesh.tets.push_back(corner[v]);
          }
        }
    mesh::reorientElements(mesh);
    return mesh;
  });
}

}  // namespace corofem
