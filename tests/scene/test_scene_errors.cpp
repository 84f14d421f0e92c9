// Every way a scene can be wrong gives ErrorCode::BadInput with the key's full path and a message
// a user can act on. The messages are checked in full where their wording is the contract.
#include "scene/scene_test_util.hpp"

#include <corofem/scene.hpp>

#include <gtest/gtest.h>

#include <cctype>

namespace corofem {
namespace {

using test::overrideError;
using test::parseError;

#define EXPECT_CONTAINS(haystack, needle) \
  EXPECT_NE(std::string(haystack).find(needle), std::string::npos) << "message: " << (haystack)

// ------------------------------------------------------------------ unknown keys
TEST(SceneErrors, UnknownKeySuggestsTheNearest) {
  EXPECT_EQ(parseError(R"({"bodies": [{"mesh": {"box": {}}, "materail": {}}]})"),
            "bodies[0].materail: unknown key; did you mean \"material\"?");
  EXPECT_EQ(parseError(R"({"bodies": [{"mesh": {"box": {}}}], "anaysis": {}})"),
            "anaysis: unknown key; did you mean \"analysis\"?");
  EXPECT_EQ(parseError(R"({"bodies": [{"mesh": {"box": {}}, "material": {"youngs_modulos": 1}}]})"),
            "bodies[0].material.youngs_modulos: unknown key; did you mean \"youngs_modulus\"?");
  EXPECT_EQ(parseError(R"({"bodies": [{"mesh": {"box": {"cell": [1, 1, 1]}}}]})"),
            "bodies[0].mesh.box.cell: unknown key; did you mean \"cells\"?");
  EXPECT_EQ(parseError(R"({"bodies": [{"mesh": {"box": {}}}], "solver": {"Tolerance": 1}})"),
            "solver.Tolerance: unknown key; did you mean \"tolerance\"?");
}

TEST(SceneErrors, UnknownKeyFarFromAnyListsTheValidKeys) {
  EXPECT_EQ(parseError(R"({"bodies": [{"mesh": {"box": {}}}], "output": {"zzzzzz": 1}})"),
            "output.zzzzzz: unknown key; the keys allowed here are \"probes\", \"vtk\", \"vtk_every\", "
            "\"surface_obj\", \"vtu_format\" and \"vtu_compression\"");
}

TEST(SceneErrors, KeyOfTheOtherAnalysisTypeSaysSo) {
  EXPECT_EQ(parseError(R"({"bodies": [{"mesh": {"box": {}}}], "analysis": {"type": "static", "time_step": 0.1}})"),
            "analysis.time_step: belongs to a dynamic analysis, but the analysis type is \"static\"; remove it or "
            "set \"type\": \"dynamic\"");
  EXPECT_CONTAINS(parseError(R"({"bodies": [{"mesh": {"box": {}}}], "analysis": {"increments": 2}})"),
                  "analysis.increments: belongs to a static analysis, but the analysis type is \"dynamic\" (the default)");
}

TEST(SceneErrors, GravityTakesNoNodes) {
  EXPECT_CONTAINS(parseError(R"({"bodies": [{"mesh": {"box": {}}, "loads": [{"type": "gravity", "nodes": {"list": [0]}}]}]})"),
                  "bodies[0].loads[0].nodes: only force and displacement loads take \"nodes\"");
}

TEST(SceneErrors, SurfaceLayoutNeedsASurfaceAndAKnownLayout) {
  EXPECT_EQ(parseError(R"({"bodies": [{"mesh": {"box": {}}, "surface_layout": "separate"}]})"),
            "bodies[0].surface_layout: lays out a render surface, but the body has none; add \"surface\": "
            "\"file.obj\" or remove \"surface_layout\"");
  EXPECT_EQ(parseError(R"({"bodies": [{"mesh": {"box": {}}, "surface": "s.obj", "surface_layout": "split"}]})"),
            "bodies[0].surface_layout: unknown value \"split\"; valid values are \"interleaved\" or \"separate\"");
}

TEST(SceneErrors, VtuFormatAndCompressionValues) {
  EXPECT_EQ(parseError(R"({"bodies": [{"mesh": {"box": {}}}], "output": {"vtu_format": "binary"}})"),
            "output.vtu_format: unknown value \"binary\"; valid values are \"ascii\", \"base64\" or \"raw\"");
  EXPECT_EQ(parseError(R"({"bodies": [{"mesh": {"box": {}}}], "output": {"vtu_compression": "zlip"}})"),
            "output.vtu_compression: unknown value \"zlip\"; did you mean \"zlib\"? (valid: \"none\" or \"zlib\")");
}

TEST(SceneErrors, VtuCompressionNeedsABinaryFormat) {
  EXPECT_EQ(parseError(R"({"bodies": [{"mesh": {"box": {}}}], "output": {"vtu_compression": "zlib"}})"),
            "output.vtu_compression: \"zlib\" compresses binary arrays only, and vtu_format is \"ascii\" (the "
            "default); set vtu_format to \"base64\" or \"raw\", or use \"none\"");
  EXPECT_EQ(parseError(R"({"bodies": [{"mesh": {"box": {}}}], "output": {"vtu_format": "ascii", "vtu_compression": "zlib"}})"),
            "output.vtu_compression: \"zlib\" compresses binary arrays only, and vtu_format is \"ascii\"; set "
            "vtu_format to \"base64\" or \"raw\", or use \"none\"");
}

TEST(SceneErrors, VtuCompressionZlibInABuildWithoutZlib) {
  if (vtuZlibAvailable()) GTEST_SKIP() << "this build has zlib; the refusal is for builds without it";
  EXPECT_EQ(parseError(R"({"bodies": [{"mesh": {"box": {}}}], "output": {"vtu_format": "raw", "vtu_compression": "zlib"}})"),
            "output.vtu_compression: \"zlib\" needs a corofem built with zlib, and this one was built without it; "
            "install zlib1g-dev and rebuild, or use \"none\"");
}

TEST(SceneErrors, DuplicateKeyIsReportedWithItsPath) {
  EXPECT_EQ(parseError(R"({"bodies": [{"mesh": {"box": {}}}, {"mesh": {"box": {}}, "name": "a", "name": "b"}]})"),
            "bodies[1].name: duplicate key (the same key appears twice in one object)");
}

// ------------------------------------------------------------------ wrong types
TEST(SceneErrors, WrongTypeNamesExpectedAndGot) {
  EXPECT_EQ(parseError(R"({"bodies": [{"mesh": {"box": {}}, "material": {"density": "heavy"}}]})"),
            "bodies[0].material.density: expected a number, got the string \"heavy\"");
  EXPECT_EQ(overrideError({"output.vtk=1"}), "output.vtk: expected true or false, got the number 1");
  EXPECT_EQ(overrideError({"bodies.0.name=[1]"}), "bodies[0].name: expected a string, got an array of 1 element");
  EXPECT_EQ(overrideError({"analysis.steps=2.5"}), "analysis.steps: expected an integer, got 2.5");
  EXPECT_EQ(overrideError({"bodies.0.material=5"}),
            "bodies[0].material: expected an object {\"youngs_modulus\": E, \"poisson_ratio\": nu, \"density\": rho, "
            "...}, got the number 5");
  EXPECT_EQ(parseError(R"({"bodies": {"mesh": {"box": {}}}})"), "bodies: expected an array of bodies, got an object");
  EXPECT_EQ(parseError("[1, 2]"), "top level: expected a JSON object {\"bodies\": [...], ...}, got an array of 2 elements");
  EXPECT_EQ(overrideError({"bodies.0.fixed={\"list\": [0]}"}),
            "bodies[0].fixed: expected an array of node sets, e.g. [{\"plane\": {...}}], got an object");
  EXPECT_EQ(overrideError({"solver.rotation=null"}),
            "solver.rotation: expected one of \"polar\", \"svd\", \"quaternion\" or \"qr\", got null");
}

TEST(SceneErrors, VectorsNeedExactlyThreeFiniteNumbers) {
  EXPECT_EQ(overrideError({"bodies.0.initial_velocity=[1, 2]"}),
            "bodies[0].initial_velocity: expected an array of exactly 3 numbers, got an array of 2 elements");
  EXPECT_EQ(overrideError({"bodies.0.initial_velocity=[1, 2, 3, 4]"}),
            "bodies[0].initial_velocity: expected an array of exactly 3 numbers, got an array of 4 elements");
  EXPECT_EQ(overrideError({"bodies.0.mesh.translate=[1, \"x\", 3]"}),
            "bodies[0].mesh.translate[1]: expected a number, got the string \"x\"");
  EXPECT_EQ(overrideError({"bodies.0.mesh.translate=5"}),
            "bodies[0].mesh.translate: expected an array of exactly 3 numbers, got the number 5");
}

TEST(SceneErrors, NonFiniteNumbersAreRejected) {
  // JSON has no NaN or Inf; the ways they arrive are an overflowing literal and a bare word.
  EXPECT_EQ(parseError("{\"bodies\": [{\"mesh\": {\"box\": {}},\n \"material\": {\"density\": 1e999}}]}"),
            "line 2, column 26: the number 1e999 is too large (numbers must be finite)");
  EXPECT_EQ(overrideError({"bodies.0.material.density=nan"}),
            "bodies[0].material.density: expected a number, got the string \"nan\"");
  EXPECT_EQ(overrideError({"bodies.0.material.density=inf"}),
            "bodies[0].material.density: expected a number, got the string \"inf\"");
}

// ------------------------------------------------------------------ ranges, one per ranged field
struct RangeCase {
  std::vector<std::string> overrides;
  std::string message;
};

void PrintTo(const RangeCase& c, std::ostream* os) {
  for (const std::string& o : c.overrides) *os << o << ' ';
}

/// The test's name: its index and the overrides, with every other character as '_'.
std::string rangeName(const ::testing::TestParamInfo<RangeCase>& info) {
  std::string name = std::to_string(info.index);
  for (const std::string& o : info.param.overrides)
    for (char c : "_" + o) name += std::isalnum(static_cast<unsigned char>(c)) ? c : '_';
  return name;
}

class SceneRangeErrors : public ::testing::TestWithParam<RangeCase> {};

TEST_P(SceneRangeErrors, OutOfRangeNamesTheConditionAndThePath) {
  EXPECT_EQ(overrideError(GetParam().overrides), GetParam().message);
}

const std::string kStatic = "analysis.type=static";

INSTANTIATE_TEST_SUITE_P(
    EveryRangedField, SceneRangeErrors,
    ::testing::Values(
        RangeCase{{"bodies.0.material.youngs_modulus=0"},
                  "bodies[0].material.youngs_modulus: 0 is out of range: must satisfy E > 0"},
        RangeCase{{"bodies.0.material.youngs_modulus=-1e5"},
                  "bodies[0].material.youngs_modulus: -100000 is out of range: must satisfy E > 0"},
        RangeCase{{"bodies.0.material.poisson_ratio=0.5"},
                  "bodies[0].material.poisson_ratio: 0.5 is out of range: must satisfy -1 < nu < 0.5"},
        RangeCase{{"bodies.0.material.poisson_ratio=-1"},
                  "bodies[0].material.poisson_ratio: -1 is out of range: must satisfy -1 < nu < 0.5"},
        RangeCase{{"bodies.0.material.density=0"},
                  "bodies[0].material.density: 0 is out of range: must satisfy rho > 0"},
        RangeCase{{"bodies.0.material.rayleigh_mass=-0.1"},
                  "bodies[0].material.rayleigh_mass: -0.1 is out of range: must satisfy alpha >= 0"},
        RangeCase{{"bodies.0.material.rayleigh_stiffness=-1e-3"},
                  "bodies[0].material.rayleigh_stiffness: -0.001 is out of range: must satisfy beta >= 0"},
        RangeCase{{"bodies.0.mesh.scale=0"}, "bodies[0].mesh.scale: 0 is out of range: must satisfy scale > 0"},
        RangeCase{{"bodies.0.mesh.box.cells=[1, 0, 1]"},
                  "bodies[0].mesh.box.cells[1]: 0 is out of range: must satisfy cells >= 1"},
        RangeCase{{"bodies.0.mesh.box.tets_per_cell=4"},
                  "bodies[0].mesh.box.tets_per_cell: 4 is out of range: must satisfy tets_per_cell = 5 or 6"},
        RangeCase{{"bodies.0.mesh.box.max=[1, 0, 1]"},
                  "bodies[0].mesh.box.max: max[1] = 0 must exceed min[1] = 0"},
        RangeCase{{"bodies.0.loads=[{\"type\": \"gravity\", \"ramp_time\": -1}]"},
                  "bodies[0].loads[0].ramp_time: -1 is out of range: must satisfy ramp_time >= 0"},
        RangeCase{{"bodies.0.fixed=[{\"plane\": {\"point\": [0,0,0], \"normal\": [0,0,1], \"tolerance\": -1e-9}}]"},
                  "bodies[0].fixed[0].plane.tolerance: -1e-09 is out of range: must satisfy tolerance >= 0"},
        RangeCase{{kStatic, "analysis.increments=0"},
                  "analysis.increments: 0 is out of range: must satisfy increments >= 1"},
        RangeCase{{kStatic, "analysis.max_newton_iterations=0"},
                  "analysis.max_newton_iterations: 0 is out of range: must satisfy max_newton_iterations >= 1"},
        RangeCase{{kStatic, "analysis.residual_tolerance=0"},
                  "analysis.residual_tolerance: 0 is out of range: must satisfy residual_tolerance > 0"},
        RangeCase{{kStatic, "analysis.displacement_tolerance=-1"},
                  "analysis.displacement_tolerance: -1 is out of range: must satisfy displacement_tolerance > 0"},
        RangeCase{{"analysis.time_step=0"}, "analysis.time_step: 0 is out of range: must satisfy time_step > 0"},
        RangeCase{{"analysis.steps=-1"}, "analysis.steps: -1 is out of range: must satisfy steps >= 1, or 0 for an open-ended analysis"},
        RangeCase{{"analysis.newmark_beta=0"},
                  "analysis.newmark_beta: 0 is out of range: must satisfy 0 < beta <= 0.5"},
        RangeCase{{"analysis.newmark_beta=0.51"},
                  "analysis.newmark_beta: 0.51 is out of range: must satisfy 0 < beta <= 0.5"},
        RangeCase{{"analysis.newmark_gamma=0.49"},
                  "analysis.newmark_gamma: 0.49 is out of range: must satisfy 0.5 <= gamma <= 1"},
        RangeCase{{"analysis.newmark_gamma=1.5"},
                  "analysis.newmark_gamma: 1.5 is out of range: must satisfy 0.5 <= gamma <= 1"},
        RangeCase{{"analysis.newton_iterations=0"},
                  "analysis.newton_iterations: 0 is out of range: must satisfy newton_iterations >= 1"},
        RangeCase{{"analysis.newton_tolerance=0"},
                  "analysis.newton_tolerance: 0 is out of range: must satisfy newton_tolerance > 0"},
        RangeCase{{"solver.tolerance=0"}, "solver.tolerance: 0 is out of range: must satisfy tolerance > 0"},
        RangeCase{{"solver.max_iterations=0"},
                  "solver.max_iterations: 0 is out of range: must satisfy max_iterations >= 1"},
        RangeCase{{"solver.check_every=-2"}, "solver.check_every: -2 is out of range: must satisfy check_every >= 1"},
        RangeCase{{"output.vtk_every=-1"}, "output.vtk_every: -1 is out of range: must satisfy vtk_every >= 0"},
        RangeCase{{"analysis.steps=3e9"}, "analysis.steps: 3000000000 is out of range: must be at most 2147483647"}),
    rangeName);

TEST(SceneErrors, BoundaryValuesInsideTheRangesAreAccepted) {
  // The closed ends of the ranges: beta = 0.5, gamma = 0.5 and 1, damping = 0, vtk_every = 0.
  const Result<Scene> s = parseScene(test::kMinimalScene, "",
                                     {"analysis.newmark_beta=0.5", "analysis.newmark_gamma=1",
                                      "bodies.0.material.rayleigh_mass=0", "output.vtk_every=0",
                                      "bodies.0.material.poisson_ratio=-0.999"});
  EXPECT_TRUE(s.isOk()) << s.message();
}

// ------------------------------------------------------------------ enumerations
TEST(SceneErrors, BadEnumValueSuggestsTheNearest) {
  EXPECT_EQ(overrideError({"bodies.0.formulation=corotatonal"}),
            "bodies[0].formulation: unknown value \"corotatonal\"; did you mean \"corotational\"? (valid: "
            "\"linear\", \"corotational\", \"stvk\" or \"neo_hookean\")");
  EXPECT_EQ(overrideError({"analysis.integrator=backward-euler"}),
            "analysis.integrator: unknown value \"backward-euler\"; did you mean \"backward_euler\"? (valid: "
            "\"newmark\", \"backward_euler\" or \"auto\")");
  EXPECT_EQ(overrideError({"backend=OpenCL"}),
            "backend: unknown value \"OpenCL\"; did you mean \"opencl\"? (valid: \"auto\", \"reference\", \"opencl\" or \"vulkan\")");
  EXPECT_CONTAINS(overrideError({"solver.preconditioner=jacobi"}),
                  "solver.preconditioner: unknown value \"jacobi\"; valid values are \"none\", \"diagonal\", "
                  "\"block_diagonal\", \"amg\", \"warped_cholesky\" or \"auto\"");
  EXPECT_CONTAINS(overrideError({"solver.rotation=polr"}), "did you mean \"polar\"?");
  EXPECT_CONTAINS(overrideError({"solver.precision=single"}), "solver.precision: unknown value \"single\"");
  EXPECT_CONTAINS(overrideError({"solver.linear_solver=cg"}), "did you mean \"pcg\"?");
  EXPECT_CONTAINS(overrideError({"analysis.type=statc"}), "analysis.type: unknown value \"statc\"; did you mean \"static\"?");
  EXPECT_CONTAINS(overrideError({"bodies.0.loads=[{\"type\": \"gravty\"}]"}),
                  "bodies[0].loads[0].type: unknown value \"gravty\"; did you mean \"gravity\"?");
}

// ------------------------------------------------------------------ required keys, exclusive choices
TEST(SceneErrors, MissingRequiredKeys) {
  EXPECT_EQ(parseError("{}"),
            "bodies: required key is missing; a scene needs at least one body: \"bodies\": [{\"mesh\": {...}}]");
  EXPECT_EQ(parseError(R"({"bodies": []})"), "bodies: must contain at least one body");
  EXPECT_EQ(parseError(R"({"bodies": [{"name": "x"}]})"),
            "bodies[0].mesh: required key is missing; give {\"file\": \"mesh.msh\"} or {\"box\": {...}}");
  EXPECT_EQ(overrideError({"bodies.0.loads=[{\"vector\": [0, 0, 1]}]"}),
            "bodies[0].loads[0].type: required key is missing; one of \"gravity\", \"force\" or \"displacement\"");
  EXPECT_EQ(overrideError({"bodies.0.loads=[{\"type\": \"force\", \"vector\": [0, 0, 1]}]"}),
            "bodies[0].loads[0].nodes: required key is missing; the node set the force acts on");
  EXPECT_EQ(overrideError({"bodies.0.loads=[{\"type\": \"displacement\", \"nodes\": {\"list\": [0]}}]"}),
            "bodies[0].loads[0].vector: required key is missing; the prescribed displacement [ux, uy, uz] in m");
  EXPECT_EQ(overrideError({"output.probes=[{\"name\": \"tip\"}]"}),
            "output.probes[0].nodes: required key is missing; the node set whose mean displacement is recorded");
  EXPECT_EQ(overrideError({"bodies.0.fixed=[{\"plane\": {\"normal\": [1, 0, 0]}}]"}),
            "bodies[0].fixed[0].plane.point: required key is missing; a point on the plane [x, y, z]");
}

TEST(SceneErrors, MeshNeedsExactlyOneOfFileAndBox) {
  EXPECT_EQ(parseError(R"({"bodies": [{"mesh": {"file": "a.msh", "box": {}}}]})"),
            "bodies[0].mesh: has both \"file\" and \"box\"; give exactly one");
  EXPECT_EQ(parseError(R"({"bodies": [{"mesh": {"scale": 2}}]})"),
            "bodies[0].mesh: needs exactly one of \"file\" (a mesh file) or \"box\" (a generated box)");
  EXPECT_EQ(parseError(R"({"bodies": [{"mesh": {"file": ""}}]})"), "bodies[0].mesh.file: must not be empty");
}

// ------------------------------------------------------------------ node sets
TEST(SceneErrors, BadNodeSets) {
  const auto fixed = [](const std::string& set) { return overrideError({"bodies.0.fixed=[" + set + "]"}); };
  EXPECT_EQ(fixed(R"({"box": {"min": [0,0,0], "max": [1,1,1]}, "plane": {}})"),
            "bodies[0].fixed[0]: has \"box\" and \"plane\"; a node set is exactly one of \"box\", \"plane\", "
            "\"list\" or \"bou\"");
  EXPECT_EQ(fixed("{}"),
            "bodies[0].fixed[0]: empty node set; give exactly one of \"box\", \"plane\", \"list\" or \"bou\"");
  EXPECT_EQ(fixed(R"({"plain": {}})"), "bodies[0].fixed[0].plain: unknown key; did you mean \"plane\"?");
  EXPECT_EQ(fixed(R"({"list": [0, -3]})"),
            "bodies[0].fixed[0].list[1]: -3 is out of range: node indices are 0-based, >= 0");
  EXPECT_EQ(fixed(R"({"list": [0, 1.5]})"),
            "bodies[0].fixed[0].list[1]: expected a 0-based node index (an integer >= 0), got the number 1.5");
  EXPECT_EQ(fixed(R"({"list": []})"), "bodies[0].fixed[0].list: must not be empty");
  EXPECT_EQ(fixed(R"({"plane": {"point": [0,0,0], "normal": [0,0,0]}})"),
            "bodies[0].fixed[0].plane.normal: must be non-zero");
  EXPECT_EQ(fixed(R"({"box": {"min": [0,0,0], "max": [1,-1,1]}})"),
            "bodies[0].fixed[0].box.max: max[1] = -1 is below min[1] = 0; the box would select nothing");
  EXPECT_EQ(fixed(R"({"box": {"min": [0,0,0]}})"),
            "bodies[0].fixed[0].box.max: required key is missing; the upper corner [x, y, z]");
  EXPECT_EQ(fixed(R"({"bou": 3})"), "bodies[0].fixed[0].bou: expected a string, got the number 3");
  EXPECT_EQ(fixed("\"left\""),
            "bodies[0].fixed[0]: expected a node set: {\"box\": {...}}, {\"plane\": {...}}, {\"list\": [...]} or "
            "{\"bou\": \"file.bou\"}, got the string \"left\"");
}

// ------------------------------------------------------------------ cross-section checks
TEST(SceneErrors, NamesMustBeUniqueAndProbesMustNameABody) {
  EXPECT_EQ(parseError(R"({"bodies": [{"name": "a", "mesh": {"box": {}}}, {"name": "a", "mesh": {"box": {}}}]})"),
            "bodies[1].name: \"a\" is already the name of another body; body names must be unique");
  EXPECT_EQ(overrideError({"bodies.0.name=beam", "output.probes=[{\"body\": \"bam\", \"nodes\": {\"list\": [0]}}]"}),
            "output.probes[0].body: no body is named \"bam\"; did you mean \"beam\"?");
  EXPECT_EQ(overrideError({"output.probes=[{\"name\": \"p\", \"nodes\": {\"list\": [0]}}, {\"name\": \"p\", "
                           "\"nodes\": {\"list\": [1]}}]"}),
            "output.probes[1].name: \"p\" is already the name of another probe; probe names must be unique");
}

TEST(SceneErrors, ReferenceOnlyFeaturesOnOpenClAreRejected) {
  EXPECT_EQ(overrideError({"backend=opencl", "solver.linear_solver=cholesky"}),
            "solver.linear_solver: \"cholesky\" runs only on the reference backend, and the backend is \"opencl\"; "
            "use \"pcg\", or the backend \"reference\"");
  EXPECT_CONTAINS(overrideError({"backend.kind=opencl", "bodies.0.formulation=neo_hookean"}),
                  "bodies[0].formulation: \"neo_hookean\" runs only on the reference backend");
  EXPECT_EQ(overrideError({"backend=vulkan", "solver.preconditioner=warped_cholesky"}),
            "solver.preconditioner: \"warped_cholesky\" runs on the reference and opencl backends, and the backend is "
            "\"vulkan\"; use \"amg\", or the backend \"reference\" or \"opencl\"");
  EXPECT_TRUE(parseScene(test::kMinimalScene, "", {"backend=reference", "solver.preconditioner=warped_cholesky"}).isOk());
  EXPECT_TRUE(parseScene(test::kMinimalScene, "", {"backend=opencl", "solver.preconditioner=warped_cholesky"}).isOk());
  // "amg" runs on both backends.
  EXPECT_TRUE(parseScene(test::kMinimalScene, "", {"backend=opencl", "solver.preconditioner=amg"}).isOk());
  // On "auto" the choice is left to the backend selection (tests/schedule/test_scheduler.cpp).
  EXPECT_TRUE(parseScene(test::kMinimalScene, "", {"solver.linear_solver=cholesky"}).isOk());
  EXPECT_TRUE(parseScene(test::kMinimalScene, "", {"solver.preconditioner=amg"}).isOk());
  EXPECT_TRUE(parseScene(test::kMinimalScene, "", {"backend=reference", "solver.preconditioner=amg"}).isOk());
}

// ------------------------------------------------------------------ JSON syntax
TEST(SceneErrors, SyntaxErrorGivesLineAndColumn) {
  const std::string message = parseError("{\n  \"bodies\": [\n    {\"mesh\": {\"box\": {}}}\n  ],\n  \"name\" \"x\"\n}");
  // The column is that of the last character read (the end of the unexpected token "x").
  EXPECT_EQ(message, "line 5, column 12: invalid JSON: syntax error while parsing object separator - unexpected "
                     "string literal; expected ':'");
  EXPECT_CONTAINS(parseError(""), "line 1, column 1: invalid JSON");
  // nlohmann reports the column of the last character read: the end of the bad token "tra".
  EXPECT_CONTAINS(parseError("{\"bodies\": [] } trailing"), "line 1, column 19: invalid JSON");
}

}  // namespace
}  // namespace corofem
