// Scene parsing: defaults, every field mapped to its struct member, shorthands, loadScene.
#include "scene/scene_test_util.hpp"

#include "common/test_data.hpp"

#include <corofem/scene.hpp>

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

namespace corofem {
namespace {

using test::parseOk;

TEST(SceneParse, MinimalSceneTakesEveryDefault) {
  const Scene s = parseOk(test::kMinimalScene);
  const Scene d;  // the struct defaults are the contract
  EXPECT_EQ(s.name, "scene");
  ASSERT_EQ(s.bodies.size(), 1u);
  const BodyDesc& b = s.bodies[0];
  const BodyDesc db;
  EXPECT_EQ(b.name, "body");
  ASSERT_TRUE(b.mesh.box.has_value());
  EXPECT_TRUE(b.mesh.file.empty());
  EXPECT_EQ(b.mesh.box->min, BoxSpec{}.min);
  EXPECT_EQ(b.mesh.box->max, BoxSpec{}.max);
  EXPECT_EQ(b.mesh.box->cells, BoxSpec{}.cells);
  EXPECT_EQ(b.mesh.box->tetsPerCell, BoxSpec{}.tetsPerCell);
  EXPECT_EQ(b.mesh.scale, 1.0);
  EXPECT_EQ(b.mesh.translate, (Vec3{0, 0, 0}));
  EXPECT_EQ(b.material.youngsModulus, db.material.youngsModulus);
  EXPECT_EQ(b.material.poissonRatio, db.material.poissonRatio);
  EXPECT_EQ(b.material.density, db.material.density);
  EXPECT_EQ(b.material.rayleighMass, db.material.rayleighMass);
  EXPECT_EQ(b.material.rayleighStiffness, db.material.rayleighStiffness);
  EXPECT_EQ(b.formulation, Formulation::Corotational);
  EXPECT_TRUE(b.fixed.empty());
  EXPECT_TRUE(b.loads.empty());
  EXPECT_EQ(b.initialVelocity, (Vec3{0, 0, 0}));
  EXPECT_EQ(b.initialAngularVelocity, (Vec3{0, 0, 0}));
  EXPECT_TRUE(b.surface.empty());
  EXPECT_EQ(b.surfaceLayout, SurfaceLayout::Interleaved);

  EXPECT_EQ(s.analysis.kind, d.analysis.kind);
  EXPECT_EQ(s.analysis.statics.increments, d.analysis.statics.increments);
  EXPECT_EQ(s.analysis.statics.maxNewtonIterations, d.analysis.statics.maxNewtonIterations);
  EXPECT_EQ(s.analysis.statics.residualTolerance, d.analysis.statics.residualTolerance);
  EXPECT_EQ(s.analysis.statics.displacementTolerance, d.analysis.statics.displacementTolerance);
  EXPECT_EQ(s.analysis.dynamics.integrator, d.analysis.dynamics.integrator);
  EXPECT_EQ(s.analysis.dynamics.timeStep, d.analysis.dynamics.timeStep);
  EXPECT_EQ(s.analysis.dynamics.steps, d.analysis.dynamics.steps);
  EXPECT_EQ(s.analysis.dynamics.newmarkBeta, d.analysis.dynamics.newmarkBeta);
  EXPECT_EQ(s.analysis.dynamics.newmarkGamma, d.analysis.dynamics.newmarkGamma);
  EXPECT_EQ(s.analysis.dynamics.newtonIterations, d.analysis.dynamics.newtonIterations);
  EXPECT_EQ(s.analysis.dynamics.newtonTolerance, d.analysis.dynamics.newtonTolerance);

  EXPECT_EQ(s.solver.linearSolver, d.solver.linearSolver);
  EXPECT_EQ(s.solver.tolerance, d.solver.tolerance);
  EXPECT_EQ(s.solver.maxIterations, d.solver.maxIterations);
  EXPECT_EQ(s.solver.checkEvery, d.solver.checkEvery);
  EXPECT_EQ(s.solver.preconditioner, d.solver.preconditioner);
  EXPECT_EQ(s.solver.precision, d.solver.precision);
  EXPECT_EQ(s.solver.rotation, d.solver.rotation);
  EXPECT_EQ(s.backend.kind, BackendKind::Auto);
  EXPECT_TRUE(s.backend.device.empty());
  EXPECT_TRUE(s.output.probes.empty());
  EXPECT_EQ(s.output.vtk, d.output.vtk);
  EXPECT_EQ(s.output.vtkEvery, d.output.vtkEvery);
  EXPECT_EQ(s.output.surfaceObj, d.output.surfaceObj);
  EXPECT_EQ(s.output.vtuFormat, d.output.vtuFormat);
  EXPECT_EQ(s.output.vtuFormat, VtuFormat::Ascii);
  EXPECT_EQ(s.output.vtuCompression, VtuCompression::None);
}

// Every key set to a value unlike its default, to show that each reaches its own struct member.
const char* kFullScene = R"({
  "name": "everything",
  "backend": {"kind": "opencl", "device": "NVIDIA"},
  "bodies": [
    {"name": "beam",
     "mesh": {"box": {"min": [0, -0.05, -0.05], "max": [0.8, 0.05, 0.05], "cells": [8, 2, 3], "tets_per_cell": 6},
              "scale": 2.5, "translate": [1, 2, 3]},
     "material": {"youngs_modulus": 5e4, "poisson_ratio": -0.25, "density": 1200.5,
                  "rayleigh_mass": 0.125, "rayleigh_stiffness": 0.002},
     "formulation": "linear",
     "fixed": [{"box": {"min": [-1, -1, -1], "max": [0.001, 1, 1]}},
               {"plane": {"point": [0, 0, 0], "normal": [1, 0, 0], "tolerance": 1e-6}},
               {"list": [0, 5, 7]},
               {"bou": "clamp.bou"}],
     "loads": [{"type": "gravity", "vector": [0, 0, -9.81], "ramp_time": 0.5},
               {"type": "force", "vector": [0, -10, 0], "nodes": {"list": [3]}, "ramp_time": 0.25},
               {"type": "displacement", "vector": [0.1, 0, 0], "nodes": {"plane": {"point": [0.8, 0, 0], "normal": [2, 0, 0]}}}],
     "initial_velocity": [1, 0, 0],
     "initial_angular_velocity": [0, 0, 3.5],
     "surface": "beam.obj", "surface_layout": "separate"},
    {"mesh": {"file": "other.msh"}, "formulation": "neo_hookean"},
    {"mesh": "third.veg", "formulation": "stvk"}
  ],
  "analysis": {"type": "dynamic", "integrator": "backward_euler", "time_step": 0.005, "steps": 42,
               "newmark_beta": 0.3, "newmark_gamma": 0.6, "newton_iterations": 3, "newton_tolerance": 1e-7},
  "solver": {"linear_solver": "pcg", "tolerance": 1e-9, "max_iterations": 250, "check_every": 8,
             "preconditioner": "block_diagonal", "precision": "float", "rotation": "quaternion"},
  "output": {"probes": [{"name": "tip", "body": "beam", "nodes": {"list": [1, 2]}},
                        {"nodes": {"list": [0]}}],
             "vtk": false, "vtk_every": 7, "surface_obj": true, "vtu_format": "base64"}
})";

TEST(SceneParse, EveryKeyReachesItsField) {
  // OpenCL with stvk/neo_hookean is rejected, so parse with the backend switched to reference.
  const Scene s = parseOk(kFullScene, {"backend.kind=reference"});
  EXPECT_EQ(s.name, "everything");
  EXPECT_EQ(s.backend.kind, BackendKind::Reference);
  EXPECT_EQ(s.backend.device, "NVIDIA");
  ASSERT_EQ(s.bodies.size(), 3u);
  const BodyDesc& b = s.bodies[0];
  EXPECT_EQ(b.name, "beam");
  ASSERT_TRUE(b.mesh.box.has_value());
  EXPECT_EQ(b.mesh.box->min, (std::array<double, 3>{0, -0.05, -0.05}));
  EXPECT_EQ(b.mesh.box->max, (std::array<double, 3>{0.8, 0.05, 0.05}));
  EXPECT_EQ(b.mesh.box->cells, (std::array<int, 3>{8, 2, 3}));
  EXPECT_EQ(b.mesh.box->tetsPerCell, 6);
  EXPECT_EQ(b.mesh.scale, 2.5);
  EXPECT_EQ(b.mesh.translate, (Vec3{1, 2, 3}));
  EXPECT_EQ(b.material.youngsModulus, 5e4);
  EXPECT_EQ(b.material.poissonRatio, -0.25);
  EXPECT_EQ(b.material.density, 1200.5);
  EXPECT_EQ(b.material.rayleighMass, 0.125);
  EXPECT_EQ(b.material.rayleighStiffness, 0.002);
  EXPECT_EQ(b.formulation, Formulation::Linear);
  ASSERT_EQ(b.fixed.size(), 4u);
  EXPECT_EQ(b.fixed[0].kind, NodeSetDesc::Kind::Box);
  EXPECT_EQ(b.fixed[0].boxMin, (Vec3{-1, -1, -1}));
  EXPECT_EQ(b.fixed[0].boxMax, (Vec3{0.001, 1, 1}));
  EXPECT_EQ(b.fixed[1].kind, NodeSetDesc::Kind::Plane);
  EXPECT_EQ(b.fixed[1].planePoint, (Vec3{0, 0, 0}));
  EXPECT_EQ(b.fixed[1].planeNormal, (Vec3{1, 0, 0}));
  EXPECT_EQ(b.fixed[1].planeTolerance, 1e-6);
  EXPECT_EQ(b.fixed[2].kind, NodeSetDesc::Kind::List);
  EXPECT_EQ(b.fixed[2].indices, (std::vector<std::uint32_t>{0, 5, 7}));
  EXPECT_EQ(b.fixed[3].kind, NodeSetDesc::Kind::BouFile);
  EXPECT_EQ(b.fixed[3].bouFile, "clamp.bou");
  ASSERT_EQ(b.loads.size(), 3u);
  EXPECT_EQ(b.loads[0].kind, LoadDesc::Kind::Gravity);
  EXPECT_EQ(b.loads[0].vector, (Vec3{0, 0, -9.81}));
  EXPECT_EQ(b.loads[0].rampTime, 0.5);
  EXPECT_EQ(b.loads[1].kind, LoadDesc::Kind::Force);
  EXPECT_EQ(b.loads[1].vector, (Vec3{0, -10, 0}));
  EXPECT_EQ(b.loads[1].nodes.kind, NodeSetDesc::Kind::List);
  EXPECT_EQ(b.loads[1].nodes.indices, (std::vector<std::uint32_t>{3}));
  EXPECT_EQ(b.loads[1].rampTime, 0.25);
  EXPECT_EQ(b.loads[2].kind, LoadDesc::Kind::Displacement);
  EXPECT_EQ(b.loads[2].vector, (Vec3{0.1, 0, 0}));
  EXPECT_EQ(b.loads[2].nodes.kind, NodeSetDesc::Kind::Plane);
  EXPECT_EQ(b.loads[2].nodes.planeNormal, (Vec3{2, 0, 0}));
  EXPECT_EQ(b.loads[2].nodes.planeTolerance, NodeSetDesc{}.planeTolerance);
  EXPECT_EQ(b.loads[2].rampTime, 0.0);
  EXPECT_EQ(b.initialVelocity, (Vec3{1, 0, 0}));
  EXPECT_EQ(b.initialAngularVelocity, (Vec3{0, 0, 3.5}));
  EXPECT_EQ(b.surface, "beam.obj");
  EXPECT_EQ(b.surfaceLayout, SurfaceLayout::Separate);

  EXPECT_EQ(s.bodies[1].name, "body1");  // unnamed bodies are "body", "body1", ...
  EXPECT_EQ(s.bodies[1].mesh.file, "other.msh");
  EXPECT_FALSE(s.bodies[1].mesh.box.has_value());
  EXPECT_EQ(s.bodies[1].formulation, Formulation::NeoHookean);
  EXPECT_EQ(s.bodies[2].mesh.file, "third.veg");  // "mesh": "file" shorthand
  EXPECT_EQ(s.bodies[2].formulation, Formulation::StVenantKirchhoff);

  EXPECT_EQ(s.analysis.kind, AnalysisDesc::Kind::Dynamic);
  EXPECT_EQ(s.analysis.dynamics.integrator, Integrator::BackwardEuler);
  EXPECT_EQ(s.analysis.dynamics.timeStep, 0.005);
  EXPECT_EQ(s.analysis.dynamics.steps, 42);
  EXPECT_EQ(s.analysis.dynamics.newmarkBeta, 0.3);
  EXPECT_EQ(s.analysis.dynamics.newmarkGamma, 0.6);
  EXPECT_EQ(s.analysis.dynamics.newtonIterations, 3);
  EXPECT_EQ(s.analysis.dynamics.newtonTolerance, 1e-7);

  EXPECT_EQ(s.solver.linearSolver, LinearSolverKind::Pcg);
  EXPECT_EQ(s.solver.tolerance, 1e-9);
  EXPECT_EQ(s.solver.maxIterations, 250);
  EXPECT_EQ(s.solver.checkEvery, 8);
  EXPECT_EQ(s.solver.preconditioner, PreconditionerKind::BlockDiagonal);
  EXPECT_EQ(s.solver.precision, Precision::Float);
  EXPECT_EQ(s.solver.rotation, RotationMethod::Quaternion);

  ASSERT_EQ(s.output.probes.size(), 2u);
  EXPECT_EQ(s.output.probes[0].name, "tip");
  EXPECT_EQ(s.output.probes[0].body, "beam");
  EXPECT_EQ(s.output.probes[0].nodes.indices, (std::vector<std::uint32_t>{1, 2}));
  EXPECT_EQ(s.output.probes[1].name, "probe1");  // default probe name: "probe<index>"
  EXPECT_EQ(s.output.probes[1].body, "");        // "" = the first body
  EXPECT_FALSE(s.output.vtk);
  EXPECT_EQ(s.output.vtkEvery, 7);
  EXPECT_TRUE(s.output.surfaceObj);
  EXPECT_EQ(s.output.vtuFormat, VtuFormat::Base64);
}

TEST(SceneParse, VtuFormatAndCompression) {
  const std::string scene = R"({"bodies": [{"mesh": {"box": {}}}]})";
  EXPECT_EQ(parseOk(scene, {"output.vtu_format=raw"}).output.vtuFormat, VtuFormat::Raw);
  EXPECT_EQ(parseOk(scene, {"output.vtu_format=ascii"}).output.vtuFormat, VtuFormat::Ascii);
  EXPECT_EQ(parseOk(scene, {"output.vtu_compression=none"}).output.vtuCompression, VtuCompression::None);
  if (!vtuZlibAvailable()) GTEST_SKIP() << "this build has no zlib: \"zlib\" is refused (SceneErrors.VtuCompression*)";
  const Scene z = parseOk(scene, {"output.vtu_format=base64", "output.vtu_compression=zlib"});
  EXPECT_EQ(z.output.vtuFormat, VtuFormat::Base64);
  EXPECT_EQ(z.output.vtuCompression, VtuCompression::Zlib);
}

TEST(SceneParse, StaticAnalysisFields) {
  const Scene s = parseOk(R"({"bodies": [{"mesh": {"file": "a.msh"}}],
    "analysis": {"type": "static", "increments": 4, "max_newton_iterations": 12,
                 "residual_tolerance": 1e-9, "displacement_tolerance": 1e-10},
    "solver": {"linear_solver": "cholesky", "preconditioner": "none", "precision": "double", "rotation": "svd"}})");
  EXPECT_EQ(s.analysis.kind, AnalysisDesc::Kind::Static);
  EXPECT_EQ(s.analysis.statics.increments, 4);
  EXPECT_EQ(s.analysis.statics.maxNewtonIterations, 12);
  EXPECT_EQ(s.analysis.statics.residualTolerance, 1e-9);
  EXPECT_EQ(s.analysis.statics.displacementTolerance, 1e-10);
  EXPECT_EQ(s.solver.linearSolver, LinearSolverKind::Cholesky);
  EXPECT_EQ(s.solver.preconditioner, PreconditionerKind::None);
  EXPECT_EQ(s.solver.rotation, RotationMethod::Svd);
}

TEST(SceneParse, EnumerationsAndShorthands) {
  for (const auto& [text, kind] : std::vector<std::pair<std::string, BackendKind>>{
           {"\"auto\"", BackendKind::Auto}, {"\"reference\"", BackendKind::Reference},
           {"\"opencl\"", BackendKind::OpenCL}, {"{\"kind\": \"opencl\", \"device\": 1}", BackendKind::OpenCL}}) {
    const Scene s = parseOk(R"({"bodies": [{"mesh": {"box": {}}}], "backend": )" + text + "}");
    EXPECT_EQ(s.backend.kind, kind) << text;
  }
  EXPECT_EQ(parseOk(R"({"bodies": [{"mesh": {"box": {}}}], "backend": {"device": 1}})").backend.device, "1");
  const Scene qr = parseOk(test::kMinimalScene, {"solver.rotation=qr", "solver.precision=float"});
  EXPECT_EQ(qr.solver.rotation, RotationMethod::Qr);
  EXPECT_EQ(qr.solver.precision, Precision::Float);
  for (const auto& [text, kind] : std::vector<std::pair<std::string, PreconditionerKind>>{
           {"none", PreconditionerKind::None}, {"diagonal", PreconditionerKind::Diagonal},
           {"block_diagonal", PreconditionerKind::BlockDiagonal}, {"amg", PreconditionerKind::Amg},
           {"warped_cholesky", PreconditionerKind::WarpedCholesky}, {"auto", PreconditionerKind::Auto}})
    EXPECT_EQ(parseOk(test::kMinimalScene, {"solver.preconditioner=" + text}).solver.preconditioner, kind) << text;
  // Not given: "auto" (preconditionerOf chooses per body).
  EXPECT_EQ(parseOk(test::kMinimalScene).solver.preconditioner, PreconditionerKind::Auto);
  EXPECT_EQ(SolverDesc{}.preconditioner, PreconditionerKind::Auto);
  EXPECT_EQ(parseOk(R"({"bodies": [{"mesh": {"box": {}}}], "backend": "reference", "solver": {"preconditioner": "amg"}})")
                .solver.preconditioner,
            PreconditionerKind::Amg);
  // Integers may be written as integral floats (1e3).
  EXPECT_EQ(parseOk(test::kMinimalScene, {"solver.max_iterations=1e3"}).solver.maxIterations, 1000);
  EXPECT_EQ(parseOk(test::kMinimalScene, {"bodies.0.fixed=[{\"list\": [2.0, 1e1]}]"}).bodies[0].fixed[0].indices,
            (std::vector<std::uint32_t>{2, 10}));
}

TEST(SceneParse, CommentsAreAllowed) {
  const Scene s = parseOk("// a scene\n{\"bodies\": [{\"mesh\": {\"box\": {}}}] /* one body */}");
  EXPECT_EQ(s.bodies.size(), 1u);
}

TEST(SceneParse, ToStringNamesMatchTheJsonValues) {
  EXPECT_STREQ(toString(Formulation::Linear), "linear");
  EXPECT_STREQ(toString(Formulation::Corotational), "corotational");
  EXPECT_STREQ(toString(Formulation::StVenantKirchhoff), "stvk");
  EXPECT_STREQ(toString(Formulation::NeoHookean), "neo_hookean");
  EXPECT_STREQ(toString(RotationMethod::Polar), "polar");
  EXPECT_STREQ(toString(RotationMethod::Svd), "svd");
  EXPECT_STREQ(toString(RotationMethod::Quaternion), "quaternion");
  EXPECT_STREQ(toString(RotationMethod::Qr), "qr");
  EXPECT_STREQ(toString(BackendKind::Auto), "auto");
  EXPECT_STREQ(toString(BackendKind::Reference), "reference");
  EXPECT_STREQ(toString(BackendKind::OpenCL), "opencl");
  EXPECT_STREQ(toString(PreconditionerKind::None), "none");
  EXPECT_STREQ(toString(PreconditionerKind::Diagonal), "diagonal");
  EXPECT_STREQ(toString(PreconditionerKind::BlockDiagonal), "block_diagonal");
  EXPECT_STREQ(toString(PreconditionerKind::Amg), "amg");
  EXPECT_STREQ(toString(PreconditionerKind::Auto), "auto");
  // And each name parses back to the same value.
  for (Formulation f : {Formulation::Linear, Formulation::Corotational, Formulation::StVenantKirchhoff,
                        Formulation::NeoHookean})
    EXPECT_EQ(parseOk(test::kMinimalScene, {std::string("bodies.0.formulation=") + toString(f)}).bodies[0].formulation, f);
}

TEST(SceneParse, BaseDirIsKeptAsGiven) {
  const Result<Scene> s = parseScene(test::kMinimalScene, "some/folder");
  ASSERT_TRUE(s.isOk()) << s.message();
  EXPECT_EQ(s->baseDir, "some/folder");
}

TEST(LoadScene, NameDefaultsToTheFileStemAndBaseDirToItsFolder) {
  const auto dir = test::tempDir();
  const auto path = dir / "my_beam.json";
  std::ofstream(path) << test::kMinimalScene;
  Result<Scene> s = loadScene(path.string());
  ASSERT_TRUE(s.isOk()) << s.message();
  EXPECT_EQ(s->name, "my_beam");
  EXPECT_EQ(std::filesystem::path(s->baseDir), dir);

  std::ofstream(dir / "named.json") << R"({"name": "given", "bodies": [{"mesh": {"box": {}}}]})";
  Result<Scene> named = loadScene((dir / "named.json").string());
  ASSERT_TRUE(named.isOk()) << named.message();
  EXPECT_EQ(named->name, "given");
  Result<Scene> overridden = loadScene(path.string(), {"name=from_set"});
  ASSERT_TRUE(overridden.isOk()) << overridden.message();
  EXPECT_EQ(overridden->name, "from_set");
}

TEST(LoadScene, MissingFileIsIoErrorNamingThePath) {
  const Result<Scene> s = loadScene("/nonexistent/dir/scene.json");
  ASSERT_FALSE(s.isOk());
  EXPECT_EQ(s.status().code(), ErrorCode::IoError);
  EXPECT_NE(s.message().find("/nonexistent/dir/scene.json"), std::string::npos) << s.message();
}

TEST(LoadScene, ErrorsFromAFileBeginWithItsPath) {
  const auto path = test::tempDir() / "bad.json";
  std::ofstream(path) << R"({"bodies": [{"mesh": {"box": {}}, "materail": {}}]})";
  const Result<Scene> s = loadScene(path.string());
  ASSERT_FALSE(s.isOk());
  EXPECT_EQ(s.status().code(), ErrorCode::BadInput);
  EXPECT_EQ(s.message(), path.string() + ": bodies[0].materail: unknown key; did you mean \"material\"?");
}

TEST(LoadScene, SyntaxErrorInAFileGivesPathLineAndColumn) {
  const auto path = test::tempDir() / "syntax.json";
  std::ofstream(path) << "{\n  \"bodies\": [\n    {\"mesh\": {\"box\": {}},}\n  ]\n}\n";
  const Result<Scene> s = loadScene(path.string());
  ASSERT_FALSE(s.isOk());
  EXPECT_EQ(s.status().code(), ErrorCode::BadInput);
  EXPECT_EQ(s.message().rfind(path.string() + ": line 3, column ", 0), 0u) << s.message();
}

}  // namespace
}  // namespace corofem
