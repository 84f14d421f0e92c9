// probes.csv: a CSV table written row by row, every write checked, with RFC 4180 quoting of names
// and no non-finite number in it.
#pragma once

#include <cstddef>
#include <cstdio>
#include <string>
#include <string_view>
#include <vector>

namespace corofem::detail {

/// `text` as one CSV field: quoted, with quotes doubled, when it holds a comma, a quote or a line
/// break (RFC 4180); as it is otherwise.
std::string csvField(std::string_view text);

/// A CSV file opened for writing. Each row is written and flushed at once, so a run killed between
/// rows leaves whole rows; a write that fails (a full disk, a file gone) throws IoError naming the
/// file and the reason instead of leaving a cut table behind.
class CsvFile {
 public:
  CsvFile() = default;
  CsvFile(const CsvFile&) = delete;
  CsvFile& operator=(const CsvFile&) = delete;
  ~CsvFile();

  /// Creates (or truncates) the file and writes the header row. Throws IoError when it cannot.
  void open(const std::string& path, const std::vector<std::string>& columns);

  /// Starts a row; add the fields, then end it.
  void beginRow() { row_.clear(); }
  void add(long long value);
  /// A finite value is written with 10 significant digits; a NaN or an infinity is not written (the
  /// cell stays empty) and is counted, with the first one's place kept for the run's summary.
  void add(double value, const std::string& where);
  void endRow();

  const std::string& path() const { return path_; }
  std::size_t nonFiniteCount() const { return nonFinite_; }
  const std::string& firstNonFinite() const { return firstNonFinite_; }  ///< "step 0, elastic_energy = inf"

 private:
  void separate() {
    if (!row_.empty()) row_ += ',';
  }
  void write(const std::string& text);

  std::FILE* file_ = nullptr;
  std::string path_;
  std::vector<std::string> columns_;
  std::string row_;
  std::size_t nonFinite_ = 0;
  std::string firstNonFinite_;
};

}  // namespace corofem::detail
