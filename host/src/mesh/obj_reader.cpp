// Wavefront OBJ reader for triangle surfaces: "v x y z", "vt u v", "f" with corners v, v/vt, v//vn or
// v/vt/vn (1-based, negative = relative to the end). Quads and polygons are fan-split (0, i, i+1).
// Texture coordinates are kept per vertex when every corner of a vertex uses the same (u, v);
// otherwise (seams, missing vt) the mesh gets no texcoords. Normals, groups and materials are ignored.
#include "mesh/readers.hpp"
#include "mesh/text_scanner.hpp"

#include <charconv>
#include <cmath>
#include <limits>

namespace corofem::mesh {
namespace {

/// Parses one OBJ index ("12", "-3"); false when malformed.
bool parseIndex(const char*& p, const char* end, std::int64_t& value) {
  auto [ptr, ec] = std::from_chars(p, end, value);
  if (ec != std::errc() || ptr == p) return false;
  p = ptr;
  return true;
}

}  // namespace

SurfaceMesh parseObj(const std::string& text, const std::string& path, MeshReadReport& report) {
  TextScanner sc(text, path);
  sc.setCommentChar('#');
  SurfaceMesh mesh;
  std::vector<float> uv;            // 2 per vt line
  std::vector<std::int64_t> uvOf;   // per vertex: vt index used by its corners, -1 none yet
  bool uvConsistent = true, anyCornerWithoutUv = false;
  std::vector<std::uint32_t> corners;

  auto resolve = [&](std::int64_t index, std::size_t count, const char* what) -> std::size_t {
    // OBJ indices are 1-based; negative ones count back from the last element defined so far.
    const std::int64_t i = index > 0 ? index - 1 : std::int64_t(count) + index;
    if (index == 0 || i < 0 || i >= std::int64_t(count))
      sc.fail("face refers to ", what, " ", index, ", but ", count, " ", what,
              "s are defined before it (OBJ indices start at 1; negative ones count back)");
    return std::size_t(i);
  };

  while (!sc.atEnd()) {
    sc.setContext(nullptr);
    const std::string_view key = sc.token();
    if (key == "v") {
      const std::int64_t id = std::int64_t(mesh.vertexCount() + 1);
      sc.setContext("vertex", id);
      double xyz[3];
      sc.readPoint(xyz, id, true);
      mesh.vertices.insert(mesh.vertices.end(), xyz, xyz + 3);
      uvOf.push_back(-1);
      sc.skipLine();  // optional w or vertex colour
    } else if (key == "vt") {
      sc.setContext("texture coordinate", std::int64_t(uv.size() / 2 + 1));
      const double u = sc.readDoubleOnLine();
      const double v = sc.atLineEnd() ? 0.0 : sc.readDoubleOnLine();
      for (const double t : {u, v})  // stored as float: NaN, infinity and |t| > 3.4e38 have no value there
        if (!(std::abs(t) <= double(std::numeric_limits<float>::max())))
          sc.fail("texture coordinate ", uv.size() / 2 + 1, " has the value ", t,
                  ", which is not a finite float; fix the vt line");
      uv.push_back(static_cast<float>(u));
      uv.push_back(static_cast<float>(v));
      sc.skipLine();
    } else if (key == "f") {
      sc.setContext("face");
      corners.clear();
      for (std::string_view tok = sc.tokenOnLine(); !tok.empty(); tok = sc.tokenOnLine()) {
        const char* p = tok.data();
        const char* end = p + tok.size();
        std::int64_t vi = 0, ti = 0;
        bool hasUv = false;
        if (!parseIndex(p, end, vi)) sc.fail("malformed face corner '", detail::shorten(tok), "'");
        if (p < end && *p == '/') {
          ++p;
          if (p < end && *p != '/') {
            if (!parseIndex(p, end, ti)) sc.fail("malformed face corner '", detail::shorten(tok), "'");
            hasUv = true;
          }
          if (p < end && *p == '/') {
            ++p;
            std::int64_t ni = 0;
            if (!parseIndex(p, end, ni)) sc.fail("malformed face corner '", detail::shorten(tok), "'");
          }
        }
        if (p != end) sc.fail("malformed face corner '", detail::shorten(tok), "'");
        const std::size_t v = resolve(vi, mesh.vertexCount(), "vertex");
        corners.push_back(static_cast<std::uint32_t>(v));
        if (hasUv) {
          const auto t = static_cast<std::int64_t>(resolve(ti, uv.size() / 2, "texture coordinate"));
          std::int64_t& mine = uvOf[v];
          if (mine < 0) {
            mine = t;
          } else if (mine != t && (uv[2 * mine] != uv[2 * t] || uv[2 * mine + 1] != uv[2 * t + 1])) {
            uvConsistent = false;  // a seam: one vertex, two (u, v)
          }
        } else {
          anyCornerWithoutUv = true;
        }
      }
      if (corners.size() < 3) sc.fail("a face needs at least 3 vertices, this one has ", corners.size());
      if (corners.size() > 3) ++report.splitPolygons;
      for (std::size_t i = 1; i + 1 < corners.size(); ++i) {
        mesh.triangles.push_back(corners[0]);
        mesh.triangles.push_back(corners[i]);
        mesh.triangles.push_back(corners[i + 1]);
      }
    } else {
      sc.skipLine();  // vn, g, o, s, usemtl, mtllib, l, p, ...: not needed for a triangle surface
    }
  }
  if (mesh.vertices.empty()) sc.fail("the file has no vertices ('v' lines); is this an OBJ file?");
  if (!uv.empty() && uvConsistent && !anyCornerWithoutUv) {
    mesh.texcoords.assign(2 * mesh.vertexCount(), 0.0f);
    for (std::size_t v = 0; v < mesh.vertexCount(); ++v)
      if (uvOf[v] >= 0) {
        mesh.texcoords[2 * v] = uv[2 * std::size_t(uvOf[v])];
        mesh.texcoords[2 * v + 1] = uv[2 * std::size_t(uvOf[v]) + 1];
      }
  }
  report.format = "obj";
  return mesh;
}

}  // namespace corofem::mesh
