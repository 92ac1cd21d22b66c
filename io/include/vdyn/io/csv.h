// The vehicle CSV: one row per state, every computed quantity, units in the header. Written from
// the vdyn.pb.VehicleState message, so the batch run (vdyn-server --batch) and the recorder's
// export give the same columns, units and order, and one analysis script reads both.
#pragma once

#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include "vdyn/state.pb.h"

namespace vdyn {

// The column names, in order (docs/formats.md explains each).
std::vector<std::string> CsvColumns();

// The values of one row, in column order (what WriteRow prints).
void CsvRowValues(const pb::VehicleState& s, std::vector<double>& out);

// Writes v at p as a CSV cell writes it, returns the end: the shortest decimal form that reads
// back exactly (as std::to_chars writes it), "0" for either zero. `end - p` must be at least 32
// (with kShortestDoubleBytes it takes the fast path).
char* CsvNumber(char* p, char* end, double v);

// The bytes FormatCsvRow needs (kShortestDoubleBytes a cell).
std::size_t CsvRowMaxBytes();
// Writes the row of `s` (cells, commas, the closing newline) at `out`, which has CsvRowMaxBytes(),
// and returns its length: what CsvWriter::WriteRow writes, for a writer on another thread.
std::size_t FormatCsvRow(const pb::VehicleState& s, char* out);

class CsvWriter {
 public:
  // Opens `path` for writing (creating parent folders). Throws std::runtime_error with the reason.
  explicit CsvWriter(const std::filesystem::path& path);
  ~CsvWriter();
  CsvWriter(const CsvWriter&) = delete;
  CsvWriter& operator=(const CsvWriter&) = delete;

  void WriteRow(const pb::VehicleState& s);
  // Writes a row FormatCsvRow made.
  void WriteFormattedRow(const char* row, std::size_t length);
  // Flushes and closes; throws std::runtime_error when the data did not all reach the file.
  void Close();
  std::size_t rows() const { return rows_; }

 private:
  std::FILE* file_ = nullptr;
  std::filesystem::path path_;
  std::vector<char> buffer_;
  std::vector<char> row_;  // CsvRowMaxBytes()
  std::size_t rows_ = 0;
};

}  // namespace vdyn
