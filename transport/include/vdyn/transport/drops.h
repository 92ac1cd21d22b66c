// Counters of what was dropped or refused, by kind ("malformed payload on vdyn/input"), with the
// last detail of each kind ("steer"). Counting is lock-free and allocation-free once a kind has
// been seen (register the kinds a real-time thread counts beforehand): the 1 kHz loop may count.
// Logging is separate: each kind is logged once, then at most every 10 s with the count since its
// last line, so a flood of bad input cannot flood the log. In the default mode Count() logs when
// due; with `deferred` only Report() does, from a thread that may log.
#pragma once

#include <array>
#include <atomic>
#include <cstdint>
#include <map>
#include <mutex>
#include <string>
#include <string_view>

namespace vdyn::transport {

class DropCounters {
 public:
  explicit DropCounters(bool deferred = false) : deferred_(deferred) {}
  DropCounters(const DropCounters&) = delete;
  DropCounters& operator=(const DropCounters&) = delete;

  // The slot of a kind, created when new (takes a lock and may allocate: not on the 1 kHz thread).
  int Register(std::string_view kind);
  // Counts one drop of a registered kind: lock-free, no allocation, no logging when deferred.
  void Count(int slot, std::string_view detail = {});
  // Counts by name (registering a new kind).
  void Count(std::string_view kind, std::string_view detail = {});
  // Logs every kind whose count grew and whose last line is 10 s old (or that was never logged).
  void Report();

  std::map<std::string, std::uint64_t> Snapshot() const;
  std::uint64_t Total() const;
  std::uint64_t Of(std::string_view kind) const;

  static constexpr int kMaxKinds = 128;

 private:
  struct Slot {
    std::string name;                    // written once, before `used_` publishes the slot
    std::atomic<std::uint64_t> count{0};
    std::atomic<bool> detail_busy{false};
    char detail[160] = {};
    std::uint64_t logged = 0;            // Report()'s side, under report_mu_
    std::int64_t last_log_ns = 0;
  };
  int Find(std::string_view kind) const;
  void MaybeLog(Slot& s, std::int64_t now_ns);

  bool deferred_;
  std::array<Slot, kMaxKinds> slots_;
  std::atomic<int> used_{0};
  std::mutex register_mu_;
  std::mutex report_mu_;
  std::atomic<std::uint64_t> overflow_{0};  // drops of kinds beyond kMaxKinds
};

}  // namespace vdyn::transport
