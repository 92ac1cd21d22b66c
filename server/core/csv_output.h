// The batch CSV: one row per step (or every Nth), every computed quantity, units in the header.
#pragma once

#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include "simulator.h"

namespace vdyn {

// The column names, in order (docs/formats.md explains each).
std::vector<std::string> CsvColumns();

class CsvWriter {
 public:
  // Opens `path` for writing (creating parent folders). Throws std::runtime_error with the reason.
  explicit CsvWriter(const std::filesystem::path& path);
  ~CsvWriter();
  CsvWriter(const CsvWriter&) = delete;
  CsvWriter& operator=(const CsvWriter&) = delete;

  void WriteRow(const StepRecord& r);
  // Flushes and closes; throws std::runtime_error when the data did not all reach the file.
  void Close();
  std::size_t rows() const { return rows_; }

 private:
  std::FILE* file_ = nullptr;
  std::filesystem::path path_;
  std::vector<char> buffer_;
  std::size_t rows_ = 0;
};

}  // namespace vdyn
