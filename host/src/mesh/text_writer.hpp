// A string builder for the mesh writers: numbers with std::to_chars (shortest form that reads back
// to the same double, so a written mesh re-reads bit for bit), saved to disk in one write.
#pragma once

#include <corofem/mesh.hpp>

#include <charconv>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

namespace corofem::mesh {

class TextWriter {
 public:
  TextWriter& operator<<(std::string_view s) {
    buf_.append(s.data(), s.size());
    return *this;
  }
  TextWriter& operator<<(char c) {
    buf_.push_back(c);
    return *this;
  }
  TextWriter& operator<<(double v) { return put(v); }
  TextWriter& operator<<(float v) { return put(v); }
  TextWriter& operator<<(std::int64_t v) { return put(v); }
  TextWriter& operator<<(std::uint64_t v) { return put(v); }
  TextWriter& operator<<(std::int32_t v) { return put(v); }
  TextWriter& operator<<(std::uint32_t v) { return put(v); }
  void reserve(std::size_t n) { buf_.reserve(n); }
  const std::string& text() const { return buf_; }

  /// Writes the text to path (through a temporary file renamed into place, so a reader never sees
  /// a half-written file). Throws IoError naming the path.
  void save(const std::string& path) const;

 private:
  template <class T>
  TextWriter& put(T v) {
    char tmp[32];
    auto [ptr, ec] = std::to_chars(tmp, tmp + sizeof tmp, v);
    (void)ec;
    buf_.append(tmp, static_cast<std::size_t>(ptr - tmp));
    return *this;
  }
  std::string buf_;
};

/// XML attribute/text escaping (&, <, >, ").
std::string xmlEscape(std::string_view s);

/// Throws BadInput unless every element index is below the node count, regions are empty or one
/// per element, and every coordinate (texcoord, normal) is finite: what a writer needs to produce a
/// valid file.
void checkWritable(const TetMesh& mesh, const std::string& path);
void checkWritable(const SurfaceMesh& mesh, const std::string& path);

/// Throws BadInput unless each field has components x (node or element count) values, all finite.
void checkFields(const std::vector<MeshField>& fields, std::size_t nodes, std::size_t elements, const std::string& path);

/// Writers behind writeTetMesh / writeSurfaceMesh (one file per format).
void writeVtu(const std::string& path, const TetMesh& mesh, const std::vector<MeshField>& fields,
              const VtuOptions& options);
void writeVtuSurface(const std::string& path, const SurfaceMesh& mesh, const VtuOptions& options);
void writeVtkLegacy(const std::string& path, const TetMesh& mesh, const std::vector<MeshField>& fields);
void writeVtkPolyData(const std::string& path, const SurfaceMesh& mesh);
void writeGmsh22(const std::string& path, const TetMesh& mesh);
void writeMedit(const std::string& path, const TetMesh& mesh);
void writeTetGen(const std::string& nodePath, const std::string& elePath, const TetMesh& mesh);
void writeVeg(const std::string& path, const TetMesh& mesh);
void writeObj(const std::string& path, const SurfaceMesh& mesh);

}  // namespace corofem::mesh
