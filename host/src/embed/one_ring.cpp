// The one-ring of a surface vertex as the device surface passes read it (one_ring.hpp).
#include "embed/one_ring.hpp"

#include <algorithm>

namespace corofem::detail {

void oneRing(const SurfaceBinding& b, std::uint32_t v, std::vector<std::pair<std::uint32_t, std::uint32_t>>& pairs,
             std::vector<std::uint32_t>& out) {
  pairs.clear();
  out.clear();
  for (std::uint32_t q = b.vertexTriangleOffsets[v]; q < b.vertexTriangleOffsets[v + 1]; ++q) {
    const std::uint32_t* t = &b.triangles[3 * static_cast<std::size_t>(b.vertexTriangles[q])];
    if (t[0] == t[1] || t[1] == t[2] || t[0] == t[2]) continue;
    if (t[0] == v) pairs.emplace_back(t[1], t[2]);
    else if (t[1] == v) pairs.emplace_back(t[2], t[0]);
    else pairs.emplace_back(t[0], t[1]);
  }
  const std::size_t d = pairs.size();
  if (d == 0) return;
  // Pairs sorted by their first vertex (then by position): the successor of a fan's last vertex is
  // the first unused pair starting there.
  std::vector<std::uint32_t> byFirst(d), seconds(d);
  for (std::size_t i = 0; i < d; ++i) byFirst[i] = static_cast<std::uint32_t>(i), seconds[i] = pairs[i].second;
  std::sort(byFirst.begin(), byFirst.end(), [&](std::uint32_t i, std::uint32_t j) {
    return pairs[i].first != pairs[j].first ? pairs[i].first < pairs[j].first : i < j;
  });
  std::sort(seconds.begin(), seconds.end());
  std::vector<char> used(d, 0);
  auto successor = [&](std::uint32_t vertex) -> std::size_t {
    auto it = std::lower_bound(byFirst.begin(), byFirst.end(), vertex,
                               [&](std::uint32_t i, std::uint32_t key) { return pairs[i].first < key; });
    for (; it != byFirst.end() && pairs[*it].first == vertex; ++it)
      if (!used[*it]) return *it;
    return d;
  };
  std::vector<std::vector<std::uint32_t>> fans;
  std::vector<char> closed;
  auto walk = [&](std::size_t start) {
    std::vector<std::uint32_t> fan{pairs[start].first, pairs[start].second};
    used[start] = 1;
    for (std::size_t next = successor(fan.back()); next < d; next = successor(fan.back())) {
      used[next] = 1;
      fan.push_back(pairs[next].second);
    }
    const bool isClosed = fan.size() > 2 && fan.back() == fan.front();
    if (isClosed) fan.pop_back();
    fans.push_back(std::move(fan));
    closed.push_back(isClosed);
  };
  for (std::size_t i = 0; i < d; ++i)  // open ends: no pair ends where this one starts
    if (!used[i] && !std::binary_search(seconds.begin(), seconds.end(), pairs[i].first)) walk(i);
  for (std::size_t i = 0; i < d; ++i)
    if (!used[i]) walk(i);
  if (fans.size() == 1 && closed[0]) {
    out = std::move(fans[0]);
    std::rotate(out.begin(), std::min_element(out.begin(), out.end()), out.end());
    return;
  }
  for (std::size_t f = 0; f < fans.size(); ++f) {
    out.insert(out.end(), fans[f].begin(), fans[f].end());
    if (closed[f]) out.push_back(fans[f].front());
    out.push_back(v);
  }
}

}  // namespace corofem::detail
