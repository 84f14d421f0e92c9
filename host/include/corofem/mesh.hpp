// Meshes: a tetrahedral volume mesh and a triangle surface mesh; reading, writing and generating.
#pragma once

#include <corofem/status.hpp>

#include <array>
#include <cstddef>
#include <cstdint>
#include <map>
#include <string>
#include <vector>

namespace corofem {

/// Linear tetrahedral mesh. Elements are positively oriented after loading:
/// (b-a) . ((c-a) x (d-a)) > 0 for element nodes (a, b, c, d).
struct TetMesh {
  std::vector<double> nodes;          ///< 3 per node: x, y, z (scene units, SI metres by convention)
  std::vector<std::uint32_t> tets;    ///< 4 per element: 0-based node indices
  std::vector<std::int32_t> regions;  ///< one region id per element, or empty when the file has none

  std::size_t nodeCount() const { return nodes.size() / 3; }
  std::size_t tetCount() const { return tets.size() / 4; }
};

/// Triangle surface mesh (render surface, coupled-mesh target). Quads and polygons are fan-split.
struct SurfaceMesh {
  std::vector<double> vertices;          ///< 3 per vertex
  std::vector<std::uint32_t> triangles;  ///< 3 per triangle, 0-based vertex indices
  std::vector<float> texcoords;          ///< 2 per vertex when the file has per-vertex UVs, else empty
  /// 3 per vertex, unit length (0 0 0 for a vertex with no triangle), or empty: the smooth normals
  /// of a deformed surface (Simulation::readSurface, deformSurface). Written by the OBJ (`vn`) and
  /// .vtu ("Normals" point data) writers; the OBJ reader leaves it empty.
  std::vector<float> normals;

  std::size_t vertexCount() const { return vertices.size() / 3; }
  std::size_t triangleCount() const { return triangles.size() / 3; }
};

/// What a reader did beyond returning the mesh.
struct MeshReadReport {
  std::string format;                              ///< e.g. "gmsh 4.1", "medit", "vtk legacy 5.1"
  std::size_t reorientedElements = 0;              ///< negatively oriented elements whose nodes were swapped
  std::size_t skippedElements = 0;                 ///< non-tetrahedral elements skipped (Gmsh, VTK)
  std::map<std::string, std::size_t> skippedByType;///< e.g. {"triangle (gmsh type 2)": 120}
  std::size_t splitPolygons = 0;                   ///< OBJ quads/polygons fan-split into triangles
};

/// The largest inputs corofem reads or generates: a guard against a wrong path or a corrupt or
/// hostile file exhausting the memory. The defaults are far above anything corofem can simulate on
/// one machine; raise a limit where the machine has the memory. Every loading call takes it
/// (readTetMesh, readSurfaceMesh, generateBox, loadScene, parseScene, loadBodyMesh, resolveNodeSet,
/// and SimulationOptions::inputLimits for the files a Simulation reads); the C API's counterpart is
/// corofem_input_limits, the command's the flags --max-input-bytes, --max-scene-bytes and
/// --max-box-tets. An input over a limit is BadInput naming the limit, its value and how to raise
/// it; an input exactly at a limit is read.
/// A value is a hard limit: 0 refuses every input of its kind (the C API's corofem_input_limits,
/// which C code often zero-fills, reads 0 as the default instead).
struct InputLimits {
  /// Bytes: the largest mesh (every file of it: TetGen's .node and .ele each), surface (.obj) or
  /// .bou file read. Default 1 GiB.
  std::uint64_t maxInputBytes = std::uint64_t(1) << 30;
  /// Bytes: the largest scene (JSON) file read. Default 16 MiB (scenes have a few KiB; the parsed
  /// JSON takes many times the text's size).
  std::uint64_t maxSceneBytes = std::uint64_t(16) << 20;
  /// Tetrahedra: the largest box generateBox (and a scene's "box" mesh) makes. Default 50 million
  /// (about 1 GB for the mesh alone, and far more to simulate it).
  std::uint64_t maxBoxTets = 50'000'000;
};

/// Options of mesh validation on load.
struct MeshValidation {
  /// An element whose volume is below this fraction of the mean element volume is an error
  /// ("near-zero volume"). 0 disables the relative test; exactly zero volume is always an error.
  double minRelativeVolume = 1e-12;
  bool reorient = true;  ///< swap two nodes of negatively oriented elements (counted in the report)
};

/// Reads a tetrahedral mesh; the format is chosen from the extension (.msh Gmsh 1/2.2/4.1,
/// .node/.ele TetGen given either file, .mesh Medit, .vtk legacy, .veg Vega). Errors name the file,
/// line and element. A file larger than limits.maxInputBytes is refused (BadInput).
Result<TetMesh> readTetMesh(const std::string& path, MeshReadReport* report = nullptr,
                            const MeshValidation& validation = {}, const InputLimits& limits = {});

/// Reads a triangle surface mesh (.obj; also the boundary of any tet mesh format is NOT extracted).
/// A file larger than limits.maxInputBytes is refused (BadInput).
Result<SurfaceMesh> readSurfaceMesh(const std::string& path, MeshReadReport* report = nullptr,
                                    const InputLimits& limits = {});

/// Per-node or per-element data written alongside a mesh (VTK formats).
struct MeshField {
  std::string name;          ///< field name shown in ParaView
  int components = 1;        ///< 1 (scalar) or 3 (vector)
  bool perElement = false;   ///< cell data when true, point data otherwise
  std::vector<double> values;///< components x (node or element count)
};

/// How a .vtu file (VTK XML) stores its data arrays. Every format holds the same values: binary
/// arrays are little endian with UInt64 headers, read by ParaView, VTK and meshio.
enum class VtuFormat {
  Ascii,   ///< text (format="ascii"): shortest decimals that read back exactly; the largest files
  Base64,  ///< binary, inline base64 (format="binary"): still well-formed XML
  Raw,     ///< binary, in one appended raw section (format="appended", encoding="raw"): the smallest
           ///< and fastest; not well-formed XML (VTK's own layout)
};

/// Compression of a binary .vtu's arrays.
enum class VtuCompression {
  None,
  Zlib,  ///< vtkZLibDataCompressor in 32 KiB blocks; needs a build with zlib (vtuZlibAvailable())
};

/// Options of the .vtu writers (ignored by the other formats).
struct VtuOptions {
  VtuFormat format = VtuFormat::Ascii;                ///< how the arrays are stored
  VtuCompression compression = VtuCompression::None;  ///< Zlib: only with Base64 or Raw
};

/// True when this build can write zlib-compressed .vtu files (zlib was found at build time).
bool vtuZlibAvailable();

/// Writes a tet mesh; format from the extension: .vtu (VTK XML, stored as `vtu` says), .vtk
/// (legacy 2.0 ASCII), .msh (Gmsh 2.2 ASCII), .mesh (Medit), .node (TetGen, with .ele beside it),
/// .veg (Vega). Non-finite coordinates or field values are refused (BadInput).
Status writeTetMesh(const std::string& path, const TetMesh& mesh, const std::vector<MeshField>& fields = {},
                    const VtuOptions& vtu = {});

/// Writes a surface mesh (.obj, or .vtk/.vtu as a polygonal dataset), with its normals where it
/// has them (.obj and .vtu). Non-finite coordinates, texcoords or normals are refused (BadInput).
Status writeSurfaceMesh(const std::string& path, const SurfaceMesh& mesh, const VtuOptions& vtu = {});

/// A ParaView `.pvd` time-series collection: add (time, file) entries, then write.
class PvdSeries {
 public:
  explicit PvdSeries(std::string pvdPath) : path_(std::move(pvdPath)) {}
  void add(double time, const std::string& fileRelativeToPvd) { entries_.push_back({time, fileRelativeToPvd}); }
  Status write() const;  ///< rewrites the whole .pvd (call after each add: a killed run stays readable)
  const std::string& path() const { return path_; }

 private:
  struct Entry { double time; std::string file; };
  std::string path_;
  std::vector<Entry> entries_;
};

/// Axis-aligned box split into cells, each cell into 5 or 6 tetrahedra.
struct BoxSpec {
  std::array<double, 3> min{0.0, 0.0, 0.0};  ///< lower corner
  std::array<double, 3> max{1.0, 1.0, 1.0};  ///< upper corner, > min on every axis
  std::array<int, 3> cells{1, 1, 1};         ///< cells per axis, >= 1
  int tetsPerCell = 5;                        ///< 5 (alternating, conforming) or 6 (Kuhn split)
};
/// Generates the box. More tetrahedra than limits.maxBoxTets (or more nodes than 32-bit indices
/// reach) is BadInput.
Result<TetMesh> generateBox(const BoxSpec& spec, const InputLimits& limits = {});

/// Geometry and quality summary (the `corofem info` command).
struct MeshInfo {
  std::size_t nodes = 0, tets = 0, boundaryFaces = 0, negativeElements = 0;
  std::array<double, 3> bboxMin{}, bboxMax{};
  double volume = 0, minVolume = 0, maxVolume = 0;
  double minAspect = 0, maxAspect = 0;  ///< aspect ratio: longest edge / (2 sqrt(6) inradius), 1 for regular
  std::size_t unusedNodes = 0;
};
MeshInfo computeMeshInfo(const TetMesh& mesh);

/// Signed volume of element e: (b-a).((c-a)x(d-a)) / 6.
double signedVolume(const TetMesh& mesh, std::size_t element);

}  // namespace corofem
