// Mutated scenes never crash and never leak an internal error: each one parses or is bad input.
#include "scene/scene_test_util.hpp"

#include <corofem/scene.hpp>

#include <gtest/gtest.h>

#include <random>

namespace corofem {
namespace {

const char* kSeedScene = R"({
  "name": "fuzz", "backend": {"kind": "reference", "device": "0"},
  "bodies": [{"name": "beam", "mesh": {"box": {"min": [0, 0, 0], "max": [1, 0.1, 0.1], "cells": [4, 1, 1]}, "scale": 1},
              "material": {"youngs_modulus": 1e5, "poisson_ratio": 0.3, "density": 1000},
              "fixed": [{"plane": {"point": [0, 0, 0], "normal": [1, 0, 0]}}, {"list": [0, 1]}, {"box": {"min": [0,0,0], "max": [1,1,1]}}],
              "loads": [{"type": "force", "vector": [0, -1, 0], "nodes": {"bou": "a.bou"}, "ramp_time": 0.1}]}],
  "analysis": {"type": "dynamic", "time_step": 0.01, "steps": 10},
  "solver": {"tolerance": 1e-6, "rotation": "svd"},
  "output": {"probes": [{"name": "tip", "body": "beam", "nodes": {"list": [3]}}], "vtk_every": 2}
})";

void expectParsesOrBadInput(const std::string& text, const std::vector<std::string>& overrides = {}) {
  const Result<Scene> s = parseScene(text, "", overrides);
  if (!s.isOk()) {
    EXPECT_EQ(s.status().code(), ErrorCode::BadInput) << s.message() << "\ninput:\n" << text;
    EXPECT_FALSE(s.message().empty());
  }
}

TEST(SceneFuzz, CharacterMutationsGiveBadInputNotCrashes) {
  ASSERT_TRUE(parseScene(kSeedScene, "").isOk());
  const std::string seed = kSeedScene;
  const std::string alphabet = "{}[]:,\"0123456789.-+eE abcxyz_\n";
  std::mt19937 rng(12345);  // fixed seed: the same inputs on every run
  for (int trial = 0; trial < 3000; ++trial) {
    std::string text = seed;
    const int edits = 1 + static_cast<int>(rng() % 3);
    for (int e = 0; e < edits; ++e) {
      const std::size_t at = rng() % text.size();
      switch (rng() % 3) {
        case 0: text.erase(at, 1); break;
        case 1: text[at] = alphabet[rng() % alphabet.size()]; break;
        default: text.insert(at, 1, alphabet[rng() % alphabet.size()]); break;
      }
    }
    expectParsesOrBadInput(text);
  }
}

TEST(SceneFuzz, OverridesWithOddPathsAndValuesGiveBadInputNotCrashes) {
  const std::vector<std::string> paths{"", ".", "bodies", "bodies.0", "bodies.00", "bodies.-1", "bodies.99999999999",
                                       "bodies[", "bodies[x]", "bodies[0]", "bodies.0.fixed.0.list.1", "a.b.c",
                                       "output.probes.0.nodes", "analysis.type", "backend.kind", "name"};
  const std::vector<std::string> values{"", "0", "-1", "1e400", "[]", "{}", "null", "true", "\"\"", "[1,2,3]",
                                        "{\"list\": [1]}", "static", "nan", "[", "\"unterminated"};
  for (const std::string& p : paths)
    for (const std::string& v : values) expectParsesOrBadInput(kSeedScene, {p + "=" + v});
  expectParsesOrBadInput(kSeedScene, {"no equals sign"});
}

}  // namespace
}  // namespace corofem
