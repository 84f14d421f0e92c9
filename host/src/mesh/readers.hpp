// The format parsers behind readTetMesh / readSurfaceMesh. Each takes the whole file text (read once
// into memory) and returns what it found in the file's own numbering; read_mesh.cpp dispatches on the
// extension and hands tet meshes to finalizeTetMesh (mesh_validation.hpp) for the shared checks.
#pragma once

#include "mesh/mesh_validation.hpp"

#include <corofem/mesh.hpp>

#include <string>

namespace corofem::mesh {

/// Gmsh .msh ASCII: version 1 ($NOD/$ELM), 2.x and 4.1. Only tetrahedra (type 4) are kept; other
/// element types are counted in report.skippedByType. Regions: the physical tag (v1, v2) or the volume
/// entity tag (v4.1); none when all are 0 (Gmsh's "no physical group").
ParsedTetMesh parseGmsh(const std::string& text, const std::string& path, MeshReadReport& report);

/// TetGen .node + .ele (0- or 1-based, detected from the first node id; first element attribute ->
/// regions). Reads the .node file first, so its errors come before a missing .ele; each file at most
/// limits.maxInputBytes.
ParsedTetMesh parseTetGen(const std::string& nodePath, const std::string& elePath, MeshReadReport& report,
                          const InputLimits& limits);

/// Medit .mesh (ASCII): Vertices and Tetrahedra (reference -> regions); other sections skipped.
ParsedTetMesh parseMedit(const std::string& text, const std::string& path, MeshReadReport& report);

/// VTK legacy ASCII UNSTRUCTURED_GRID, versions 2.0-4.2 (CELLS n size) and 5.1 (OFFSETS/CONNECTIVITY).
/// Cell type 10 kept; a one-component integer cell array named like mat_id/region -> regions.
ParsedTetMesh parseVtkLegacy(const std::string& text, const std::string& path, MeshReadReport& report);

/// Vega .veg: *VERTICES, *ELEMENTS TET (1-based); *MATERIAL, *REGION, *SET tolerated.
ParsedTetMesh parseVeg(const std::string& text, const std::string& path, MeshReadReport& report);

/// Wavefront OBJ surface: v, vt, f (all index forms, negative indices); polygons fan-split.
SurfaceMesh parseObj(const std::string& text, const std::string& path, MeshReadReport& report);

}  // namespace corofem::mesh
