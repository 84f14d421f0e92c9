// The nested dissection of precond/nested_dissection.hpp.
#include "precond/nested_dissection.hpp"

#include "util/error.hpp"

#include <Eigen/OrderingMethods>
#include <Eigen/SparseCore>

#include <algorithm>
#include <array>
#include <cmath>

namespace corofem::detail {

namespace {

/// The node graph of the free dofs: per node group (consecutive free dofs of one node) its
/// position, its dofs, and its neighbours (vertexGraph of A over the groups).
struct NodeGraph {
  std::vector<std::array<double, 3>> position;
  std::vector<int> dofStart;  ///< group g: free dofs [dofStart[g], dofStart[g + 1])
  VertexGraph graph;
  std::size_t size() const { return position.size(); }
};

NodeGraph nodeGraph(const AmgMatrix& A, const std::vector<Eigen::Index>& freeDofs, const Eigen::VectorXd& rest) {
  NodeGraph g;
  for (std::size_t i = 0; i < freeDofs.size(); ++i) {
    const Eigen::Index node = freeDofs[i] / 3;
    if (i == 0 || node != freeDofs[i - 1] / 3) {
      g.dofStart.push_back(static_cast<int>(i));
      g.position.push_back({rest[3 * node], rest[3 * node + 1], rest[3 * node + 2]});
    }
  }
  g.dofStart.push_back(static_cast<int>(freeDofs.size()));
  g.graph = vertexGraph(A, g.dofStart);
  return g;
}

class Dissection {
 public:
  explicit Dissection(const NodeGraph& g) : g_(g), label_(g.size(), -1), local_(g.size(), -1) {}

  /// Appends the order of `nodes` to order_.
  void dissect(std::vector<int> nodes) {
    if (nodes.size() <= kLeafNodes) {
      leaf(nodes);
      return;
    }
    // The longest side of the part's bounding box, and its nodes along it (ties by index).
    std::array<double, 3> lo = g_.position[static_cast<std::size_t>(nodes[0])], hi = lo;
    for (const int v : nodes)
      for (int a = 0; a < 3; ++a) {
        lo[a] = std::min(lo[a], g_.position[static_cast<std::size_t>(v)][a]);
        hi[a] = std::max(hi[a], g_.position[static_cast<std::size_t>(v)][a]);
      }
    int axis = 0;
    for (int a = 1; a < 3; ++a)
      if (hi[a] - lo[a] > hi[axis] - lo[axis]) axis = a;
    std::sort(nodes.begin(), nodes.end(), [&](int a, int b) {
      const double pa = g_.position[static_cast<std::size_t>(a)][axis], pb = g_.position[static_cast<std::size_t>(b)][axis];
      return pa != pb ? pa < pb : a < b;
    });
    const std::size_t half = nodes.size() / 2;
    const int side0 = next_++, side1 = next_++;
    for (std::size_t k = 0; k < nodes.size(); ++k) label_[static_cast<std::size_t>(nodes[k])] = k < half ? side0 : side1;
    // Each half's border with the other; the smaller is the separator.
    std::array<std::vector<int>, 2> border, inner;
    for (std::size_t k = 0; k < nodes.size(); ++k) {
      const int v = nodes[k];
      const int own = label_[static_cast<std::size_t>(v)], other = own == side0 ? side1 : side0;
      bool touches = false;
      for (int e = g_.graph.start[static_cast<std::size_t>(v)]; e < g_.graph.start[static_cast<std::size_t>(v) + 1] && !touches; ++e)
        touches = label_[static_cast<std::size_t>(g_.graph.adj[static_cast<std::size_t>(e)])] == other;
      (touches ? border : inner)[own == side0 ? 0 : 1].push_back(v);
    }
    const int cut = border[0].size() <= border[1].size() ? 0 : 1;
    std::array<std::vector<int>, 2> part;
    for (int s = 0; s < 2; ++s) {
      part[s] = inner[s];
      if (s != cut) part[s].insert(part[s].end(), border[s].begin(), border[s].end());
    }
    if (part[0].empty() || part[1].empty()) {  // no split to be had (a dense clump): order it whole
      leaf(nodes);
      return;
    }
    std::vector<int> separator = std::move(border[cut]);
    dissect(std::move(part[0]));
    dissect(std::move(part[1]));
    leaf(separator);
  }

  const std::vector<int>& order() const { return order_; }

 private:
  /// Appends `nodes` in approximate minimum degree order of their graph among themselves.
  void leaf(const std::vector<int>& nodes) {
    const auto m = static_cast<int>(nodes.size());
    if (m <= 2) {
      order_.insert(order_.end(), nodes.begin(), nodes.end());
      return;
    }
    for (int k = 0; k < m; ++k) local_[static_cast<std::size_t>(nodes[static_cast<std::size_t>(k)])] = k;
    std::vector<Eigen::Triplet<double, int>> entries;
    for (int k = 0; k < m; ++k) {
      const int v = nodes[static_cast<std::size_t>(k)];
      entries.emplace_back(k, k, 1.0);
      for (int e = g_.graph.start[static_cast<std::size_t>(v)]; e < g_.graph.start[static_cast<std::size_t>(v) + 1]; ++e) {
        const int j = local_[static_cast<std::size_t>(g_.graph.adj[static_cast<std::size_t>(e)])];
        if (j >= 0) entries.emplace_back(k, j, 1.0);
      }
    }
    Eigen::SparseMatrix<double, Eigen::ColMajor, int> pattern(m, m);
    pattern.setFromTriplets(entries.begin(), entries.end());
    Eigen::PermutationMatrix<Eigen::Dynamic, Eigen::Dynamic, int> inverse;
    Eigen::AMDOrdering<int>()(pattern, inverse);  // the k-th eliminated is inverse.indices()[k]
    for (int k = 0; k < m; ++k) order_.push_back(nodes[static_cast<std::size_t>(inverse.indices()[k])]);
    for (const int v : nodes) local_[static_cast<std::size_t>(v)] = -1;
  }

  const NodeGraph& g_;
  std::vector<int> label_;  ///< per node: the side of the split it was last in
  std::vector<int> local_;  ///< per node: its index in the leaf being ordered, or -1
  int next_ = 0;
  std::vector<int> order_;
};

}  // namespace

std::vector<int> nestedDissection(const AmgMatrix& A, const std::vector<Eigen::Index>& freeDofs,
                                  const Eigen::VectorXd& rest) {
  checkRestSystem("nestedDissection", A, freeDofs, rest);
  for (const Eigen::Index d : freeDofs)
    if (!std::isfinite(rest[d]))
      fail(ErrorCode::Internal, "nestedDissection: the rest position of free dof ", d, " is not finite");
  const NodeGraph g = nodeGraph(A, freeDofs, rest);
  std::vector<int> all(g.size());
  for (std::size_t q = 0; q < g.size(); ++q) all[q] = static_cast<int>(q);
  Dissection d(g);
  d.dissect(std::move(all));
  std::vector<int> position(freeDofs.size());
  int next = 0;
  for (const int q : d.order())
    for (int i = g.dofStart[static_cast<std::size_t>(q)]; i < g.dofStart[static_cast<std::size_t>(q) + 1]; ++i)
      position[static_cast<std::size_t>(i)] = next++;
  return position;
}

}  // namespace corofem::detail
