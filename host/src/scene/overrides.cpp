// `--set` overrides: navigate a JSON document by a key path and replace (or add) one value.
#include "scene/overrides.hpp"

#include "scene/json_path.hpp"
#include "util/error.hpp"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cctype>
#include <string>
#include <vector>

namespace corofem::scene {

namespace {

using nlohmann::json;

/// Segments of the longest key path an override may have (scene keys are at most 6 deep; a longer
/// path only creates objects the schema check rejects, at a cost quadratic in its length).
constexpr std::size_t kMaxSegments = 32;

/// One step of a key path: an object key, or a number that may index an array.
struct Segment {
  std::string text;
  bool bracketed = false;  ///< written as [n]: must index an array
  bool isNumber() const {
    return !text.empty() &&
           std::all_of(text.begin(), text.end(), [](unsigned char c) { return std::isdigit(c); });
  }
};

const char* typeName(const json& value) {
  switch (value.type()) {
    case json::value_t::object: return "an object";
    case json::value_t::array: return "an array";
    case json::value_t::string: return "a string";
    case json::value_t::boolean: return "a boolean";
    case json::value_t::null: return "null";
    default: return "a number";
  }
}

class OverrideError {
 public:
  OverrideError(const std::string& prefix, const std::string& text) : prefix_(prefix), text_(text) {}
  template <class... Parts>
  [[noreturn]] void operator()(const Parts&... parts) const {
    // The override is quoted once, shortened (parts that quote it again shorten theirs too).
    detail::fail(ErrorCode::BadInput, prefix_, "--set \"", detail::shorten(text_, 80), "\": ", parts...);
  }

 private:
  const std::string& prefix_;
  const std::string& text_;
};

std::vector<Segment> splitPath(const std::string& path, const OverrideError& fail) {
  std::vector<Segment> segments;
  std::string current;
  bool haveCurrent = false;
  for (std::size_t i = 0; i < path.size(); ++i) {
    const char c = path[i];
    if (c == '.') {
      if (!haveCurrent) fail("empty segment in the key path \"", detail::shorten(path, 80), "\" (two dots, or a leading dot)");
      segments.push_back({current, false});
      current.clear();
      haveCurrent = false;
      // a '.' right after "]" (bodies[0].name) separates nothing new
    } else if (c == '[') {
      if (haveCurrent) segments.push_back({current, false});
      const std::size_t close = path.find(']', i);
      if (close == std::string::npos) fail("unclosed '[' in the key path \"", detail::shorten(path, 80), "\"");
      Segment index{path.substr(i + 1, close - i - 1), true};
      if (!index.isNumber())
        fail("\"[", detail::shorten(index.text), "]\" in the key path is not an array index (a number)");
      segments.push_back(index);
      current.clear();
      haveCurrent = false;
      i = close;
      if (i + 1 < path.size() && path[i + 1] == '.') ++i;  // "[0].name"
    } else {
      current += c;
      haveCurrent = true;
    }
  }
  if (haveCurrent) segments.push_back({current, false});
  else if (!path.empty() && path.back() == '.') fail("the key path \"", detail::shorten(path, 80), "\" ends with a dot");
  return segments;
}

void applyOne(json& root, const std::string& text, const std::string& prefix) {
  const OverrideError fail(prefix, text);
  const std::size_t eq = text.find('=');
  if (eq == std::string::npos) fail("expected key.path=value (no '=' found)");
  std::string path = text.substr(0, eq);
  while (!path.empty() && std::isspace(static_cast<unsigned char>(path.back()))) path.pop_back();
  while (!path.empty() && std::isspace(static_cast<unsigned char>(path.front()))) path.erase(0, 1);
  if (path.empty()) fail("the key path before '=' is empty");
  const std::string valueText = text.substr(eq + 1);

  // A value that parses as JSON is JSON (numbers, true, "quoted strings", arrays, objects); anything
  // else is a bare string, so `analysis.integrator=backward_euler` needs no shell quoting.
  json value = json::parse(valueText, nullptr, /*allow_exceptions=*/false, /*ignore_comments=*/true);
  if (value.is_discarded()) value = valueText;

  const std::vector<Segment> segments = splitPath(path, fail);
  if (segments.size() > kMaxSegments)
    fail("the key path has ", segments.size(), " segments; no scene key is more than ", kMaxSegments, " deep");
  json* node = &root;
  std::string where;  // key path of *node, for messages
  auto at = [&where] { return where.empty() ? std::string("the top level") : detail::shorten(where, 120); };
  for (std::size_t s = 0; s < segments.size(); ++s) {
    const Segment& seg = segments[s];
    const bool last = s + 1 == segments.size();
    if (node->is_array()) {
      if (!seg.isNumber())
        fail(at(), " is an array: the next segment must be a numeric index (e.g. ", at(), ".0), not \"",
             detail::shorten(seg.text), "\"");
      // More than 9 digits is out of range of any scene array (and of std::stoul on some platforms).
      const std::size_t index = seg.text.size() > 9 ? node->size() + 1 : std::stoul(seg.text);
      if (index >= node->size())
        fail("index ", detail::shorten(seg.text), " is out of range: ", at(), " has ", node->size(),
             node->size() == 1 ? " element" : " elements");
      where = indexPath(where, index);
      node = &(*node)[index];
    } else if (node->is_object()) {
      if (seg.bracketed)
        fail(at(), " is an object, not an array: [", detail::shorten(seg.text), "] cannot index it");
      auto it = node->find(seg.text);
      if (it == node->end()) {
        // A missing intermediate object is created; a missing array cannot be indexed.
        const bool nextIsIndex = !last && segments[s + 1].isNumber();
        if (nextIsIndex)
          fail("index ", detail::shorten(segments[s + 1].text), " is out of range: ",
               detail::shorten(childPath(where, seg.text), 120), " is absent");
        it = node->emplace(seg.text, last ? json() : json::object()).first;
      }
      where = childPath(where, seg.text);
      node = &*it;
    } else {
      fail("cannot go into ", at(), ", which is ", typeName(*node), ", to set \"", detail::shorten(seg.text), "\"");
    }
  }
  *node = std::move(value);
}

}  // namespace

void applyOverrides(json& root, const std::vector<std::string>& overrides, const std::string& messagePrefix) {
  for (const std::string& text : overrides) applyOne(root, text, messagePrefix);
}

}  // namespace corofem::scene
