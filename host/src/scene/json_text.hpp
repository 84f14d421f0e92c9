// The scene file as JSON text: parsing with positions in messages, duplicate keys, shorthands.
#pragma once

#include <nlohmann/json.hpp>

#include <string>

namespace corofem::scene {

/// Parses JSON text (comments allowed). Errors are ErrorCode::BadInput starting with
/// `messagePrefix`: "line L, column C: invalid JSON: ..." for malformed text (the token the JSON
/// library quotes is shortened, so a 40,000-character string or number gives a short message), the
/// position of a number too large for a double, and the key path of a key repeated within one object.
nlohmann::json parseJsonText(const std::string& text, const std::string& messagePrefix);

/// Expands the shorthands that --set paths would need to go through: `"backend": "opencl"` becomes
/// {"kind": "opencl"} and `"mesh": "beam.msh"` {"file": "beam.msh"}, so that
/// `--set backend.device=1` and `--set bodies.0.mesh.scale=2` work on them.
void expandShorthands(nlohmann::json& root);

}  // namespace corofem::scene
