// Key paths and "did you mean" suggestions for scene-file messages. No JSON types here, so that
// this header stays cheap to include.
//
// A key path names a value the way a user reads the scene file: `bodies[0].material.poisson_ratio`.
#pragma once

#include <cstddef>
#include <string>
#include <string_view>
#include <vector>

namespace corofem::scene {

/// `parent.key`, or `key` at the top level; a key that is not a plain identifier is quoted:
/// `parent["my key"]`.
std::string childPath(const std::string& parent, const std::string& key);

/// `parent[index]`.
std::string indexPath(const std::string& parent, std::size_t index);

/// Optimal-string-alignment distance (Levenshtein plus adjacent transpositions, so "materail" is 1
/// from "material"), compared case-insensitively.
std::size_t editDistance(std::string_view a, std::string_view b);

/// The candidate nearest to `word` when it is plausibly a misspelling of it (distance at most
/// max(2, length / 3)); "" when none is that close. Ties go to the earlier candidate.
std::string nearestName(const std::string& word, const std::vector<std::string>& candidates);

/// `"a", "b" or "c"`, for messages that list the valid choices.
std::string quotedList(const std::vector<std::string>& names, const char* lastSeparator = " or ");

/// Shortest text that reads back to the same double (0.1 -> "0.1", 1e-06 -> "1e-06").
std::string formatNumber(double value);

/// `[x, y, z]` with formatNumber.
std::string formatVec3(const double* v);

}  // namespace corofem::scene
