// A fast tokenizer over a whole text file held in memory, with line tracking, for the mesh readers.
// Numbers are parsed with std::from_chars (libstdc++ 12 uses the fast_float algorithm for double),
// never with iostreams. Every error names the file and the line, and, where the reader set one, the
// record being read ("node 17 of 354").
#pragma once

#include "util/error.hpp"

#include <corofem/mesh.hpp>

#include <charconv>
#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

namespace corofem::mesh {

/// Reads the whole mesh file into a string (readInputFile: regular files only, at most
/// limits.maxInputBytes). Throws IoError naming the path when it cannot be read, BadInput when it is
/// not a regular file or too large.
std::string readWholeFile(const std::string& path, const InputLimits& limits);

/// Lower-case extension with the dot (".msh"), or "" when the name has none.
std::string lowerExtension(const std::string& path);

class TextScanner {
 public:
  TextScanner(const std::string& text, std::string path)
      : begin_(text.data()), p_(text.data()), end_(text.data() + text.size()), path_(std::move(path)) {}

  /// Characters after which the rest of a line is a comment ('#' for TetGen, Medit, Vega, OBJ), or 0.
  void setCommentChar(char c) { comment_ = c; }

  /// What the reader is reading now, for error messages: "node", 17, 354 -> "node 17 of 354".
  void setContext(const char* what, std::int64_t index = -1, std::int64_t count = -1) {
    what_ = what;
    index_ = index;
    count_ = count;
  }

  const std::string& path() const { return path_; }
  std::size_t line() const { return line_; }
  std::size_t bytesRemaining() const { return static_cast<std::size_t>(end_ - p_); }
  const char* position() const { return p_; }

  /// Skips blanks, newlines and comments.
  void skipSpace() {
    while (p_ < end_) {
      const char c = *p_;
      if (c == '\n') {
        ++line_;
        ++p_;
      } else if (c == ' ' || c == '\t' || c == '\r' || c == '\f' || c == '\v') {
        ++p_;
      } else if (c == comment_ && c != 0) {
        while (p_ < end_ && *p_ != '\n') ++p_;
      } else {
        return;
      }
    }
  }

  /// Skips blanks (not newlines) and a trailing comment; true when the line (or file) ends here.
  bool atLineEnd() {
    skipBlanks();
    if (p_ < end_ && *p_ == comment_ && comment_ != 0)
      while (p_ < end_ && *p_ != '\n') ++p_;
    return p_ >= end_ || *p_ == '\n';
  }

  /// True at the end of the file (after skipping blanks, newlines and comments).
  bool atEnd() {
    skipSpace();
    return p_ >= end_;
  }

  /// Moves past the next newline (or to the end of the file).
  void skipLine() {
    while (p_ < end_ && *p_ != '\n') ++p_;
    if (p_ < end_) {
      ++p_;
      ++line_;
    }
  }

  /// Moves past the next occurrence of marker (counting lines); false when there is none.
  bool skipPast(std::string_view marker);

  /// Requires that nothing but blanks or a comment follows on the current line.
  void expectLineEnd() {
    if (!atLineEnd()) fail("unexpected '", peekRaw(), "' after the end of ", context(), "; expected the end of the line");
  }

  /// Next whitespace-delimited token (crossing newlines); empty at the end of the file.
  std::string_view token() {
    skipSpace();
    const char* start = p_;
    while (p_ < end_ && !isSpace(*p_)) ++p_;
    return {start, static_cast<std::size_t>(p_ - start)};
  }

  /// Next token without consuming it.
  std::string_view peekToken() {
    skipSpace();
    const char* q = p_;
    while (q < end_ && !isSpace(*q)) ++q;
    return {p_, static_cast<std::size_t>(q - p_)};
  }

  /// Next token on the current line; empty when the line ends first.
  std::string_view tokenOnLine() {
    if (atLineEnd()) return {};
    const char* start = p_;
    while (p_ < end_ && !isSpace(*p_)) ++p_;
    return {start, static_cast<std::size_t>(p_ - start)};
  }

  /// Rest of the current line without its leading/trailing blanks; moves past the newline.
  std::string_view restOfLine() {
    skipBlanks();
    const char* start = p_;
    while (p_ < end_ && *p_ != '\n') ++p_;
    const char* stop = p_;
    while (stop > start && isSpace(stop[-1])) --stop;
    skipLine();
    return {start, static_cast<std::size_t>(stop - start)};
  }

  /// Integer, crossing newlines. Errors: end of file (truncated), malformed token.
  std::int64_t readInt() {
    skipSpace();
    return parseInt();
  }

  /// Integer on the current line only: a line with too few values is an error, not a silent read
  /// of the next line.
  std::int64_t readIntOnLine() {
    if (atLineEnd()) failShortLine();  // (or failEof at the end of the file)
    return parseInt();
  }

  /// Double, crossing newlines.
  double readDouble() {
    skipSpace();
    return parseDouble();
  }

  /// Double on the current line only.
  double readDoubleOnLine() {
    if (atLineEnd()) failShortLine();  // (or failEof at the end of the file)
    return parseDouble();
  }

  /// x y z of a node; NaN or infinite coordinates are errors naming the node (its file id). With
  /// sameLine the three values must share the current line.
  void readPoint(double* xyz, std::int64_t nodeId, bool sameLine) {
    for (int k = 0; k < 3; ++k) {
      xyz[k] = sameLine ? readDoubleOnLine() : readDouble();
      if (!(xyz[k] - xyz[k] == 0)) failNonFinite(nodeId, k, xyz[k]);  // false for NaN and +-Inf
    }
  }

  /// A count from a header, checked against what the file can still hold: an entry needs at least
  /// minBytesPerEntry bytes, so a count above bytesRemaining / minBytesPerEntry cannot be right
  /// (truncated file or corrupt header). Returns the count; callers may reserve it safely.
  std::size_t readCount(const char* what, std::size_t minBytesPerEntry);

  /// Checks a count read by other means in the same way as readCount.
  void checkCount(std::int64_t count, const char* what, std::size_t minBytesPerEntry);

  /// Builds "file P line L: parts" and throws BadInput.
  template <class... Parts>
  [[noreturn]] void fail(const Parts&... parts) const {
    detail::fail(ErrorCode::BadInput, "file ", path_, " line ", line_, ": ", parts...);
  }

  /// "node 17 of 354" from the context, or "the header" when none is set.
  std::string context() const;

  bool isEndOfToken(char c) const { return isSpace(c) || (c == comment_ && c != 0); }

  static bool isSpace(char c) { return c == ' ' || c == '\t' || c == '\n' || c == '\r' || c == '\f' || c == '\v'; }

 private:
  void skipBlanks() {
    while (p_ < end_ && (*p_ == ' ' || *p_ == '\t' || *p_ == '\r' || *p_ == '\f' || *p_ == '\v')) ++p_;
  }

  std::string peekRaw() const;  // the token at p_, shortened, for messages

  std::int64_t parseInt() {
    if (p_ >= end_) failEof();
    const char* q = p_;
    if (*q == '+') ++q;
    std::int64_t v = 0;
    auto [ptr, ec] = std::from_chars(q, end_, v);
    if (ec != std::errc() || (ptr < end_ && !isEndOfToken(*ptr))) failNumber("an integer");
    p_ = ptr;
    return v;
  }

  double parseDouble() {
    if (p_ >= end_) failEof();
    const char* q = p_;
    if (*q == '+') ++q;
    double v = 0;
    auto [ptr, ec] = std::from_chars(q, end_, v);
    if (ec == std::errc::result_out_of_range) failNumber("a finite number (this one is out of the double range)");
    if (ec != std::errc() || (ptr < end_ && !isEndOfToken(*ptr))) failNumber("a number");
    p_ = ptr;
    return v;
  }

  [[noreturn]] void failEof() const;
  [[noreturn]] void failShortLine() const;
  [[noreturn]] void failNumber(const char* expected) const;
  [[noreturn]] void failNonFinite(std::int64_t nodeId, int component, double value) const;

  const char* begin_;
  const char* p_;
  const char* end_;
  std::string path_;
  std::size_t line_ = 1;
  char comment_ = 0;
  const char* what_ = nullptr;
  std::int64_t index_ = -1, count_ = -1;
};

}  // namespace corofem::mesh
