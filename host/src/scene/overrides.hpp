// `--set key.path=value` overrides, applied to a parsed scene document before it is validated.
#pragma once

#include <nlohmann/json_fwd.hpp>

#include <string>
#include <vector>

namespace corofem::scene {

/// Applies each override in order. The path is split at '.', and a numeric segment (or `[n]`)
/// indexes an array: "bodies.0.material.youngs_modulus=1e6", "bodies[0].loads[1].vector=[0,0,1]".
/// Missing objects along the path are created (the schema check that follows reports a key that
/// does not exist, with a suggestion). The value is parsed as JSON when it parses, else it is taken
/// as a bare string ("analysis.integrator=backward_euler"). Errors (ErrorCode::BadInput) start with
/// `messagePrefix` and name the override: a missing '=', an empty path, an index out of range, a
/// path that runs through a number or a string.
void applyOverrides(nlohmann::json& root, const std::vector<std::string>& overrides,
                    const std::string& messagePrefix);

}  // namespace corofem::scene
