// writeTetMesh / writeSurfaceMesh: checks, then the writer chosen by the extension.
#include "mesh/text_scanner.hpp"
#include "mesh/text_writer.hpp"

#include <corofem/mesh.hpp>

namespace corofem {

Status writeTetMesh(const std::string& path, const TetMesh& mesh, const std::vector<MeshField>& fields,
                    const VtuOptions& vtu) {
  return detail::guard([&] {
    const std::string ext = mesh::lowerExtension(path);
    mesh::checkWritable(mesh, path);
    mesh::checkFields(fields, mesh.nodeCount(), mesh.tetCount(), path);
    const std::string stem = path.substr(0, path.size() - ext.size());
    if (ext == ".vtu") {
      mesh::writeVtu(path, mesh, fields, vtu);
    } else if (ext == ".vtk") {
      mesh::writeVtkLegacy(path, mesh, fields);
    } else if (ext == ".msh") {
      mesh::writeGmsh22(path, mesh);
    } else if (ext == ".mesh") {
      mesh::writeMedit(path, mesh);
    } else if (ext == ".node" || ext == ".ele") {
      mesh::writeTetGen(stem + ".node", stem + ".ele", mesh);
    } else if (ext == ".veg") {
      mesh::writeVeg(path, mesh);
    } else {
      detail::fail(ErrorCode::BadInput, "cannot write tetrahedral mesh ", path, ": unknown extension '", ext,
                   "'; supported are .vtu (VTK XML), .vtk (legacy VTK), .msh (Gmsh 2.2), .mesh (Medit), "
                   ".node/.ele (TetGen), .veg (Vega)");
    }
  });
}

Status writeSurfaceMesh(const std::string& path, const SurfaceMesh& mesh, const VtuOptions& vtu) {
  return detail::guard([&] {
    const std::string ext = mesh::lowerExtension(path);
    mesh::checkWritable(mesh, path);
    if (ext == ".obj") {
      mesh::writeObj(path, mesh);
    } else if (ext == ".vtk") {
      mesh::writeVtkPolyData(path, mesh);
    } else if (ext == ".vtu") {
      mesh::writeVtuSurface(path, mesh, vtu);
    } else {
      detail::fail(ErrorCode::BadInput, "cannot write surface mesh ", path, ": unknown extension '", ext,
                   "'; supported are .obj (Wavefront OBJ), .vtk (legacy VTK POLYDATA), .vtu (VTK XML)");
    }
  });
}

}  // namespace corofem
