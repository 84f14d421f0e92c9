// Scene JSON text: parse errors with their position, numbers out of the double range, duplicate keys.
//
// The JSON library's messages are taken apart by hand (no std::regex: libstdc++'s regex recurses
// once per character matched and overflows the stack on a long token), and the token they quote is
// shortened.
#include "scene/json_text.hpp"

#include "scene/json_path.hpp"
#include "util/error.hpp"

#include <charconv>
#include <set>
#include <string_view>
#include <utility>
#include <vector>

namespace corofem::scene {

namespace {

using nlohmann::json;

/// Objects and arrays may nest this deep (a scene needs 6 levels). Deeper, the parsed document would
/// take memory in proportion: 50 MB of "[" ran out of memory ("internal error").
constexpr std::size_t kMaxDepth = 64;

/// Parser callback that records the first key repeated within one object (JSON parsers silently
/// keep the last value, which hides a typo'd copy-paste), with its key path, and stops the parse
/// at objects or arrays nested deeper than kMaxDepth.
class DuplicateKeyFinder {
 public:
  explicit DuplicateKeyFinder(const std::string& prefix) : prefix_(prefix) {}

  bool operator()(int /*depth*/, json::parse_event_t event, json& parsed) {
    if ((event == json::parse_event_t::object_start || event == json::parse_event_t::array_start) &&
        stack_.size() >= kMaxDepth)
      detail::fail(ErrorCode::BadInput, prefix_, detail::shorten(currentPath(), 120),
                   ": objects and arrays nest more than ", kMaxDepth,
                   " levels deep here; a scene nests 6 at most, so look for brackets that are not closed");
    switch (event) {
      case json::parse_event_t::object_start: stack_.emplace_back(); break;
      case json::parse_event_t::array_start: stack_.emplace_back().array = true; break;
      case json::parse_event_t::key: {
        Frame& top = stack_.back();
        top.key = parsed.get<std::string>();
        if (!top.keys.insert(top.key).second && duplicate_.empty()) duplicate_ = currentPath();
        break;
      }
      case json::parse_event_t::object_end:
      case json::parse_event_t::array_end:
        stack_.pop_back();
        afterValue();
        break;
      case json::parse_event_t::value: afterValue(); break;
    }
    return true;
  }
  const std::string& duplicate() const { return duplicate_; }

 private:
  struct Frame {
    bool array = false;
    std::size_t index = 0;
    std::string key;
    std::set<std::string> keys;
  };
  void afterValue() {
    if (!stack_.empty() && stack_.back().array) ++stack_.back().index;
  }
  std::string currentPath() const {
    std::string path;
    for (const Frame& f : stack_) path = f.array ? indexPath(path, f.index) : childPath(path, f.key);
    return path;
  }
  const std::string& prefix_;
  std::vector<Frame> stack_;
  std::string duplicate_;
};

/// Line and column (1-based) of a byte offset.
std::pair<std::size_t, std::size_t> lineColumn(const std::string& text, std::size_t offset) {
  std::size_t line = 1, column = 1;
  for (std::size_t i = 0; i < offset && i < text.size(); ++i) {
    if (text[i] == '\n') {
      ++line;
      column = 1;
    } else {
      ++column;
    }
  }
  return {line, column};
}

/// Reads an unsigned number at the front of s and moves past it.
bool readNumber(std::string_view& s, std::size_t& value) {
  const auto [ptr, ec] = std::from_chars(s.data(), s.data() + s.size(), value);
  if (ec != std::errc() || ptr == s.data()) return false;
  s.remove_prefix(static_cast<std::size_t>(ptr - s.data()));
  return true;
}

bool skip(std::string_view& s, std::string_view prefix) {
  if (s.substr(0, prefix.size()) != prefix) return false;
  s.remove_prefix(prefix.size());
  return true;
}

/// The library's description with the token it quotes ("...; last read: '<token>'", maybe
/// followed by "; expected <what>") shortened: the start of the token and the end of the text are
/// kept. (Where the token ends cannot be told: it may hold "'; expected " itself.)
std::string shortenLastRead(std::string_view description) {
  constexpr std::string_view kLastRead = "last read: '";
  const std::size_t open = description.find(kLastRead);
  if (open == std::string_view::npos) return detail::elideMiddle(description, 150, 50);
  const std::size_t begin = open + kLastRead.size();
  return std::string(description.substr(0, begin)) + detail::elideMiddle(description.substr(begin), 40, 60);
}

bool isNumberChar(char c) {
  return (c >= '0' && c <= '9') || c == '-' || c == '+' || c == '.' || c == 'e' || c == 'E';
}

/// Offset of `literal` where it stands as a whole token in text, or npos. Linear in the text's size:
/// a comparison starting at a token's first character stops within that token.
std::size_t findNumberToken(const std::string& text, std::string_view literal) {
  if (literal.empty()) return std::string::npos;
  for (std::size_t i = 0; i + literal.size() <= text.size(); ++i) {
    if (i > 0 && isNumberChar(text[i - 1])) continue;
    if (std::string_view(text).substr(i, literal.size()) != literal) continue;
    const std::size_t after = i + literal.size();
    if (after == text.size() || !isNumberChar(text[after])) return i;
  }
  return std::string::npos;
}

[[noreturn]] void failParseError(const json::parse_error& e, const std::string& text, const std::string& prefix) {
  // The library's message: "[json.exception.parse_error.101] parse error at line L, column C: <what>".
  const std::string what = e.what();
  std::string_view rest(what);
  const std::size_t at = rest.find("at line ");
  std::size_t line = 0, column = 0;
  if (at != std::string_view::npos) {
    rest.remove_prefix(at + 8);
    if (readNumber(rest, line) && skip(rest, ", column ") && readNumber(rest, column) && skip(rest, ": "))
      detail::fail(ErrorCode::BadInput, prefix, "line ", line, ", column ", column, ": invalid JSON: ",
                   shortenLastRead(rest));
  }
  const auto [l, c] = lineColumn(text, e.byte > 0 ? e.byte - 1 : 0);
  detail::fail(ErrorCode::BadInput, prefix, "line ", l, ", column ", c, ": invalid JSON: ", shortenLastRead(what));
}

[[noreturn]] void failOutOfRange(const json::out_of_range& e, const std::string& text, const std::string& prefix) {
  // A number too large for a double (1e999): "... number overflow parsing '<literal>'". Find the
  // literal in the text to give its position.
  const std::string_view what(e.what());
  constexpr std::string_view kParsing = "parsing '";
  const std::size_t open = what.find(kParsing);
  const std::size_t close = what.rfind('\'');
  if (open != std::string_view::npos && close != std::string_view::npos && close > open + kParsing.size()) {
    const std::string_view literal = what.substr(open + kParsing.size(), close - open - kParsing.size());
    const std::size_t offset = findNumberToken(text, literal);
    if (offset != std::string::npos) {
      const auto [line, column] = lineColumn(text, offset);
      detail::fail(ErrorCode::BadInput, prefix, "line ", line, ", column ", column, ": the number ",
                   detail::shorten(literal), " is too large (numbers must be finite)");
    }
    detail::fail(ErrorCode::BadInput, prefix, "invalid JSON: the number ", detail::shorten(literal),
                 " is too large (numbers must be finite)");
  }
  detail::fail(ErrorCode::BadInput, prefix, "invalid JSON: ", detail::shorten(what, 200));
}

}  // namespace

json parseJsonText(const std::string& text, const std::string& messagePrefix) {
  DuplicateKeyFinder duplicates(messagePrefix);
  json root;
  try {
    root = json::parse(text, std::ref(duplicates), /*allow_exceptions=*/true, /*ignore_comments=*/true);
  } catch (const json::parse_error& e) {
    failParseError(e, text, messagePrefix);
  } catch (const json::out_of_range& e) {
    failOutOfRange(e, text, messagePrefix);
  }
  if (!duplicates.duplicate().empty())
    detail::fail(ErrorCode::BadInput, messagePrefix, duplicates.duplicate(),
                 ": duplicate key (the same key appears twice in one object)");
  return root;
}

void expandShorthands(json& root) {
  if (!root.is_object()) return;
  if (auto it = root.find("backend"); it != root.end() && it->is_string()) *it = json{{"kind", *it}};
  if (auto it = root.find("bodies"); it != root.end() && it->is_array())
    for (json& body : *it)
      if (body.is_object())
        if (auto mesh = body.find("mesh"); mesh != body.end() && mesh->is_string()) *mesh = json{{"file", *mesh}};
}

}  // namespace corofem::scene
