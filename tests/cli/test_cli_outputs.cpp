// What `corofem run` writes for the tools people use: the render surface's OBJ carries one unit
// normal per vertex (the smooth normals of the deformed surface) and faces that reference them; the
// .vtu series in every vtu_format / vtu_compression reads back with meshio, the surface's "Normals"
// equal to the OBJ's, bit for bit.
#include "cli/cli_runner.hpp"
#include "common/meshio_reader.hpp"
#include "output/run_outputs.hpp"
#include "util/error.hpp"

#include <corofem/mesh.hpp>
#include <corofem/scene.hpp>
#include <corofem/simulation.hpp>

#include <nlohmann/json.hpp>

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <fstream>
#include <sstream>

namespace {

using corofem::test::runCli;
namespace fs = std::filesystem;

/// A closed ellipsoid inside the beam (centre (0.4, 0.05, 0.05), radii 0.35, 0.04, 0.04): poles and
/// rings of shared vertices, so every vertex normal averages several faces.
corofem::SurfaceMesh ellipsoid(int rings, int segments) {
  corofem::SurfaceMesh s;
  const double c[3] = {0.4, 0.05, 0.05}, r[3] = {0.35, 0.04, 0.04};
  const double pi = std::acos(-1.0);
  const auto vertex = [&](double x, double y, double z) {
    s.vertices.push_back(x);
    s.vertices.push_back(y);
    s.vertices.push_back(z);
  };
  vertex(c[0] - r[0], c[1], c[2]);
  for (int i = 1; i < rings; ++i) {
    const double t = pi * i / rings;
    for (int j = 0; j < segments; ++j) {
      const double p = 2 * pi * j / segments;
      vertex(c[0] - r[0] * std::cos(t), c[1] + r[1] * std::sin(t) * std::cos(p), c[2] + r[2] * std::sin(t) * std::sin(p));
    }
  }
  vertex(c[0] + r[0], c[1], c[2]);
  const auto ring = [&](int i, int j) { return std::uint32_t(1 + (i - 1) * segments + (j % segments)); };
  const std::uint32_t last = std::uint32_t(s.vertexCount() - 1);
  for (int j = 0; j < segments; ++j) {
    s.triangles.insert(s.triangles.end(), {0, ring(1, j + 1), ring(1, j)});
    s.triangles.insert(s.triangles.end(), {last, ring(rings - 1, j), ring(rings - 1, j + 1)});
    for (int i = 1; i + 1 < rings; ++i)
      s.triangles.insert(s.triangles.end(), {ring(i, j), ring(i, j + 1), ring(i + 1, j + 1), ring(i, j),
                                             ring(i + 1, j + 1), ring(i + 1, j)});
  }
  return s;
}

struct Obj {
  std::vector<double> v;
  std::vector<float> vn;
  std::vector<std::uint32_t> faces;  ///< 0-based
  std::string error;                 ///< a face corner that is not "a//a"
};

Obj readObj(const fs::path& path) {
  std::ifstream in(path);
  Obj obj;
  for (std::string line; std::getline(in, line);) {
    std::istringstream ls(line);
    std::string key;
    ls >> key;
    if (key == "v") {
      double x, y, z;
      ls >> x >> y >> z;
      obj.v.insert(obj.v.end(), {x, y, z});
    } else if (key == "vn") {
      float x, y, z;
      ls >> x >> y >> z;
      obj.vn.insert(obj.vn.end(), {x, y, z});
    } else if (key == "f") {
      for (std::string corner; ls >> corner;) {
        const auto slashes = corner.find("//");
        if (slashes == std::string::npos || corner.substr(0, slashes) != corner.substr(slashes + 2))
          obj.error = "face corner '" + corner + "' is not v//vn with the same index";
        obj.faces.push_back(std::uint32_t(std::stoul(corner) - 1));
      }
    }
  }
  return obj;
}

/// Runs the beam for 6 steps (VTK at 0, 3, 6) with the ellipsoid as its surface; returns the output folder.
fs::path runWithSurface(const std::string& extra) {
  const fs::path dir = corofem::test::tempDir();
  const corofem::Status st = corofem::writeSurfaceMesh((dir / "ellipsoid.obj").string(), ellipsoid(12, 16));
  EXPECT_TRUE(st.isOk()) << st.message();
  const fs::path out = dir / "out";
  const auto r = runCli(std::string("run ") + corofem::test::kFig8Scene + " -q --out '" + out.string() + "' --set analysis.steps=6" +
                        " --set output.vtk_every=3 --set output.surface_obj=true --set 'bodies.0.surface=\"" +
                        (dir / "ellipsoid.obj").string() + "\"' " + extra);
  EXPECT_EQ(r.exitCode, 0) << r.output;
  return out;
}

TEST(CliOutputs, SurfaceObjHasTheUnitNormalsOfTheDeformedSurface) {
  const fs::path out = runWithSurface("");
  const Obj rest = readObj(out / "surface" / "beam_surface_000000.obj");
  const Obj obj = readObj(out / "surface" / "beam_surface_000006.obj");
  ASSERT_TRUE(obj.error.empty()) << obj.error;
  const std::size_t n = obj.v.size() / 3;
  ASSERT_EQ(n, 2u + 11u * 16u);
  ASSERT_EQ(obj.vn.size(), 3 * n);  // one vn per vertex
  ASSERT_EQ(obj.faces.size(), 3u * (2u * 16u + 2u * 16u * 10u));
  // The smooth normals of the deformed positions: normalise(sum over the vertex's triangles of
  // (b - a) x (c - a)), recomputed here from the OBJ's own v lines and faces.
  std::vector<double> sum(3 * n, 0.0);
  for (std::size_t t = 0; t < obj.faces.size(); t += 3) {
    const double* a = &obj.v[3 * obj.faces[t]];
    const double* b = &obj.v[3 * obj.faces[t + 1]];
    const double* c = &obj.v[3 * obj.faces[t + 2]];
    const double u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]}, w[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
    const double cr[3] = {u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0]};
    for (int k = 0; k < 3; ++k)
      for (int d = 0; d < 3; ++d) sum[3 * obj.faces[t + std::size_t(k)] + std::size_t(d)] += cr[d];
  }
  double moved = 0;  // how far the rest normals are from the deformed ones: the test would see a stale normal
  for (std::size_t i = 0; i < n; ++i) {
    const double len = std::sqrt(sum[3 * i] * sum[3 * i] + sum[3 * i + 1] * sum[3 * i + 1] + sum[3 * i + 2] * sum[3 * i + 2]);
    const double vnLen = std::hypot(double(obj.vn[3 * i]), double(obj.vn[3 * i + 1]), double(obj.vn[3 * i + 2]));
    ASSERT_NEAR(vnLen, 1.0, 1e-6) << "vn " << i + 1;
    for (int d = 0; d < 3; ++d) {
      ASSERT_NEAR(obj.vn[3 * i + std::size_t(d)], sum[3 * i + std::size_t(d)] / len, 1e-6) << "vn " << i + 1;
      moved = std::max(moved, std::abs(double(rest.vn[3 * i + std::size_t(d)]) - sum[3 * i + std::size_t(d)] / len));
    }
  }
  EXPECT_GT(moved, 1e-4) << "the beam did not deform enough for this test to tell rest from deformed normals";
}

struct FormatCase {
  const char* format;
  const char* compression;
};

void PrintTo(const FormatCase& c, std::ostream* os) { *os << c.format << '/' << c.compression; }

class CliVtuFormats : public ::testing::TestWithParam<FormatCase> {};

TEST_P(CliVtuFormats, SeriesReadBackWithMeshioWithTheObjsNormals) {
  COROFEM_REQUIRE_MESHIO();
  const FormatCase f = GetParam();
  if (std::string(f.compression) == "zlib" && !corofem::vtuZlibAvailable())
    GTEST_SKIP() << "this build has no zlib (zlib1g-dev was absent at configure time); zlib is not tested";
  const fs::path out = runWithSurface(std::string("--set output.vtu_format=") + f.format +
                                      " --set output.vtu_compression=" + f.compression);
  const std::string tag = std::string("format=\"") + (std::string(f.format) == "ascii" ? "ascii" : std::string(f.format) == "raw" ? "appended" : "binary") + "\"";
  std::string error;

  // The tetrahedra: 8 cells x 5 tets; points = rest + displacement, as written.
  const fs::path tetPath = out / "vtk" / "beam_000006.vtu";
  std::ifstream tetIn(tetPath, std::ios::binary);
  std::stringstream tetText;
  tetText << tetIn.rdbuf();
  EXPECT_NE(tetText.str().find(tag), std::string::npos) << "the series is not in the asked format " << tag;
  const nlohmann::json tet = corofem::test::readWithMeshio(tetPath.string(), error);
  ASSERT_FALSE(tet.is_null()) << error;
  ASSERT_EQ(tet.at("cells").size(), 1u);
  EXPECT_EQ(tet.at("cells")[0].at("type"), "tetra");
  EXPECT_EQ(tet.at("cells")[0].at("values").size(), 4u * 40u);
  corofem::BoxSpec spec;
  spec.max = {0.8, 0.1, 0.1};
  spec.cells = {8, 1, 1};
  const corofem::TetMesh box = corofem::generateBox(spec).value();
  const auto points = tet.at("points").at("values").get<std::vector<double>>();
  const auto disp = tet.at("point_data").at("displacement").at("values").get<std::vector<double>>();
  ASSERT_EQ(points.size(), box.nodes.size());
  ASSERT_EQ(disp.size(), box.nodes.size());
  double largest = 0;
  for (std::size_t i = 0; i < points.size(); ++i) {
    ASSERT_NEAR(points[i] - disp[i], box.nodes[i], 1e-15) << "value " << i;
    largest = std::max(largest, std::abs(disp[i]));
  }
  EXPECT_GT(largest, 1e-4);  // the beam moved
  EXPECT_TRUE(tet.at("point_data").contains("velocity"));

  // The surface: positions and normals equal the OBJ's of the same step, bit for bit.
  const Obj obj = readObj(out / "surface" / "beam_surface_000006.obj");
  const nlohmann::json surface = corofem::test::readWithMeshio((out / "vtk" / "beam_surface_000006.vtu").string(), error);
  ASSERT_FALSE(surface.is_null()) << error;
  EXPECT_EQ(surface.at("cells")[0].at("type"), "triangle");
  EXPECT_EQ(surface.at("cells")[0].at("values").get<std::vector<std::uint32_t>>(), obj.faces);
  EXPECT_EQ(surface.at("points").at("values").get<std::vector<double>>(), obj.v);
  const nlohmann::json& normals = surface.at("point_data").at("Normals");
  EXPECT_EQ(normals.at("dtype"), "float32");
  const auto vn = normals.at("values").get<std::vector<double>>();
  ASSERT_EQ(vn.size(), obj.vn.size());
  for (std::size_t i = 0; i < vn.size(); ++i) ASSERT_EQ(vn[i], double(obj.vn[i])) << "normal value " << i;
}

INSTANTIATE_TEST_SUITE_P(EveryFormat, CliVtuFormats,
                         ::testing::Values(FormatCase{"ascii", "none"}, FormatCase{"base64", "none"},
                                           FormatCase{"raw", "none"}, FormatCase{"base64", "zlib"},
                                           FormatCase{"raw", "zlib"}),
                         [](const auto& info) { return std::string(info.param.format) + "_" + info.param.compression; });

TEST(CliOutputs, ZlibWithAsciiIsBadInputNamingTheKeys) {
  const auto r = runCli(std::string("run ") + corofem::test::kFig8Scene + " -q --out '" + (corofem::test::tempDir() / "out").string() +
                        "' --set output.vtu_compression=zlib");
  EXPECT_EQ(r.exitCode, 2) << r.output;
  EXPECT_NE(r.output.find("output.vtu_compression"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("set vtu_format to \"base64\" or \"raw\""), std::string::npos) << r.output;
}

TEST(CliOutputs, RunOutputsRefuseWhatTheParserWouldForASceneMadeInCode) {
  auto scene = corofem::loadScene(corofem::test::kFig8Scene);
  ASSERT_TRUE(scene.isOk()) << scene.message();
  scene.value().output.vtuCompression = corofem::VtuCompression::Zlib;  // with the default ascii format
  auto sim = corofem::Simulation::create(scene.value());
  ASSERT_TRUE(sim.isOk()) << sim.message();
  const fs::path dir = corofem::test::tempDir() / "out";
  try {
    corofem::detail::RunOutputs out(sim.value(), dir.string());
    FAIL() << "RunOutputs accepted zlib with the ascii format";
  } catch (const corofem::detail::Error& e) {
    EXPECT_EQ(e.code(), corofem::ErrorCode::BadInput);
    EXPECT_NE(std::string(e.what()).find("output.vtu_compression"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(fs::exists(dir)) << "nothing is written before the refusal";
}

}  // namespace
