// `--set key.path=value` overrides: applied before validation, with array indices, bare strings,
// JSON values, created objects, and errors that name the override.
#include "scene/scene_test_util.hpp"

#include <corofem/scene.hpp>

#include <gtest/gtest.h>

namespace corofem {
namespace {

using test::overrideError;
using test::parseOk;

const char* kTwoBodies = R"({
  "bodies": [
    {"name": "a", "mesh": {"box": {}}, "loads": [{"type": "gravity"}, {"type": "force", "vector": [0, 0, 1], "nodes": {"list": [0]}}]},
    {"name": "b", "mesh": "b.msh", "material": {"density": 500}}
  ],
  "backend": "reference",
  "analysis": {"type": "dynamic", "steps": 10}
})";

TEST(SceneOverrides, NumbersBooleansAndNestedKeys) {
  const Scene s = parseOk(kTwoBodies, {"analysis.steps=25", "analysis.time_step=0.002", "output.vtk=false",
                                       "output.vtk_every=3", "bodies.1.material.youngs_modulus=1e6"});
  EXPECT_EQ(s.analysis.dynamics.steps, 25);
  EXPECT_EQ(s.analysis.dynamics.timeStep, 0.002);
  EXPECT_FALSE(s.output.vtk);  // "output" was absent: the object is created
  EXPECT_EQ(s.output.vtkEvery, 3);
  EXPECT_EQ(s.bodies[1].material.youngsModulus, 1e6);
  EXPECT_EQ(s.bodies[1].material.density, 500);  // untouched siblings stay
  EXPECT_EQ(s.bodies[0].material.youngsModulus, MaterialDesc{}.youngsModulus);
}

TEST(SceneOverrides, ArrayIndicesInDotAndBracketForm) {
  const Scene s = parseOk(kTwoBodies, {"bodies.0.loads.1.vector=[1, 2, 3]", "bodies[0].loads[0].vector=[0,0,-1]",
                                       "bodies[1].name=renamed", "bodies.0.loads.1.nodes.list.0=7"});
  EXPECT_EQ(s.bodies[0].loads[1].vector, (Vec3{1, 2, 3}));
  EXPECT_EQ(s.bodies[0].loads[0].vector, (Vec3{0, 0, -1}));
  EXPECT_EQ(s.bodies[0].loads[1].nodes.indices, (std::vector<std::uint32_t>{7}));
  EXPECT_EQ(s.bodies[1].name, "renamed");
}

TEST(SceneOverrides, BareWordsAreStringsAndQuotedStringsToo) {
  const Scene s = parseOk(kTwoBodies, {"analysis.integrator=backward_euler", "bodies.0.formulation=\"linear\"",
                                       "bodies.1.surface=meshes/b surface.obj"});
  EXPECT_EQ(s.analysis.dynamics.integrator, Integrator::BackwardEuler);
  EXPECT_EQ(s.bodies[0].formulation, Formulation::Linear);
  EXPECT_EQ(s.bodies[1].surface, "meshes/b surface.obj");
}

TEST(SceneOverrides, ObjectsReplaceWholeSections) {
  const Scene s = parseOk(kTwoBodies, {R"(analysis={"type": "static", "increments": 3})"});
  EXPECT_EQ(s.analysis.kind, AnalysisDesc::Kind::Static);
  EXPECT_EQ(s.analysis.statics.increments, 3);
}

TEST(SceneOverrides, ShorthandsCanBeReachedThroughTheirLongForm) {
  // "backend": "reference" and "mesh": "b.msh" are expanded before overrides are applied.
  const Scene s = parseOk(kTwoBodies, {"backend.device=2", "bodies.1.mesh.scale=0.001"});
  EXPECT_EQ(s.backend.kind, BackendKind::Reference);
  EXPECT_EQ(s.backend.device, "2");
  EXPECT_EQ(s.bodies[1].mesh.file, "b.msh");
  EXPECT_EQ(s.bodies[1].mesh.scale, 0.001);
}

TEST(SceneOverrides, AppliedInOrderSoTheLastWins) {
  const Scene s = parseOk(kTwoBodies, {"analysis.steps=5", "analysis.steps=6"});
  EXPECT_EQ(s.analysis.dynamics.steps, 6);
}

TEST(SceneOverrides, SpacesAroundThePathAreIgnored) {
  EXPECT_EQ(parseOk(kTwoBodies, {" analysis.steps =9"}).analysis.dynamics.steps, 9);
}

TEST(SceneOverrides, UnknownKeyAfterApplicationSuggestsTheNearest) {
  EXPECT_EQ(overrideError({"bodies.0.material.youngs_modulus_=1e5"}),
            "bodies[0].material.youngs_modulus_: unknown key; did you mean \"youngs_modulus\"?");
  EXPECT_EQ(overrideError({"outptu.vtk=false"}), "outptu: unknown key; did you mean \"output\"?");
  EXPECT_EQ(overrideError({"analysis.time_stpe=0.1"}), "analysis.time_stpe: unknown key; did you mean \"time_step\"?");
}

TEST(SceneOverrides, IndexOutOfRangeNamesTheOverride) {
  EXPECT_EQ(overrideError({"bodies.3.name=x"}), "--set \"bodies.3.name=x\": index 3 is out of range: bodies has 1 element");
  EXPECT_EQ(overrideError({"bodies.99999999999.name=x"}),
            "--set \"bodies.99999999999.name=x\": index 99999999999 is out of range: bodies has 1 element");
  EXPECT_EQ(test::parseError(kTwoBodies, {"bodies.0.loads.2.vector=[0,0,1]"}),
            "--set \"bodies.0.loads.2.vector=[0,0,1]\": index 2 is out of range: bodies[0].loads has 2 elements");
  EXPECT_EQ(overrideError({"bodies.0.fixed.0.list=[1]"}),
            "--set \"bodies.0.fixed.0.list=[1]\": index 0 is out of range: bodies[0].fixed is absent");
}

TEST(SceneOverrides, MalformedOverrides) {
  EXPECT_EQ(overrideError({"analysis.steps"}), "--set \"analysis.steps\": expected key.path=value (no '=' found)");
  EXPECT_EQ(overrideError({"=5"}), "--set \"=5\": the key path before '=' is empty");
  EXPECT_EQ(overrideError({"analysis..steps=5"}),
            "--set \"analysis..steps=5\": empty segment in the key path \"analysis..steps\" (two dots, or a leading dot)");
  EXPECT_EQ(overrideError({"bodies.name=x"}),
            "--set \"bodies.name=x\": bodies is an array: the next segment must be a numeric index (e.g. bodies.0), "
            "not \"name\"");
  // Objects created along a path are then checked like any other value.
  EXPECT_EQ(overrideError({"bodies.0.mesh.box.cells.x=1"}),
            "bodies[0].mesh.box.cells: expected an array of exactly 3 integers (cells along x, y, z), got an object");
}

TEST(SceneOverrides, CannotDescendIntoAScalar) {
  EXPECT_EQ(test::parseError(kTwoBodies, {"analysis.steps.value=3"}),
            "--set \"analysis.steps.value=3\": cannot go into analysis.steps, which is a number, to set \"value\"");
  EXPECT_EQ(test::parseError(kTwoBodies, {"bodies[0].material[0]=3"}),
            "--set \"bodies[0].material[0]=3\": index 0 is out of range: bodies[0].material is absent");
}

TEST(SceneOverrides, ErrorsFromAFileNameTheFileFirst) {
  // loadScene's prefix is the file; for parseScene there is none. Checked through the public API.
  const Result<Scene> s = parseScene(kTwoBodies, "", {"bodies.9.name=x"});
  ASSERT_FALSE(s.isOk());
  EXPECT_EQ(s.status().code(), ErrorCode::BadInput);
  EXPECT_EQ(s.message().rfind("--set \"bodies.9.name=x\"", 0), 0u) << s.message();
}

}  // namespace
}  // namespace corofem
