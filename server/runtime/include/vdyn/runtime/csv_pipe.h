// The batch CSV's rows: made from a step's record, written on a second thread (CsvPipe).
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <exception>
#include <mutex>
#include <thread>
#include <vector>

#include "vdyn/io/csv.h"
#include "vdyn/physics/simulator.h"
#include "vdyn/state.pb.h"

namespace vdyn {

// A step's CSV row, made from the state message as the recorder's export makes it (one table of
// columns for both). Holds its message objects: one per thread, no allocation per row.
class CsvRowFormatter {
 public:
  explicit CsvRowFormatter(std::int64_t step_ns) : step_ns_(step_ns) {}
  // Writes the row of `r` at `out` (CsvRowMaxBytes()) and returns its length.
  std::size_t Format(const StepRecord& r, char* out);
  // Writes the row of `r` to `csv` (on the calling thread).
  void Write(const StepRecord& r, CsvWriter& csv);

 private:
  const pb::VehicleState& Message(const StepRecord& r);

  std::int64_t step_ns_;
  pb::VehicleState row_;
  pb::DriverInput input_msg_;
};

// The CSV on a second thread. The stepping thread Push()es each record into a ring of fixed
// slots (allocated once) and goes on; the writer formats the rows in order and writes them.
// Formatting a row costs more than a step, so when `format_here_from` or more rows wait, the
// stepping thread formats the row itself into its slot (the writer then only writes it): the two
// threads share the work in whatever proportion this machine needs, and the bytes are the same
// whoever formats. A side that finds the ring empty (writer) or full (stepping thread) sleeps
// until a batch of kWake rows (or room for them) is there: woken once per batch, never spinning.
class CsvPipe {
 public:
  static constexpr std::uint64_t kSlots = 64;
  static constexpr std::uint64_t kWake = 16;

  CsvPipe(CsvWriter& csv, std::int64_t step_ns, std::uint64_t format_here_from = kSlots / 2);
  CsvPipe(const CsvPipe&) = delete;
  CsvPipe& operator=(const CsvPipe&) = delete;
  ~CsvPipe();  // joins the writer; rows pushed and not yet written are written first

  // The stepping thread's side: queues the row of `r` (after a failed write: drops it).
  void Push(const StepRecord& r);
  // Waits for every pushed row to be written; rethrows what the writer threw.
  void Finish();
  // Rows the stepping thread formatted itself (read after Finish()).
  std::uint64_t rows_formatted_by_pusher() const { return formatted_by_pusher_; }

 private:
  char* Line(std::size_t slot) { return lines_.data() + slot * line_bytes_; }
  void Join();
  void Run();

  CsvWriter& csv_;
  const std::size_t line_bytes_;
  const std::uint64_t format_here_from_;
  CsvRowFormatter pusher_rows_;  // used by the stepping thread only
  CsvRowFormatter writer_rows_;  // used by the writer only
  std::uint64_t formatted_by_pusher_ = 0;
  std::vector<StepRecord> records_;
  std::vector<char> lines_;               // kSlots rows of line_bytes_
  std::vector<std::size_t> line_length_;  // 0: the slot holds a record to format
  // Sequentially consistent where not said otherwise: a side sets its *_waiting_ flag and then
  // reads the other's counter; the other stores its counter and then reads the flag. A slot
  // (record or line and its length) is published by the head_ store that follows its writing.
  std::atomic<std::uint64_t> head_{0};  // rows pushed (stepping thread)
  std::atomic<std::uint64_t> tail_{0};  // rows written (writer)
  std::atomic<bool> writer_waiting_{false};
  std::atomic<bool> pusher_waiting_{false};
  std::atomic<bool> done_{false};
  std::atomic<bool> failed_{false};
  std::mutex mutex_;
  std::condition_variable rows_ready_;
  std::condition_variable room_;
  std::exception_ptr error_;
  std::thread thread_;  // last: starts when everything above exists
};

}  // namespace vdyn
