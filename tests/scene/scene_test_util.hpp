// Helpers shared by the scene tests: parse a scene that must parse, or one that must fail.
#pragma once

#include <corofem/scene.hpp>

#include <gtest/gtest.h>

#include <string>
#include <vector>

namespace corofem::test {

/// The smallest valid scene: one body on a generated unit box.
inline const char* kMinimalScene = R"({"bodies": [{"mesh": {"box": {}}}]})";

/// Parses `text` (with overrides); fails the test with the message when it does not parse.
inline Scene parseOk(const std::string& text, const std::vector<std::string>& overrides = {}) {
  Result<Scene> scene = parseScene(text, "", overrides);
  EXPECT_TRUE(scene.isOk()) << scene.message();
  return scene.isOk() ? scene.value() : Scene{};
}

/// Parses `text` expecting ErrorCode::BadInput; returns the message ("" when it parsed).
inline std::string parseError(const std::string& text, const std::vector<std::string>& overrides = {}) {
  Result<Scene> scene = parseScene(text, "", overrides);
  EXPECT_FALSE(scene.isOk()) << "expected an error, but the scene parsed";
  if (scene.isOk()) return "";
  EXPECT_EQ(scene.status().code(), ErrorCode::BadInput) << scene.message();
  return scene.message();
}

/// The error message of the minimal scene with `overrides` applied (they inject the bad value).
inline std::string overrideError(const std::vector<std::string>& overrides) {
  return parseError(kMinimalScene, overrides);
}

}  // namespace corofem::test
