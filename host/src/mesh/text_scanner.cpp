// Whole-file reading and the cold (error) paths of the text scanner.
#include "mesh/text_scanner.hpp"

#include "mesh/input_file.hpp"

#include <algorithm>
#include <limits>
#include <sstream>

namespace corofem::mesh {

std::string readWholeFile(const std::string& path, const InputLimits& limits) {
  return readInputFile(path, "mesh file " + path,
                       "; check the path (relative paths are taken from the working directory)", limits);
}

std::string lowerExtension(const std::string& path) {
  const auto slash = path.find_last_of("/\\");
  const auto dot = path.find_last_of('.');
  if (dot == std::string::npos || (slash != std::string::npos && dot < slash)) return "";
  std::string ext = path.substr(dot);
  for (char& c : ext)
    if (c >= 'A' && c <= 'Z') c = static_cast<char>(c - 'A' + 'a');
  return ext;
}

bool TextScanner::skipPast(std::string_view marker) {
  const std::string_view rest(p_, static_cast<std::size_t>(end_ - p_));
  const auto at = rest.find(marker);
  const char* stop = at == std::string_view::npos ? end_ : p_ + at + marker.size();
  line_ += static_cast<std::size_t>(std::count(p_, stop, '\n'));
  p_ = stop;
  return at != std::string_view::npos;
}

std::string TextScanner::context() const {
  if (!what_) return "the header";
  std::ostringstream os;
  os << what_;
  if (index_ >= 0) os << ' ' << index_;
  if (count_ >= 0) os << " of " << count_;
  return os.str();
}

std::string TextScanner::peekRaw() const {
  const char* q = p_;
  while (q < end_ && !isSpace(*q) && q - p_ < 40) ++q;
  return std::string(p_, q);
}

void TextScanner::failEof() const {
  fail("the file ends while reading ", context(), "; the file is truncated (or a count in it is too large)");
}

void TextScanner::failShortLine() const {
  if (p_ >= end_) failEof();
  fail("the line ends too early while reading ", context(), "; a value is missing");
}

void TextScanner::failNumber(const char* expected) const {
  fail("expected ", expected, " while reading ", context(), ", found '", peekRaw(), "'");
}

void TextScanner::failNonFinite(std::int64_t nodeId, int component, double value) const {
  fail("node ", nodeId, " has a non-finite ", "xyz"[component], " coordinate (", value,
       "); fix the coordinates in the file");
}

void TextScanner::checkCount(std::int64_t count, const char* what, std::size_t minBytesPerEntry) {
  if (count < 0) fail("the number of ", what, " is negative (", count, ")");
  if (count > static_cast<std::int64_t>(std::numeric_limits<std::uint32_t>::max() - 1))
    fail("the file announces ", count, " ", what, ", more than corofem can index (32-bit indices)");
  // An entry takes at least minBytesPerEntry bytes (one character and one separator per value; the
  // last entry may lack its final newline, hence the + 1), so a larger count cannot fit in what
  // remains: fail now instead of allocating for it.
  const std::size_t fits = (bytesRemaining() + 1) / (minBytesPerEntry ? minBytesPerEntry : 1);
  if (static_cast<std::uint64_t>(count) > fits)
    fail("the header announces ", count, " ", what, ", but only ", bytesRemaining(),
         " bytes follow, room for at most ", fits,
         "; the file is truncated or the count is wrong");
}

std::size_t TextScanner::readCount(const char* what, std::size_t minBytesPerEntry) {
  const auto* savedWhat = what_;
  const auto savedIndex = index_, savedCount = count_;
  std::string label = std::string("the number of ") + what;
  setContext(label.c_str());
  const std::int64_t count = readInt();
  setContext(savedWhat, savedIndex, savedCount);
  checkCount(count, what, minBytesPerEntry);
  return static_cast<std::size_t>(count);
}

}  // namespace corofem::mesh
