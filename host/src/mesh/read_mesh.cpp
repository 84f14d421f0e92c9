// readTetMesh / readSurfaceMesh: choose the parser from the extension, read the file once into
// memory, parse, and run the shared validation (mesh_validation.cpp).
#include "mesh/readers.hpp"
#include "mesh/text_scanner.hpp"

#include <corofem/mesh.hpp>

namespace corofem {

namespace {

constexpr const char* kTetExtensions =
    ".msh (Gmsh 1, 2.2, 4.1 ASCII), .node/.ele (TetGen), .mesh (Medit), .vtk (legacy VTK), .veg (Vega)";

std::string withExtension(const std::string& path, const char* ext) {
  return path.substr(0, path.size() - mesh::lowerExtension(path).size()) + ext;
}

TetMesh readTetMeshOrThrow(const std::string& path, MeshReadReport& report, const MeshValidation& validation,
                           const InputLimits& limits) {
  const std::string ext = mesh::lowerExtension(path);
  mesh::ParsedTetMesh parsed;
  std::string messagePath = path;
  if (ext == ".msh") {
    parsed = mesh::parseGmsh(mesh::readWholeFile(path, limits), path, report);
  } else if (ext == ".node" || ext == ".ele") {
    const std::string nodePath = ext == ".node" ? path : withExtension(path, ".node");
    const std::string elePath = ext == ".ele" ? path : withExtension(path, ".ele");
    parsed = mesh::parseTetGen(nodePath, elePath, report, limits);
    messagePath = elePath;  // element errors are reported against the .ele file
  } else if (ext == ".mesh") {
    parsed = mesh::parseMedit(mesh::readWholeFile(path, limits), path, report);
  } else if (ext == ".vtk") {
    parsed = mesh::parseVtkLegacy(mesh::readWholeFile(path, limits), path, report);
  } else if (ext == ".veg") {
    parsed = mesh::parseVeg(mesh::readWholeFile(path, limits), path, report);
  } else {
    detail::fail(ErrorCode::BadInput, "cannot read tetrahedral mesh ", path, ": unknown extension '", ext,
                 "'; supported are ", kTetExtensions);
  }
  return mesh::finalizeTetMesh(std::move(parsed), messagePath, validation, &report);
}

}  // namespace

Result<TetMesh> readTetMesh(const std::string& path, MeshReadReport* report, const MeshValidation& validation,
                            const InputLimits& limits) {
  return detail::guardResult<TetMesh>([&] {
    MeshReadReport local;
    TetMesh mesh = readTetMeshOrThrow(path, local, validation, limits);
    if (report) *report = std::move(local);
    return mesh;
  });
}

Result<SurfaceMesh> readSurfaceMesh(const std::string& path, MeshReadReport* report, const InputLimits& limits) {
  return detail::guardResult<SurfaceMesh>([&] {
    const std::string ext = mesh::lowerExtension(path);
    if (ext != ".obj")
      detail::fail(ErrorCode::BadInput, "cannot read surface mesh ", path, ": unknown extension '", ext,
                   "'; supported is .obj (Wavefront OBJ)");
    MeshReadReport local;
    SurfaceMesh mesh = mesh::parseObj(mesh::readWholeFile(path, limits), path, local);
    if (report) *report = std::move(local);
    return mesh;
  });
}

}  // namespace corofem
