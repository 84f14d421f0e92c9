// Invariants the fuzz targets check on what the readers and the scene parser accept or refuse.
// A violated invariant prints what went wrong and aborts, which libFuzzer reports as a crash and
// saves the input (tests/fuzz/README.md).
#pragma once

#include <corofem/mesh.hpp>
#include <corofem/status.hpp>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <string_view>

namespace corofem::fuzz {

/// The longest message a refusal may have with the short paths the targets use: the readers and
/// the parser shorten what they quote, so a longer message quotes something whole.
constexpr std::size_t kMaxMessageBytes = 1024;

[[noreturn]] inline void violated(const std::string& what) {
  std::fprintf(stderr, "\n*** corofem fuzz invariant violated: %s\n", what.c_str());
  std::fflush(stderr);
  std::abort();
}

inline void require(bool condition, const std::string& what) {
  if (!condition) violated(what);
}

/// The input with each byte 0x01 (at most 4 of them) replaced by 1500 copies of the byte before it:
/// a cheap way for mutations to make the very long tokens (numbers, words, strings) that messages
/// must not quote whole.
inline std::string expandRuns(std::string_view input) {
  std::string out;
  out.reserve(input.size());
  int runs = 0;
  for (char c : input) {
    if (c == '\x01' && runs < 4) {
      ++runs;
      out.append(1500, out.empty() ? 'x' : out.back());
    } else {
      out += c;
    }
  }
  return out;
}

/// A refusal: never an internal error, a message that is there and bounded.
inline void checkRefusal(const Status& status, std::string_view what) {
  const std::string where(what);
  require(status.code() != ErrorCode::Internal, where + ": internal error: " + status.message());
  require(!status.message().empty(), where + ": an error without a message");
  require(status.message().size() <= kMaxMessageBytes,
          where + ": a message of " + std::to_string(status.message().size()) +
              " bytes: " + status.message().substr(0, 300) + "...");
}

/// What a tet-mesh reader accepted: whole arrays, indices in range, four distinct nodes per
/// element, finite coordinates, positive volumes (the readers reorient and refuse zero volumes),
/// one region per element or none.
inline void checkTetMesh(const TetMesh& mesh, std::string_view what) {
  const std::string where(what);
  require(mesh.nodes.size() % 3 == 0 && mesh.tets.size() % 4 == 0, where + ": arrays are not whole");
  require(mesh.nodeCount() > 0 && mesh.tetCount() > 0, where + ": an empty mesh was accepted");
  for (double x : mesh.nodes) require(std::isfinite(x), where + ": a non-finite coordinate");
  for (std::size_t e = 0; e < mesh.tetCount(); ++e) {
    const std::uint32_t* t = &mesh.tets[4 * e];
    for (int a = 0; a < 4; ++a) {
      require(t[a] < mesh.nodeCount(), where + ": element " + std::to_string(e) + " has a node out of range");
      for (int b = a + 1; b < 4; ++b) require(t[a] != t[b], where + ": element " + std::to_string(e) + " repeats a node");
    }
    const double v = signedVolume(mesh, e);
    require(v > 0 && std::isfinite(v), where + ": element " + std::to_string(e) + " has volume " + std::to_string(v));
  }
  require(mesh.regions.empty() || mesh.regions.size() == mesh.tetCount(), where + ": regions are not one per element");
}

/// What the OBJ reader accepted: whole arrays, indices in range, finite values, texcoords 2 per
/// vertex or none.
inline void checkSurface(const SurfaceMesh& mesh, std::string_view what) {
  const std::string where(what);
  require(mesh.vertices.size() % 3 == 0 && mesh.triangles.size() % 3 == 0, where + ": arrays are not whole");
  require(mesh.vertexCount() > 0, where + ": a surface without vertices was accepted");
  for (double x : mesh.vertices) require(std::isfinite(x), where + ": a non-finite coordinate");
  for (std::uint32_t i : mesh.triangles) require(i < mesh.vertexCount(), where + ": a triangle corner out of range");
  require(mesh.texcoords.empty() || mesh.texcoords.size() == 2 * mesh.vertexCount(),
          where + ": texcoords are not 2 per vertex");
  for (float t : mesh.texcoords) require(std::isfinite(t), where + ": a non-finite texcoord");
}

}  // namespace corofem::fuzz
