// corofem::toString spells every enumerator as the scene format does: each name parses back to
// the enumerator it came from (the names are switches, the parser uses its own tables).
#include <corofem/scene.hpp>

#include <gtest/gtest.h>

#include <string>

namespace {

using namespace corofem;

Scene parse(const std::string& bodyExtra, const std::string& sceneExtra) {
  const std::string text = R"({"bodies": [{"mesh": {"box": {"min": [0,0,0], "max": [1,1,1], "cells": [1,1,1]}})" +
                           bodyExtra + "}]" + sceneExtra + "}";
  auto scene = parseScene(text, ".");
  EXPECT_TRUE(scene.isOk()) << scene.message() << "\n" << text;
  return scene.isOk() ? scene.value() : Scene{};
}

TEST(EnumNames, FormulationsParseBack) {
  for (Formulation f : {Formulation::Linear, Formulation::Corotational, Formulation::StVenantKirchhoff,
                        Formulation::NeoHookean})
    EXPECT_EQ(parse(std::string(R"(, "formulation": ")") + toString(f) + "\"", "").bodies.at(0).formulation, f)
        << toString(f);
}

TEST(EnumNames, SolverEnumerationsParseBack) {
  for (RotationMethod m : {RotationMethod::Polar, RotationMethod::Svd, RotationMethod::Quaternion, RotationMethod::Qr})
    EXPECT_EQ(parse("", std::string(R"(, "solver": {"rotation": ")") + toString(m) + "\"}").solver.rotation, m)
        << toString(m);
  for (Precision p : {Precision::Double, Precision::Float, Precision::Mixed})
    EXPECT_EQ(parse("", std::string(R"(, "solver": {"precision": ")") + toString(p) + "\"}").solver.precision, p)
        << toString(p);
  for (PreconditionerKind p : {PreconditionerKind::None, PreconditionerKind::Diagonal, PreconditionerKind::BlockDiagonal,
                               PreconditionerKind::Amg, PreconditionerKind::WarpedCholesky, PreconditionerKind::Auto})
    EXPECT_EQ(parse("", std::string(R"(, "solver": {"preconditioner": ")") + toString(p) + "\"}").solver.preconditioner, p)
        << toString(p);
}

TEST(EnumNames, SurfaceLayoutsParseBack) {
  // The parser reads the layout only next to a surface (it is an error without one); the file need
  // not exist for parsing.
  for (SurfaceLayout l : {SurfaceLayout::Interleaved, SurfaceLayout::Separate})
    EXPECT_EQ(parse(std::string(R"(, "surface": "s.obj", "surface_layout": ")") + toString(l) + "\"", "")
                  .bodies.at(0)
                  .surfaceLayout,
              l)
        << toString(l);
}

TEST(EnumNames, BackendsParseBack) {
  for (BackendKind b : {BackendKind::Auto, BackendKind::Reference, BackendKind::OpenCL})
    EXPECT_EQ(parse("", std::string(R"(, "backend": ")") + toString(b) + "\"").backend.kind, b) << toString(b);
}

}  // namespace
