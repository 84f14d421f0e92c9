// Saving, escaping and the pre-write checks shared by the mesh writers.
#include "mesh/text_writer.hpp"

#include "util/error.hpp"
#include "util/temp_file.hpp"

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>

namespace corofem::mesh {

namespace {

/// Throws BadInput at the first non-finite value: no NaN or infinity is written to a file.
template <class T>
void checkFinite(const T* values, std::size_t count, int perItem, const char* item, const std::string& what,
                 const std::string& path) {
  for (std::size_t i = 0; i < count; ++i)
    if (!std::isfinite(values[i]))
      detail::fail(ErrorCode::BadInput, "cannot write ", path, ": ", what, " of ", item, " ", i / std::size_t(perItem),
                   " is ", values[i], " (component ", i % std::size_t(perItem),
                   "); only finite numbers are written, so fix the value or leave it out");
}

}  // namespace

void TextWriter::save(const std::string& path) const {
  // A fixed name (not temporaryNameFor): one writer per output file, and the hardening tests point
  // "<path>.tmp" at /dev/full to see a full disk reported.
  const std::string tmp = path + ".tmp";
  std::FILE* f = std::fopen(tmp.c_str(), "wb");
  if (!f)
    detail::fail(ErrorCode::IoError, "cannot write ", path, ": ", std::strerror(errno),
                 "; check that the folder exists and is writable");
  // errno is read right after the call that failed: fwrite usually succeeds into the buffer, and
  // fclose, flushing it, is the call that meets a full disk.
  int err = 0;
  if (std::fwrite(buf_.data(), 1, buf_.size(), f) != buf_.size()) err = errno ? errno : EIO;
  if (std::fclose(f) != 0 && err == 0) err = errno ? errno : EIO;
  if (err != 0) {
    std::remove(tmp.c_str());
    detail::fail(ErrorCode::IoError, "cannot write ", path, ": ", std::strerror(err), " (disk full?)");
  }
  if (const std::error_code ec = detail::replaceFile(tmp, path))
    detail::fail(ErrorCode::IoError, "cannot write ", path, ": renaming the temporary file failed: ", ec.message());
}

std::string xmlEscape(std::string_view s) {
  std::string r;
  r.reserve(s.size());
  for (char c : s) {
    switch (c) {
      case '&': r += "&amp;"; break;
      case '<': r += "&lt;"; break;
      case '>': r += "&gt;"; break;
      case '"': r += "&quot;"; break;
      default: r += c;
    }
  }
  return r;
}

void checkWritable(const TetMesh& mesh, const std::string& path) {
  if (mesh.nodes.size() % 3 != 0 || mesh.tets.size() % 4 != 0)
    detail::fail(ErrorCode::BadInput, "cannot write ", path, ": the mesh arrays are not whole (", mesh.nodes.size(),
                 " node values, ", mesh.tets.size(), " element indices); they must be multiples of 3 and 4");
  const std::size_t n = mesh.nodeCount();
  checkFinite(mesh.nodes.data(), mesh.nodes.size(), 3, "node", "the position", path);
  for (std::size_t i = 0; i < mesh.tets.size(); ++i)
    if (mesh.tets[i] >= n)
      detail::fail(ErrorCode::BadInput, "cannot write ", path, ": element ", i / 4, " refers to node ", mesh.tets[i],
                   " but the mesh has ", n, " nodes (0-based indices)");
  if (!mesh.regions.empty() && mesh.regions.size() != mesh.tetCount())
    detail::fail(ErrorCode::BadInput, "cannot write ", path, ": the mesh has ", mesh.regions.size(), " regions for ",
                 mesh.tetCount(), " elements; give one per element or none");
}

void checkWritable(const SurfaceMesh& mesh, const std::string& path) {
  if (mesh.vertices.size() % 3 != 0 || mesh.triangles.size() % 3 != 0)
    detail::fail(ErrorCode::BadInput, "cannot write ", path, ": the surface arrays are not whole (",
                 mesh.vertices.size(), " vertex values, ", mesh.triangles.size(), " triangle indices)");
  const std::size_t n = mesh.vertexCount();
  checkFinite(mesh.vertices.data(), mesh.vertices.size(), 3, "vertex", "the position", path);
  for (std::size_t i = 0; i < mesh.triangles.size(); ++i)
    if (mesh.triangles[i] >= n)
      detail::fail(ErrorCode::BadInput, "cannot write ", path, ": triangle ", i / 3, " refers to vertex ",
                   mesh.triangles[i], " but the surface has ", n, " vertices (0-based indices)");
  checkFinite(mesh.texcoords.data(), mesh.texcoords.size(), 2, "vertex", "the texture coordinate", path);
  if (!mesh.texcoords.empty() && mesh.texcoords.size() != 2 * n)
    detail::fail(ErrorCode::BadInput, "cannot write ", path, ": ", mesh.texcoords.size(),
                 " texcoord values for ", n, " vertices; give 2 per vertex or none");
  if (!mesh.normals.empty() && mesh.normals.size() != 3 * n)
    detail::fail(ErrorCode::BadInput, "cannot write ", path, ": ", mesh.normals.size(), " normal values for ", n,
                 " vertices; give 3 per vertex or none");
  checkFinite(mesh.normals.data(), mesh.normals.size(), 3, "vertex", "the normal", path);
}

void checkFields(const std::vector<MeshField>& fields, std::size_t nodes, std::size_t elements,
                 const std::string& path) {
  for (const MeshField& f : fields) {
    if (f.name.empty()) detail::fail(ErrorCode::BadInput, "cannot write ", path, ": a field has no name");
    if (f.components < 1 || f.components > 9)
      detail::fail(ErrorCode::BadInput, "cannot write ", path, ": field '", f.name, "' has ", f.components,
                   " components; use 1 (scalar) or 3 (vector)");
    const std::size_t count = f.perElement ? elements : nodes;
    if (f.values.size() != count * std::size_t(f.components))
      detail::fail(ErrorCode::BadInput, "cannot write ", path, ": field '", f.name, "' has ", f.values.size(),
                   " values, expected ", f.components, " x ", count, (f.perElement ? " elements" : " nodes"), " = ",
                   count * std::size_t(f.components));
    checkFinite(f.values.data(), f.values.size(), f.components, f.perElement ? "element" : "node",
                "field '" + detail::shorten(f.name) + "'", path);
  }
}

}  // namespace corofem::mesh
