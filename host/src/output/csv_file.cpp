#include "output/csv_file.hpp"

#include "util/error.hpp"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>

namespace corofem::detail {

namespace {
constexpr const char* kLost = "; the rows before this one are in the file (its last line may be incomplete)";
}  // namespace

std::string csvField(std::string_view text) {
  if (text.find_first_of(",\"\r\n") == std::string_view::npos) return std::string(text);
  std::string quoted = "\"";
  for (char c : text) {
    if (c == '"') quoted += '"';
    quoted += c;
  }
  return quoted + '"';
}

CsvFile::~CsvFile() {
  if (file_) std::fclose(file_);
}

void CsvFile::open(const std::string& path, const std::vector<std::string>& columns) {
  path_ = path;
  columns_ = columns;
  file_ = std::fopen(path.c_str(), "w");
  if (!file_) fail(ErrorCode::IoError, "cannot write ", path, ": ", std::strerror(errno));
  std::string header;
  for (const std::string& c : columns) header += (header.empty() ? "" : ",") + csvField(c);
  write(header + '\n');
}

void CsvFile::add(long long value) {
  separate();
  row_ += std::to_string(value);
}

void CsvFile::add(double value, const std::string& where) {
  separate();
  if (!std::isfinite(value)) {
    if (nonFinite_++ == 0) {
      const std::size_t column = static_cast<std::size_t>(std::count(row_.begin(), row_.end(), ','));
      firstNonFinite_ = where + ", " + (column < columns_.size() ? columns_[column] : "?") + " = " +
                        (std::isnan(value) ? "nan" : value > 0 ? "inf" : "-inf");
    }
    return;  // an empty cell
  }
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, "%.10g", value);
  row_ += buffer;
}

void CsvFile::endRow() {
  write(row_ + '\n');
  row_.clear();
}

void CsvFile::write(const std::string& text) {
  if (!file_) fail(ErrorCode::IoError, "cannot write ", path_, ": the file is not open");
  // errno is read right after the call that failed (a later call may change it).
  if (std::fwrite(text.data(), 1, text.size(), file_) != text.size()) {
    const int err = errno;
    fail(ErrorCode::IoError, "cannot write ", path_, ": ", std::strerror(err), kLost);
  }
  if (std::fflush(file_) != 0) {
    const int err = errno;
    fail(ErrorCode::IoError, "cannot write ", path_, ": ", std::strerror(err), kLost);
  }
}

}  // namespace corofem::detail
