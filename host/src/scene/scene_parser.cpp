// The JSON scene format (docs/scene-format.md): parse, apply --set overrides, validate, and fill
// the Scene structs. Every error is ErrorCode::BadInput and names the key's full path
// (`bodies[0].material.poisson_ratio`), with the nearest valid name for a misspelt key or value.
#include <corofem/scene.hpp>

#include "mesh/input_file.hpp"
#include "mesh/mesh_validation.hpp"
#include "scene/json_path.hpp"
#include "scene/json_text.hpp"
#include "scene/overrides.hpp"
#include "scene/scene_paths.hpp"
#include "util/error.hpp"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <limits>
#include <set>
#include <utility>

namespace corofem {

namespace {

using nlohmann::json;
using scene::childPath;
using scene::formatNumber;
using scene::indexPath;
using scene::nearestName;
using scene::quotedList;

template <class E>
using Choices = std::vector<std::pair<std::string, E>>;

/// A valid range of a number: ok(x) and the condition shown when it fails ("-1 < nu < 0.5").
struct Range {
  bool (*ok)(double) = nullptr;
  const char* condition = nullptr;
};

// ------------------------------------------------------------------ names of the enumerations
const Choices<Formulation> kFormulations{{"linear", Formulation::Linear},
                                         {"corotational", Formulation::Corotational},
                                         {"stvk", Formulation::StVenantKirchhoff},
                                         {"neo_hookean", Formulation::NeoHookean}};
const Choices<RotationMethod> kRotations{{"polar", RotationMethod::Polar},
                                         {"svd", RotationMethod::Svd},
                                         {"quaternion", RotationMethod::Quaternion},
                                         {"qr", RotationMethod::Qr}};
const Choices<BackendKind> kBackends{
    {"auto", BackendKind::Auto}, {"reference", BackendKind::Reference}, {"opencl", BackendKind::OpenCL},
    {"vulkan", BackendKind::Vulkan}};
const Choices<LinearSolverKind> kLinearSolvers{{"pcg", LinearSolverKind::Pcg},
                                               {"cholesky", LinearSolverKind::Cholesky}};
const Choices<PreconditionerKind> kPreconditioners{{"none", PreconditionerKind::None},
                                                   {"diagonal", PreconditionerKind::Diagonal},
                                                   {"block_diagonal", PreconditionerKind::BlockDiagonal},
                                                   {"amg", PreconditionerKind::Amg},
                                                   {"warped_cholesky", PreconditionerKind::WarpedCholesky},
                                                   {"auto", PreconditionerKind::Auto}};
const Choices<Precision> kPrecisions{{"double", Precision::Double},
                                     {"float", Precision::Float},
                                     {"mixed", Precision::Mixed}};
const Choices<SurfaceLayout> kSurfaceLayouts{{"interleaved", SurfaceLayout::Interleaved},
                                             {"separate", SurfaceLayout::Separate}};
const Choices<VtuFormat> kVtuFormats{
    {"ascii", VtuFormat::Ascii}, {"base64", VtuFormat::Base64}, {"raw", VtuFormat::Raw}};
const Choices<VtuCompression> kVtuCompressions{{"none", VtuCompression::None}, {"zlib", VtuCompression::Zlib}};
const Choices<Integrator> kIntegrators{{"newmark", Integrator::Newmark},
                                       {"backward_euler", Integrator::BackwardEuler},
                                       {"auto", Integrator::Auto}};
const Choices<AnalysisDesc::Kind> kAnalysisKinds{{"static", AnalysisDesc::Kind::Static},
                                                 {"dynamic", AnalysisDesc::Kind::Dynamic}};
const Choices<LoadDesc::Kind> kLoadKinds{{"gravity", LoadDesc::Kind::Gravity},
                                         {"force", LoadDesc::Kind::Force},
                                         {"displacement", LoadDesc::Kind::Displacement}};

template <class E>
const char* nameOf(const Choices<E>& table, E value) {
  for (const auto& entry : table)
    if (entry.second == value) return entry.first.c_str();
  return "?";
}

template <class E>
std::vector<std::string> namesOf(const Choices<E>& table) {
  std::vector<std::string> names;
  for (const auto& entry : table) names.push_back(entry.first);
  return names;
}

// ------------------------------------------------------------------ keys of each object
const std::vector<std::string> kSceneKeys{"name", "bodies", "analysis", "solver", "backend", "output"};
const std::vector<std::string> kBodyKeys{"name",  "mesh",  "material",         "formulation",
                                         "fixed", "loads", "initial_velocity", "initial_angular_velocity",
                                         "surface", "surface_layout"};
const std::vector<std::string> kMeshKeys{"file", "box", "scale", "translate"};
const std::vector<std::string> kBoxMeshKeys{"min", "max", "cells", "tets_per_cell"};
const std::vector<std::string> kMaterialKeys{"youngs_modulus", "poisson_ratio", "density", "rayleigh_mass",
                                             "rayleigh_stiffness"};
const std::vector<std::string> kNodeSetKinds{"box", "plane", "list", "bou"};
const std::vector<std::string> kNodeBoxKeys{"min", "max"};
const std::vector<std::string> kPlaneKeys{"point", "normal", "tolerance"};
const std::vector<std::string> kGravityKeys{"type", "vector", "ramp_time"};
const std::vector<std::string> kNodalLoadKeys{"type", "vector", "nodes", "ramp_time"};
const std::vector<std::string> kStaticKeys{"type", "increments", "max_newton_iterations", "residual_tolerance",
                                           "displacement_tolerance"};
const std::vector<std::string> kDynamicKeys{"type",          "integrator",    "time_step",
                                            "steps",         "newmark_beta",  "newmark_gamma",
                                            "newton_iterations", "newton_tolerance", "max_substeps",
                                            "sleep"};
const std::vector<std::string> kSleepKeys{"velocity", "load_change", "steps"};
const std::vector<std::string> kSolverKeys{"linear_solver", "tolerance",  "max_iterations", "check_every",
                                           "preconditioner", "precision", "rotation"};
const std::vector<std::string> kBackendKeys{"kind", "device", "batch"};
const std::vector<std::string> kOutputKeys{"probes", "vtk", "vtk_every", "surface_obj", "vtu_format",
                                           "vtu_compression"};
const std::vector<std::string> kProbeKeys{"name", "body", "nodes"};

bool contains(const std::vector<std::string>& names, const std::string& name) {
  return std::find(names.begin(), names.end(), name) != names.end();
}

const json* member(const json& object, const char* key) {
  const auto it = object.find(key);
  return it == object.end() ? nullptr : &*it;
}

/// What a value is, for "expected X, got Y" messages.
std::string describe(const json& value) {
  switch (value.type()) {
    case json::value_t::object: return "an object";
    case json::value_t::array:
      return "an array of " + std::to_string(value.size()) + (value.size() == 1 ? " element" : " elements");
    case json::value_t::string: {
      std::string s = value.get<std::string>();
      if (s.size() > 40) s = s.substr(0, 37) + "...";
      return "the string \"" + s + "\"";
    }
    case json::value_t::boolean: return value.get<bool>() ? "true" : "false";
    case json::value_t::null: return "null";
    case json::value_t::discarded: return "nothing";
    default: return "the number " + value.dump();
  }
}

// ------------------------------------------------------------------ typed, checked reading
/// Reads and checks values; every failure throws BadInput with "<source>: <key path>: <problem>".
class Reader {
 public:
  Reader(const std::string& source, const InputLimits& limits)
      : prefix_(source.empty() ? "" : source + ": "), limits_(limits) {}

  const std::string& prefix() const { return prefix_; }
  const InputLimits& limits() const { return limits_; }

  template <class... Parts>
  [[noreturn]] void fail(const std::string& path, const Parts&... parts) const {
    detail::fail(ErrorCode::BadInput, prefix_, path.empty() ? std::string("top level") : path, ": ", parts...);
  }

  void expectObject(const json& value, const std::string& path, const char* what) const {
    if (!value.is_object()) fail(path, "expected ", what, ", got ", describe(value));
  }

  /// Every key of `object` must be in `allowed`; a misspelt one gets the nearest valid key.
  void checkKeys(const json& object, const std::string& path, const std::vector<std::string>& allowed) const {
    for (auto it = object.begin(); it != object.end(); ++it) {
      if (contains(allowed, it.key())) continue;
      const std::string suggestion = nearestName(it.key(), allowed);
      if (!suggestion.empty()) fail(childPath(path, it.key()), "unknown key; did you mean \"", suggestion, "\"?");
      fail(childPath(path, it.key()), "unknown key; the keys allowed here are ", quotedList(allowed, " and "));
    }
  }

  void checkRange(double x, const std::string& path, const Range& range) const {
    if (range.ok && !range.ok(x))
      fail(path, formatNumber(x), " is out of range: must satisfy ", range.condition);
  }

  double number(const json& value, const std::string& path, const Range& range = {}) const {
    if (!value.is_number()) fail(path, "expected a number, got ", describe(value));
    const double x = value.get<double>();
    if (!std::isfinite(x)) fail(path, "expected a finite number, got ", formatNumber(x));
    checkRange(x, path, range);
    return x;
  }

  /// An integer; a float with an integral value (1e3) is accepted.
  int integer(const json& value, const std::string& path, const Range& range = {}) const {
    if (!value.is_number()) fail(path, "expected an integer, got ", describe(value));
    double x;
    if (value.is_number_unsigned()) x = static_cast<double>(value.get<std::uint64_t>());
    else if (value.is_number_integer()) x = static_cast<double>(value.get<std::int64_t>());
    else {
      x = value.get<double>();
      if (!std::isfinite(x) || std::floor(x) != x) fail(path, "expected an integer, got ", value.dump());
    }
    checkRange(x, path, range);
    if (std::abs(x) > std::numeric_limits<int>::max())
      fail(path, formatNumber(x), " is out of range: must be at most ", std::numeric_limits<int>::max());
    return static_cast<int>(x);
  }

  bool boolean(const json& value, const std::string& path) const {
    if (!value.is_boolean()) fail(path, "expected true or false, got ", describe(value));
    return value.get<bool>();
  }

  std::string string(const json& value, const std::string& path, bool allowEmpty = false) const {
    if (!value.is_string()) fail(path, "expected a string, got ", describe(value));
    std::string s = value.get<std::string>();
    if (s.empty() && !allowEmpty) fail(path, "must not be empty");
    return s;
  }

  Vec3 vec3(const json& value, const std::string& path) const {
    if (!value.is_array() || value.size() != 3)
      fail(path, "expected an array of exactly 3 numbers, got ", describe(value));
    Vec3 v{};
    for (std::size_t i = 0; i < 3; ++i) v[i] = number(value[i], indexPath(path, i));
    return v;
  }

  template <class E>
  E choice(const json& value, const std::string& path, const Choices<E>& table) const {
    const std::vector<std::string> names = namesOf(table);
    if (!value.is_string()) fail(path, "expected one of ", quotedList(names), ", got ", describe(value));
    const std::string s = value.get<std::string>();
    for (const auto& entry : table)
      if (entry.first == s) return entry.second;
    const std::string suggestion = nearestName(s, names);
    if (!suggestion.empty())
      fail(path, "unknown value \"", detail::shorten(s), "\"; did you mean \"", suggestion, "\"? (valid: ",
           quotedList(names), ")");
    fail(path, "unknown value \"", detail::shorten(s), "\"; valid values are ", quotedList(names));
  }

 private:
  std::string prefix_;
  InputLimits limits_;
};

/// An object at a key path, with readers that assign a field only when its key is present (so the
/// struct's default stays otherwise).
class Obj {
 public:
  Obj(const Reader& reader, const json& object, std::string path)
      : r_(reader), j_(object), path_(std::move(path)) {}

  const json* get(const char* key) const { return member(j_, key); }
  std::string at(const char* key) const { return childPath(path_, key); }
  const std::string& path() const { return path_; }

  const json& require(const char* key, const std::string& hint) const {
    const json* value = get(key);
    if (!value) r_.fail(at(key), "required key is missing", hint.empty() ? "" : "; ", hint);
    return *value;
  }

  void read(const char* key, double& out, const Range& range = {}) const {
    if (const json* v = get(key)) out = r_.number(*v, at(key), range);
  }
  void read(const char* key, int& out, const Range& range = {}) const {
    if (const json* v = get(key)) out = r_.integer(*v, at(key), range);
  }
  void read(const char* key, bool& out) const {
    if (const json* v = get(key)) out = r_.boolean(*v, at(key));
  }
  void read(const char* key, std::string& out, bool allowEmpty = false) const {
    if (const json* v = get(key)) out = r_.string(*v, at(key), allowEmpty);
  }
  void read(const char* key, Vec3& out) const {
    if (const json* v = get(key)) out = r_.vec3(*v, at(key));
  }
  template <class E>
  void read(const char* key, E& out, const Choices<E>& table) const {
    if (const json* v = get(key)) out = r_.choice(*v, at(key), table);
  }

 private:
  const Reader& r_;
  const json& j_;
  std::string path_;
};

// ------------------------------------------------------------------ ranges (header comments)
/// Upper bound of analysis.max_substeps: a failing step is retried in 2, 4, ... substeps up to this
/// many, so the bound keeps a failing step's retries to about 2 x 1024 substeps' work.
constexpr double kMaxSubsteps = 1024;

bool positive(double x) { return x > 0; }
bool nonNegative(double x) { return x >= 0; }
bool atLeastOne(double x) { return x >= 1; }

// ------------------------------------------------------------------ the sections
NodeSetDesc parseNodeSet(const Reader& r, const json& j, const std::string& path) {
  r.expectObject(j, path,
                 "a node set: {\"box\": {...}}, {\"plane\": {...}}, {\"list\": [...]} or {\"bou\": \"file.bou\"}");
  r.checkKeys(j, path, kNodeSetKinds);
  if (j.empty())
    r.fail(path, "empty node set; give exactly one of ", quotedList(kNodeSetKinds));
  if (j.size() > 1) {
    std::vector<std::string> present;
    for (auto it = j.begin(); it != j.end(); ++it) present.push_back(it.key());
    r.fail(path, "has ", quotedList(present, " and "), "; a node set is exactly one of ", quotedList(kNodeSetKinds));
  }
  NodeSetDesc set;
  const std::string kind = j.begin().key();
  const json& body = j.begin().value();
  const std::string bodyPath = childPath(path, kind);
  if (kind == "box") {
    set.kind = NodeSetDesc::Kind::Box;
    r.expectObject(body, bodyPath, "an object {\"min\": [x, y, z], \"max\": [x, y, z]}");
    r.checkKeys(body, bodyPath, kNodeBoxKeys);
    const Obj box(r, body, bodyPath);
    set.boxMin = r.vec3(box.require("min", "the lower corner [x, y, z]"), box.at("min"));
    set.boxMax = r.vec3(box.require("max", "the upper corner [x, y, z]"), box.at("max"));
    for (int a = 0; a < 3; ++a)
      if (set.boxMax[a] < set.boxMin[a])
        r.fail(box.at("max"), "max[", a, "] = ", formatNumber(set.boxMax[a]), " is below min[", a,
               "] = ", formatNumber(set.boxMin[a]), "; the box would select nothing");
  } else if (kind == "plane") {
    set.kind = NodeSetDesc::Kind::Plane;
    r.expectObject(body, bodyPath, "an object {\"point\": [x, y, z], \"normal\": [x, y, z], \"tolerance\": t}");
    r.checkKeys(body, bodyPath, kPlaneKeys);
    const Obj plane(r, body, bodyPath);
    set.planePoint = r.vec3(plane.require("point", "a point on the plane [x, y, z]"), plane.at("point"));
    set.planeNormal = r.vec3(plane.require("normal", "the plane's normal [x, y, z]"), plane.at("normal"));
    if (set.planeNormal[0] == 0 && set.planeNormal[1] == 0 && set.planeNormal[2] == 0)
      r.fail(plane.at("normal"), "must be non-zero");
    plane.read("tolerance", set.planeTolerance, {nonNegative, "tolerance >= 0"});
  } else if (kind == "list") {
    set.kind = NodeSetDesc::Kind::List;
    if (!body.is_array()) r.fail(bodyPath, "expected an array of 0-based node indices, got ", describe(body));
    if (body.empty()) r.fail(bodyPath, "must not be empty");
    for (std::size_t i = 0; i < body.size(); ++i) {
      const std::string at = indexPath(bodyPath, i);
      const json& item = body[i];
      // Integral floats (1e3) are accepted like every other integer in the format.
      const double x = item.is_number() ? item.get<double>() : 0.5;
      if (!item.is_number() || std::floor(x) != x)
        r.fail(at, "expected a 0-based node index (an integer >= 0), got ", describe(item));
      if (x < 0) r.fail(at, item.dump(), " is out of range: node indices are 0-based, >= 0");
      if (x > std::numeric_limits<std::uint32_t>::max())
        r.fail(at, item.dump(), " is out of range: too large for a node index");
      const auto index = static_cast<std::uint32_t>(x);
      set.indices.push_back(index);
    }
  } else {  // bou
    set.kind = NodeSetDesc::Kind::BouFile;
    set.bouFile = r.string(body, bodyPath);
  }
  return set;
}

std::vector<NodeSetDesc> parseNodeSets(const Reader& r, const json& j, const std::string& path) {
  if (!j.is_array()) r.fail(path, "expected an array of node sets, e.g. [{\"plane\": {...}}], got ", describe(j));
  std::vector<NodeSetDesc> sets;
  for (std::size_t i = 0; i < j.size(); ++i) sets.push_back(parseNodeSet(r, j[i], indexPath(path, i)));
  return sets;
}

MeshSourceDesc parseMesh(const Reader& r, const json& j, const std::string& path) {
  MeshSourceDesc mesh;
  if (j.is_string()) {  // shorthand: "mesh": "beam.msh"
    mesh.file = r.string(j, path);
    return mesh;
  }
  r.expectObject(j, path, "an object {\"file\": \"...\"} or {\"box\": {...}}, or a file name");
  r.checkKeys(j, path, kMeshKeys);
  const Obj o(r, j, path);
  const json* file = o.get("file");
  const json* box = o.get("box");
  if (file && box) r.fail(path, "has both \"file\" and \"box\"; give exactly one");
  if (!file && !box)
    r.fail(path, "needs exactly one of \"file\" (a mesh file) or \"box\" (a generated box)");
  if (file) mesh.file = r.string(*file, o.at("file"));
  if (box) {
    const std::string boxPath = o.at("box");
    r.expectObject(*box, boxPath, "an object {\"min\": [...], \"max\": [...], \"cells\": [...], \"tets_per_cell\": 5}");
    r.checkKeys(*box, boxPath, kBoxMeshKeys);
    const Obj b(r, *box, boxPath);
    BoxSpec spec;
    b.read("min", spec.min);
    b.read("max", spec.max);
    for (int a = 0; a < 3; ++a)
      if (!(spec.max[a] > spec.min[a]))
        r.fail(b.at("max"), "max[", a, "] = ", formatNumber(spec.max[a]), " must exceed min[", a, "] = ",
               formatNumber(spec.min[a]));
    if (const json* cells = b.get("cells")) {
      if (!cells->is_array() || cells->size() != 3)
        r.fail(b.at("cells"), "expected an array of exactly 3 integers (cells along x, y, z), got ", describe(*cells));
      for (std::size_t a = 0; a < 3; ++a)
        spec.cells[a] = r.integer((*cells)[a], indexPath(b.at("cells"), a), {atLeastOne, "cells >= 1"});
    }
    b.read("tets_per_cell", spec.tetsPerCell,
           {[](double x) { return x == 5 || x == 6; }, "tets_per_cell = 5 or 6"});
    const std::string tooLarge = mesh::boxSizeProblem(spec, r.limits());
    if (!tooLarge.empty()) r.fail(b.at("cells"), tooLarge);
    mesh.box = spec;
  }
  o.read("scale", mesh.scale, {positive, "scale > 0"});
  o.read("translate", mesh.translate);
  return mesh;
}

MaterialDesc parseMaterial(const Reader& r, const json& j, const std::string& path) {
  r.expectObject(j, path, "an object {\"youngs_modulus\": E, \"poisson_ratio\": nu, \"density\": rho, ...}");
  r.checkKeys(j, path, kMaterialKeys);
  const Obj o(r, j, path);
  MaterialDesc m;
  o.read("youngs_modulus", m.youngsModulus, {positive, "E > 0"});
  o.read("poisson_ratio", m.poissonRatio, {[](double x) { return x > -1 && x < 0.5; }, "-1 < nu < 0.5"});
  o.read("density", m.density, {positive, "rho > 0"});
  o.read("rayleigh_mass", m.rayleighMass, {nonNegative, "alpha >= 0"});
  o.read("rayleigh_stiffness", m.rayleighStiffness, {nonNegative, "beta >= 0"});
  return m;
}

LoadDesc parseLoad(const Reader& r, const json& j, const std::string& path) {
  r.expectObject(j, path, "a load object {\"type\": \"gravity\" | \"force\" | \"displacement\", ...}");
  const Obj o(r, j, path);
  LoadDesc load;
  load.kind = r.choice(o.require("type", "one of " + quotedList(namesOf(kLoadKinds))), o.at("type"), kLoadKinds);
  const bool nodal = load.kind != LoadDesc::Kind::Gravity;
  if (!nodal && o.get("nodes"))
    r.fail(o.at("nodes"), "only force and displacement loads take \"nodes\"; gravity acts on the whole body");
  r.checkKeys(j, path, nodal ? kNodalLoadKeys : kGravityKeys);
  if (nodal) {
    const std::string what = nameOf(kLoadKinds, load.kind);
    load.vector = r.vec3(o.require("vector", load.kind == LoadDesc::Kind::Force
                                                 ? "the total force [fx, fy, fz] in N"
                                                 : "the prescribed displacement [ux, uy, uz] in m"),
                         o.at("vector"));
    load.nodes = parseNodeSet(r, o.require("nodes", "the node set the " + what + " acts on"), o.at("nodes"));
  } else {
    o.read("vector", load.vector);
  }
  o.read("ramp_time", load.rampTime, {nonNegative, "ramp_time >= 0"});
  return load;
}

BodyDesc parseBody(const Reader& r, const json& j, const std::string& path, std::size_t index) {
  r.expectObject(j, path, "a body object {\"name\": ..., \"mesh\": {...}, ...}");
  r.checkKeys(j, path, kBodyKeys);
  const Obj o(r, j, path);
  BodyDesc body;
  body.name = index == 0 ? "body" : "body" + std::to_string(index);
  o.read("name", body.name);
  body.mesh = parseMesh(r, o.require("mesh", "give {\"file\": \"mesh.msh\"} or {\"box\": {...}}"), o.at("mesh"));
  if (const json* v = o.get("material")) body.material = parseMaterial(r, *v, o.at("material"));
  o.read("formulation", body.formulation, kFormulations);
  if (const json* v = o.get("fixed")) body.fixed = parseNodeSets(r, *v, o.at("fixed"));
  if (const json* v = o.get("loads")) {
    const std::string loadsPath = o.at("loads");
    if (!v->is_array()) r.fail(loadsPath, "expected an array of loads, got ", describe(*v));
    for (std::size_t i = 0; i < v->size(); ++i) body.loads.push_back(parseLoad(r, (*v)[i], indexPath(loadsPath, i)));
  }
  o.read("initial_velocity", body.initialVelocity);
  o.read("initial_angular_velocity", body.initialAngularVelocity);
  o.read("surface", body.surface);
  o.read("surface_layout", body.surfaceLayout, kSurfaceLayouts);
  if (o.get("surface_layout") && body.surface.empty())
    r.fail(o.at("surface_layout"), "lays out a render surface, but the body has none; add \"surface\": \"file.obj\" "
           "or remove \"surface_layout\"");
  return body;
}

AnalysisDesc parseAnalysis(const Reader& r, const json& j, const std::string& path) {
  r.expectObject(j, path, "an object {\"type\": \"static\" | \"dynamic\", ...}");
  const Obj o(r, j, path);
  AnalysisDesc a;
  o.read("type", a.kind, kAnalysisKinds);
  const bool isStatic = a.kind == AnalysisDesc::Kind::Static;
  const auto& allowed = isStatic ? kStaticKeys : kDynamicKeys;
  const auto& other = isStatic ? kDynamicKeys : kStaticKeys;
  const char* thisType = isStatic ? "static" : "dynamic";
  const char* otherType = isStatic ? "dynamic" : "static";
  for (auto it = j.begin(); it != j.end(); ++it)
    if (!contains(allowed, it.key()) && contains(other, it.key()))
      r.fail(childPath(path, it.key()), "belongs to a ", otherType, " analysis, but the analysis type is \"",
             thisType, "\"", o.get("type") ? "" : " (the default)", "; remove it or set \"type\": \"", otherType,
             "\"");
  r.checkKeys(j, path, allowed);
  StaticDesc& s = a.statics;
  o.read("increments", s.increments, {atLeastOne, "increments >= 1"});
  o.read("max_newton_iterations", s.maxNewtonIterations, {atLeastOne, "max_newton_iterations >= 1"});
  o.read("residual_tolerance", s.residualTolerance, {positive, "residual_tolerance > 0"});
  o.read("displacement_tolerance", s.displacementTolerance, {positive, "displacement_tolerance > 0"});
  DynamicDesc& d = a.dynamics;
  o.read("integrator", d.integrator, kIntegrators);
  o.read("time_step", d.timeStep, {positive, "time_step > 0"});
  o.read("steps", d.steps, {nonNegative, "steps >= 1, or 0 for an open-ended analysis"});
  o.read("newmark_beta", d.newmarkBeta, {[](double x) { return x > 0 && x <= 0.5; }, "0 < beta <= 0.5"});
  o.read("newmark_gamma", d.newmarkGamma, {[](double x) { return x >= 0.5 && x <= 1; }, "0.5 <= gamma <= 1"});
  o.read("newton_iterations", d.newtonIterations, {atLeastOne, "newton_iterations >= 1"});
  o.read("newton_tolerance", d.newtonTolerance, {positive, "newton_tolerance > 0"});
  o.read("max_substeps", d.maxSubsteps,
         {[](double x) { return x >= 1 && x <= kMaxSubsteps; },
          "1 <= max_substeps <= 1024 (a failed step is retried in at most 1024 substeps; for finer steps "
          "lower time_step)"});
  if (const json* sleep = o.get("sleep")) {
    // true = the default thresholds; an object sets them (and turns sleeping on).
    if (sleep->is_boolean()) {
      d.sleep.enabled = r.boolean(*sleep, o.at("sleep"));
    } else {
      r.expectObject(*sleep, o.at("sleep"), "true, false or an object {\"velocity\": 1e-4, \"load_change\": 1e-6, \"steps\": 10}");
      r.checkKeys(*sleep, o.at("sleep"), kSleepKeys);
      const Obj so(r, *sleep, o.at("sleep"));
      d.sleep.enabled = true;
      so.read("velocity", d.sleep.velocity, {positive, "velocity > 0"});
      so.read("load_change", d.sleep.loadChange, {positive, "load_change > 0"});
      so.read("steps", d.sleep.steps, {atLeastOne, "steps >= 1"});
    }
  }
  return a;
}

SolverDesc parseSolver(const Reader& r, const json& j, const std::string& path) {
  r.expectObject(j, path, "an object {\"linear_solver\": \"pcg\", \"tolerance\": 1e-6, ...}");
  r.checkKeys(j, path, kSolverKeys);
  const Obj o(r, j, path);
  SolverDesc s;
  o.read("linear_solver", s.linearSolver, kLinearSolvers);
  o.read("tolerance", s.tolerance, {positive, "tolerance > 0"});
  o.read("max_iterations", s.maxIterations, {atLeastOne, "max_iterations >= 1"});
  o.read("check_every", s.checkEvery, {atLeastOne, "check_every >= 1"});
  o.read("preconditioner", s.preconditioner, kPreconditioners);
  o.read("precision", s.precision, kPrecisions);
  o.read("rotation", s.rotation, kRotations);
  return s;
}

BackendDesc parseBackend(const Reader& r, const json& j, const std::string& path) {
  BackendDesc b;
  if (j.is_string()) {  // shorthand: "backend": "reference"
    b.kind = r.choice(j, path, kBackends);
    return b;
  }
  r.expectObject(j, path, "\"auto\", \"reference\", \"opencl\" or an object {\"kind\": ..., \"device\": ...}");
  r.checkKeys(j, path, kBackendKeys);
  const Obj o(r, j, path);
  o.read("kind", b.kind, kBackends);
  if (const json* device = o.get("device")) {
    if (device->is_number_unsigned() || (device->is_number_integer() && device->get<std::int64_t>() >= 0))
      b.device = std::to_string(device->get<std::uint64_t>());  // a device index
    else if (device->is_string())
      b.device = device->get<std::string>();
    else
      r.fail(o.at("device"), "expected a device name (substring) or a device index >= 0, got ", describe(*device));
  }
  o.read("batch", b.batch);
  return b;
}

OutputDesc parseOutput(const Reader& r, const json& j, const std::string& path) {
  r.expectObject(j, path, "an object {\"probes\": [...], \"vtk\": true, \"vtk_every\": N, \"surface_obj\": false}");
  r.checkKeys(j, path, kOutputKeys);
  const Obj o(r, j, path);
  OutputDesc out;
  if (const json* probes = o.get("probes")) {
    const std::string probesPath = o.at("probes");
    if (!probes->is_array()) r.fail(probesPath, "expected an array of probes, got ", describe(*probes));
    for (std::size_t i = 0; i < probes->size(); ++i) {
      const std::string at = indexPath(probesPath, i);
      const json& pj = (*probes)[i];
      r.expectObject(pj, at, "a probe {\"name\": ..., \"body\": ..., \"nodes\": {...}}");
      r.checkKeys(pj, at, kProbeKeys);
      const Obj p(r, pj, at);
      ProbeDesc probe;
      probe.name = "probe" + std::to_string(i);
      p.read("name", probe.name);
      p.read("body", probe.body, /*allowEmpty=*/true);
      probe.nodes = parseNodeSet(r, p.require("nodes", "the node set whose mean displacement is recorded"), p.at("nodes"));
      out.probes.push_back(std::move(probe));
    }
  }
  o.read("vtk", out.vtk);
  o.read("vtk_every", out.vtkEvery, {nonNegative, "vtk_every >= 0"});
  o.read("surface_obj", out.surfaceObj);
  o.read("vtu_format", out.vtuFormat, kVtuFormats);
  o.read("vtu_compression", out.vtuCompression, kVtuCompressions);
  if (out.vtuCompression == VtuCompression::Zlib && out.vtuFormat == VtuFormat::Ascii)
    r.fail(o.at("vtu_compression"), "\"zlib\" compresses binary arrays only, and vtu_format is \"ascii\"",
           o.get("vtu_format") ? "" : " (the default)", "; set vtu_format to \"base64\" or \"raw\", or use \"none\"");
  if (out.vtuCompression == VtuCompression::Zlib && !vtuZlibAvailable())
    r.fail(o.at("vtu_compression"), "\"zlib\" needs a corofem built with zlib, and this one was built without "
           "it; install zlib1g-dev and rebuild, or use \"none\"");
  return out;
}

/// A name must be short and printable; the scene's and the bodies' become file names (fileName).
void checkName(const Reader& r, const std::string& path, const std::string& name, bool fileName,
               const char* origin = "") {
  const std::string problem = fileName ? scene::fileNameProblem(name) : scene::nameProblem(name);
  if (!problem.empty()) r.fail(path, "the name \"", detail::shorten(name), "\"", origin, " ", problem);
}

/// Checks between sections: unique names, probes naming existing bodies, features the chosen
/// backend cannot run.
void checkConsistency(const Reader& r, const Scene& scene) {
  std::vector<std::string> bodyNames;
  for (std::size_t i = 0; i < scene.bodies.size(); ++i) {
    const std::string& name = scene.bodies[i].name;
    checkName(r, childPath(indexPath("bodies", i), "name"), name, true);
    if (contains(bodyNames, name))
      r.fail(childPath(indexPath("bodies", i), "name"), "\"", name, "\" is already the name of another body; body names must be unique");
    bodyNames.push_back(name);
  }
  std::set<std::string> probeNames;
  for (std::size_t i = 0; i < scene.output.probes.size(); ++i) {
    const ProbeDesc& probe = scene.output.probes[i];
    const std::string at = indexPath("output.probes", i);
    checkName(r, childPath(at, "name"), probe.name, false);
    if (!probeNames.insert(probe.name).second)
      r.fail(childPath(at, "name"), "\"", probe.name, "\" is already the name of another probe; probe names must be unique");
    if (!probe.body.empty() && !contains(bodyNames, probe.body)) {
      const std::string suggestion = nearestName(probe.body, bodyNames);
      if (!suggestion.empty())
        r.fail(childPath(at, "body"), "no body is named \"", detail::shorten(probe.body), "\"; did you mean \"",
               suggestion, "\"?");
      r.fail(childPath(at, "body"), "no body is named \"", detail::shorten(probe.body), "\"; the bodies are ",
             quotedList(bodyNames, " and "));
    }
  }
  if (scene.backend.kind == BackendKind::OpenCL || scene.backend.kind == BackendKind::Vulkan) {
    const std::string backend = toString(scene.backend.kind);
    if (scene.solver.linearSolver == LinearSolverKind::Cholesky)
      r.fail("solver.linear_solver", "\"cholesky\" runs only on the reference backend, and the backend is \"", backend,
             "\"; use \"pcg\", or the backend \"reference\"");
    if (scene.solver.preconditioner == PreconditionerKind::WarpedCholesky && scene.backend.kind == BackendKind::Vulkan)
      r.fail("solver.preconditioner", "\"warped_cholesky\" runs on the reference and opencl backends, and the backend "
             "is \"vulkan\"; use \"amg\", or the backend \"reference\" or \"opencl\"");
    for (std::size_t i = 0; i < scene.bodies.size(); ++i) {
      const Formulation f = scene.bodies[i].formulation;
      if (f == Formulation::StVenantKirchhoff || f == Formulation::NeoHookean)
        r.fail(childPath(indexPath("bodies", i), "formulation"), "\"", toString(f),
               "\" runs only on the reference backend, and the backend is \"", backend, "\"; use \"corotational\" or "
               "\"linear\", or the backend \"reference\"");
    }
  }
}

Scene parseDocument(const Reader& r, const json& root, const std::string& defaultName) {
  r.expectObject(root, "", "a JSON object {\"bodies\": [...], ...}");
  r.checkKeys(root, "", kSceneKeys);
  const Obj o(r, root, "");
  Scene scene;
  if (!defaultName.empty()) scene.name = defaultName;
  o.read("name", scene.name);
  checkName(r, "name", scene.name, true,
            o.get("name") ? "" : " (taken from the file name, as the scene sets no \"name\")");
  const json& bodies = o.require("bodies", "a scene needs at least one body: \"bodies\": [{\"mesh\": {...}}]");
  if (!bodies.is_array()) r.fail("bodies", "expected an array of bodies, got ", describe(bodies));
  if (bodies.empty()) r.fail("bodies", "must contain at least one body");
  for (std::size_t i = 0; i < bodies.size(); ++i) scene.bodies.push_back(parseBody(r, bodies[i], indexPath("bodies", i), i));
  if (const json* v = o.get("analysis")) scene.analysis = parseAnalysis(r, *v, "analysis");
  if (const json* v = o.get("solver")) scene.solver = parseSolver(r, *v, "solver");
  if (const json* v = o.get("backend")) scene.backend = parseBackend(r, *v, "backend");
  if (const json* v = o.get("output")) scene.output = parseOutput(r, *v, "output");
  checkConsistency(r, scene);
  return scene;
}

Scene parseWithSource(const std::string& text, const std::string& baseDir, const std::vector<std::string>& overrides,
                      const InputLimits& limits,
                      const std::string& source, const std::string& defaultName) {
  const Reader r(source, limits);
  json root = scene::parseJsonText(text, r.prefix());
  if (!overrides.empty()) {
    scene::expandShorthands(root);
    scene::applyOverrides(root, overrides, r.prefix());
  }
  Scene scene = parseDocument(r, root, defaultName);
  scene.baseDir = baseDir;
  return scene;
}

}  // namespace

Result<Scene> parseScene(const std::string& jsonText, const std::string& baseDir,
                         const std::vector<std::string>& overrides, const InputLimits& limits) {
  return detail::guardResult<Scene>([&] { return parseWithSource(jsonText, baseDir, overrides, limits, "", ""); });
}

Result<Scene> loadScene(const std::string& path, const std::vector<std::string>& overrides,
                        const InputLimits& limits) {
  return detail::guardResult<Scene>([&] {
    const std::string text =
        mesh::readInputFile(path, "the scene file \"" + path + "\"", "", limits, mesh::InputKind::Scene);
    const std::filesystem::path file(path);
    std::string baseDir = file.parent_path().string();
    if (baseDir.empty()) baseDir = ".";
    // The name defaults to the file stem ("fig8.json" -> "fig8").
    return parseWithSource(text, baseDir, overrides, limits, path, file.stem().string());
  });
}

}  // namespace corofem
