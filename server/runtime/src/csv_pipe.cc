#include "vdyn/runtime/csv_pipe.h"

#include <utility>

#include "vdyn/bridge/convert.h"

namespace vdyn {

const pb::VehicleState& CsvRowFormatter::Message(const StepRecord& r) {
  ToProto(r.input, input_msg_);
  FillVehicleState(1, "batch", step_ns_, r.step * step_ns_, r, input_msg_, false,
                   r.derived.steering_torque, row_);
  return row_;
}

std::size_t CsvRowFormatter::Format(const StepRecord& r, char* out) {
  return FormatCsvRow(Message(r), out);
}

void CsvRowFormatter::Write(const StepRecord& r, CsvWriter& csv) { csv.WriteRow(Message(r)); }

CsvPipe::CsvPipe(CsvWriter& csv, std::int64_t step_ns, std::uint64_t format_here_from)
    : csv_(csv),
      line_bytes_(CsvRowMaxBytes()),
      format_here_from_(format_here_from),
      pusher_rows_(step_ns),
      writer_rows_(step_ns),
      records_(kSlots),
      lines_(kSlots * line_bytes_),
      line_length_(kSlots, 0),
      thread_([this] { Run(); }) {}

CsvPipe::~CsvPipe() {
  Join();
}

void CsvPipe::Push(const StepRecord& r) {
  if (failed_.load(std::memory_order_acquire)) return;  // Finish() says why
  const std::uint64_t head = head_.load(std::memory_order_relaxed);
  std::uint64_t queued = head - tail_.load(std::memory_order_acquire);
  if (queued == kSlots) {
    std::unique_lock lock(mutex_);
    pusher_waiting_.store(true);
    room_.wait(lock, [&] { return head - tail_.load() <= kSlots - kWake || failed_.load(); });
    pusher_waiting_.store(false, std::memory_order_relaxed);
    if (failed_.load()) return;
    queued = head - tail_.load();
  }
  const std::size_t slot = head % kSlots;
  if (queued >= format_here_from_) {
    line_length_[slot] = pusher_rows_.Format(r, Line(slot));
    ++formatted_by_pusher_;
  } else {
    records_[slot] = r;
    line_length_[slot] = 0;
  }
  head_.store(head + 1);
  // The writer waits only with the ring empty, so tail_ is where it stopped.
  if (writer_waiting_.load() && head + 1 - tail_.load() >= kWake) {
    std::lock_guard lock(mutex_);
    rows_ready_.notify_one();
  }
}

void CsvPipe::Finish() {
  Join();
  if (error_) std::rethrow_exception(std::exchange(error_, nullptr));
}

void CsvPipe::Join() {
  if (!thread_.joinable()) return;
  {
    std::lock_guard lock(mutex_);
    done_.store(true);
    rows_ready_.notify_one();
  }
  thread_.join();
}

void CsvPipe::Run() {
  try {
    std::uint64_t tail = 0;
    for (;;) {
      const std::uint64_t head = head_.load(std::memory_order_acquire);
      if (head == tail) {
        if (done_.load()) return;
        std::unique_lock lock(mutex_);
        writer_waiting_.store(true);
        rows_ready_.wait(lock, [&] { return head_.load() - tail >= kWake || done_.load(); });
        writer_waiting_.store(false, std::memory_order_relaxed);
        continue;
      }
      for (; tail != head; ++tail) {
        const std::size_t slot = tail % kSlots;
        std::size_t length = line_length_[slot];
        if (length == 0) length = writer_rows_.Format(records_[slot], Line(slot));
        csv_.WriteFormattedRow(Line(slot), length);
        tail_.store(tail + 1);
        // The stepping thread waits only with the ring full, so head_ is where it stopped.
        if (pusher_waiting_.load() && head_.load() - (tail + 1) <= kSlots - kWake) {
          std::lock_guard lock(mutex_);
          room_.notify_one();
        }
      }
    }
  } catch (...) {
    error_ = std::current_exception();
    std::lock_guard lock(mutex_);
    failed_.store(true);
    room_.notify_one();
  }
}

}  // namespace vdyn
