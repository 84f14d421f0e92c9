// The rest system of precond/rest_system.hpp: K_0, m M + s K_0 on the free dofs, K_0 kept.
#include "precond/rest_system.hpp"

#include "model/element.hpp"
#include "util/error.hpp"
#include "util/hash.hpp"

#include <algorithm>
#include <functional>

namespace corofem::detail {

AmgMatrix restStiffness(const Problem& p) {
  // Assembled in place: each node's neighbours (the nodes it shares an element with, itself
  // included) sorted give every row's columns, 3 per neighbour; the element matrices are added in
  // element order, the order in which setFromTriplets would sum them (the same values; only an
  // entry whose every term is -0 comes out +0), without a sort of 144 entries per element.
  const std::size_t nodes = p.mesh.nodeCount(), elements = p.elements.size();
  std::vector<std::vector<std::uint32_t>> near(nodes);
  for (std::size_t n = 0; n < nodes; ++n) near[n].push_back(static_cast<std::uint32_t>(n));
  for (std::size_t e = 0; e < elements; ++e)
    for (int a = 0; a < 4; ++a)
      for (int b = 0; b < 4; ++b)
        if (a != b) near[p.mesh.tets[4 * e + a]].push_back(p.mesh.tets[4 * e + b]);
  // A node in no element (its dofs constrained, or freed by the application) has its diagonal alone.
  std::vector<int> start(3 * nodes + 1, 0);  // each dof row's first entry
  for (std::size_t n = 0; n < nodes; ++n) {
    std::sort(near[n].begin(), near[n].end());
    near[n].erase(std::unique(near[n].begin(), near[n].end()), near[n].end());
    const int width = near[n].size() > 1 ? static_cast<int>(3 * near[n].size()) : 1;
    for (std::size_t c = 0; c < 3; ++c) start[3 * n + c + 1] = start[3 * n + c] + width;
  }
  const auto n3 = static_cast<Eigen::Index>(3 * nodes);
  AmgMatrix K(n3, n3);
  K.resizeNonZeros(start.back());
  std::copy(start.begin(), start.end(), K.outerIndexPtr());
  for (std::size_t n = 0; n < nodes; ++n)
    for (std::size_t c = 0; c < 3; ++c) {
      const std::size_t row = static_cast<std::size_t>(start[3 * n + c]);
      if (near[n].size() == 1) {
        K.innerIndexPtr()[row] = static_cast<int>(3 * n + c);
        K.valuePtr()[row] = 0.0;
        continue;
      }
      for (std::size_t k = 0; k < near[n].size(); ++k)
        for (std::size_t c2 = 0; c2 < 3; ++c2) {
          K.innerIndexPtr()[row + 3 * k + c2] = static_cast<int>(3 * near[n][k] + c2);
          K.valuePtr()[row + 3 * k + c2] = 0.0;
        }
    }
  for (std::size_t e = 0; e < elements; ++e) {
    const Mat12 Ke = linearStiffness(p.elements[e], p.lame);
    for (int a = 0; a < 4; ++a) {
      const std::uint32_t na = p.mesh.tets[4 * e + a];
      for (int b = 0; b < 4; ++b) {
        const std::uint32_t nb = p.mesh.tets[4 * e + b];
        const std::size_t k = static_cast<std::size_t>(
            std::lower_bound(near[na].begin(), near[na].end(), nb) - near[na].begin());
        for (int ca = 0; ca < 3; ++ca) {
          double* row = K.valuePtr() + start[3 * na + static_cast<std::size_t>(ca)] + 3 * k;
          for (int cb = 0; cb < 3; ++cb) row[cb] += Ke(3 * a + ca, 3 * b + cb);
        }
      }
    }
  }
  return K;
}

bool freeDofsInOrder(const std::vector<Eigen::Index>& freeDofs, Eigen::Index dofs) {
  return std::adjacent_find(freeDofs.begin(), freeDofs.end(), std::greater_equal<Eigen::Index>()) == freeDofs.end() &&
         (freeDofs.empty() || (freeDofs.front() >= 0 && freeDofs.back() < dofs));
}

VertexGraph vertexGraph(const AmgMatrix& A, const std::vector<int>& vertexStart) {
  const int nv = static_cast<int>(vertexStart.size()) - 1;
  std::vector<int> vertexOf(static_cast<std::size_t>(A.rows()));
  for (int v = 0; v < nv; ++v)
    for (int i = vertexStart[v]; i < vertexStart[v + 1]; ++i) vertexOf[static_cast<std::size_t>(i)] = v;
  VertexGraph g;
  g.start.assign(static_cast<std::size_t>(nv) + 1, 0);
  std::vector<int> mark(static_cast<std::size_t>(nv), -1);
  for (int v = 0; v < nv; ++v) {
    mark[v] = v;  // no self loop
    for (int i = vertexStart[v]; i < vertexStart[v + 1]; ++i)
      for (AmgMatrix::InnerIterator it(A, i); it; ++it) {
        const int u = vertexOf[static_cast<std::size_t>(it.col())];
        if (mark[u] != v && it.value() != 0.0) {
          mark[u] = v;
          g.adj.push_back(u);
        }
      }
    g.start[v + 1] = static_cast<int>(g.adj.size());
  }
  return g;
}

void checkRestSystem(const char* who, const AmgMatrix& A, const std::vector<Eigen::Index>& freeDofs,
                     const Eigen::VectorXd& rest) {
  const auto n = static_cast<Eigen::Index>(freeDofs.size());
  if (A.rows() != n || A.cols() != n || rest.size() % 3 != 0 || !freeDofsInOrder(freeDofs, rest.size()))
    fail(ErrorCode::Internal, who, ": an operator of ", A.rows(), " x ", A.cols(), " for ", n,
         " free dofs, or free dofs not strictly ascending within 0..", rest.size(), " - 1");
}

AmgMatrix restOperator(const AmgMatrix& stiffness, const Problem& p, const std::vector<Eigen::Index>& freeDofs,
                       double massScale, double stiffScale) {
  if (stiffness.rows() != static_cast<Eigen::Index>(p.dofCount()) || stiffness.cols() != stiffness.rows())
    fail(ErrorCode::Internal, "restOperator: a stiffness of ", stiffness.rows(), " x ", stiffness.cols(), " for ",
         p.dofCount(), " dofs");
  // The rows and columns below come out in order only for free dofs in ascending order.
  if (!freeDofsInOrder(freeDofs, stiffness.rows()) || !stiffness.isCompressed())
    fail(ErrorCode::Internal, "restOperator: free dofs not strictly ascending within 0..", stiffness.rows() - 1,
         ", or an uncompressed stiffness");
  std::vector<int> index(p.dofCount(), -1);
  for (std::size_t i = 0; i < freeDofs.size(); ++i) index[static_cast<std::size_t>(freeDofs[i])] = static_cast<int>(i);
  const auto n = static_cast<Eigen::Index>(freeDofs.size());
  AmgMatrix A(n, n);
  Eigen::Index entries = 0;  // at most: the free rows' entries
  for (Eigen::Index i = 0; i < n; ++i)
    entries += stiffness.outerIndexPtr()[freeDofs[i] + 1] - stiffness.outerIndexPtr()[freeDofs[i]];
  A.reserve(entries);  // compressed: startVec and insertBack fill it in order
  // Rows in order, and in each row the columns in order: free indices ascend with the dofs.
  for (Eigen::Index i = 0; i < n; ++i) {
    const Eigen::Index d = freeDofs[i];
    A.startVec(i);
    for (AmgMatrix::InnerIterator it(stiffness, d); it; ++it) {
      const int c = index[static_cast<std::size_t>(it.col())];
      if (c < 0) continue;
      A.insertBack(i, c) = stiffScale * it.value() + (c == i ? massScale * p.lumpedMass[d] : 0.0);
    }
  }
  A.finalize();
  return A;
}

namespace {

/// What K_0 depends on, hashed (FNV-1a over the bytes): the tets, the rest positions (from which
/// buildProblem derives the elements' gradients), each element's rest volume and the material; and
/// the lumped mass, which the rest operators add to it (a hierarchy's spectral bounds, taken over
/// by another, are of m M + s K_0). A body whose key data differ gives another key but for a 2^-64
/// chance.
std::uint64_t stiffnessKey(const Problem& p) {
  std::uint64_t h = kFnv1aOffset;
  auto mix = [&h](const void* data, std::size_t bytes) { h = fnv1a64(data, bytes, h); };
  mix(p.mesh.tets.data(), p.mesh.tets.size() * sizeof(p.mesh.tets[0]));
  mix(p.restPositions.data(), static_cast<std::size_t>(p.restPositions.size()) * sizeof(double));
  for (const ElementRest& e : p.elements) mix(&e.volume, sizeof(e.volume));
  mix(&p.lame.lambda, sizeof(double));
  mix(&p.lame.mu, sizeof(double));
  mix(p.lumpedMass.data(), static_cast<std::size_t>(p.lumpedMass.size()) * sizeof(double));
  const std::size_t dofs = p.dofCount();
  mix(&dofs, sizeof(dofs));
  return h;
}

}  // namespace

const AmgMatrix& KeptStiffness::of(const Problem& p, bool& remade) {
  const std::uint64_t key = stiffnessKey(p);
  remade = stiffness_.rows() == 0 || key != key_;
  if (remade) {
    stiffness_ = restStiffness(p);
    key_ = key;
  }
  return stiffness_;
}

}  // namespace corofem::detail
