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
    detail::fail(ErrorCode::BadInput, prefix_, "--set \"", text_, "\": ", parts...);
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
      if (!haveCurrent) fail("empty segment in the key path \"", path, "\" (two dots, or a leading dot)");
      segments.push_back({current, false});
      current.clear();
      haveCurrent = false;
      // a '.' right after "]" (bodies[0].name) separates nothing new
    } else if (c == '[') {
      if (haveCurrent) segments.push_back({current, false});
      const std::size_t close = path.find(']', i);
      if (close == std::string::npos) fail("unclosed '[' in the key path \"", path, "\"");
      Segment index{path.substr(i + 1, close - i - 1), true};
      if (!index.isNumber()) fail("\"[", index.text, "]\" in the key path is not an array index (a number)");
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
  else if (!path.empty() && path.back() == '.') fail("the key path \"", path, "\" ends with a dot");
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
  json* node = &root;
  std::string where;  // key path of *node, for messages
  for (std::size_t s = 0; s < segments.size(); ++s) {
    const Segment& seg = segments[s];
    const bool last = s + 1 == segments.size();
    if (node->is_array()) {
      if (!seg.isNumber())
        fail(where, " is an array: the next segment must be a numeric index (e.g. ", where, ".0), not \"",
             seg.text, "\"");
      // More than 9 digits is out of range of any scene array (and of std::stoul on some platforms).
      const std::size_t index = seg.text.size() > 9 ? node->size() + 1 : std::stoul(seg.text);
      if (index >= node->size())
        fail("index ", seg.text, " is out of range: ", where, " has ", node->size(),
             node->size() == 1 ? " element" : " elements");
      where = indexPath(where, index);
      node = &(*node)[index];
    } else if (node->is_object()) {
      if (seg.bracketed)
        fail(where.empty() ? "the top level" : where, " is an object, not an array: [", seg.text,
             "] cannot index it");
      auto it = node->find(seg.text);
      if (it == node->end()) {
        // A missing intermediate object is created; a missing array cannot be indexed.
        const bool nextIsIndex = !last && segments[s + 1].isNumber();
        if (nextIsIndex) fail("index ", segments[s + 1].text, " is out of range: ", childPath(where, seg.text),
                              " is absent");
        it = node->emplace(seg.text, last ? json() : json::object()).first;
      }
      where = childPath(where, seg.text);
      node = &*it;
    } else {
      fail("cannot go into ", where, ", which is ", typeName(*node), ", to set \"", seg.text, "\"");
    }
  }
  *node = std::move(value);
}

}  // namespace

void applyOverrides(json& root, const std::vector<std::string>& overrides, const std::string& messagePrefix) {
  for (const std::string& text : overrides) applyOne(root, text, messagePrefix);
}

}  // namespace corofem::scene
