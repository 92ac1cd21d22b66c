// Pacing of the real-time loop: absolute deadlines on the monotonic clock, lateness statistics,
// and the scheduling the process could get.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace vdyn {

std::int64_t MonotonicNowNs();
// Sleeps until the absolute monotonic time t_ns (returns at once when it has passed).
void SleepUntilNs(std::int64_t t_ns);

// Asks for SCHED_FIFO at `priority` for the calling thread; falls back to SCHED_OTHER with a
// 1 ns timer slack. Returns a line saying which (for the log and the diagnostics).
std::string SetUpRealtimeScheduling(int priority);

// Lateness samples of one reporting window (microseconds), and its percentiles.
class LatenessWindow {
 public:
  LatenessWindow() { samples_.reserve(4096); }
  void Add(double us) { samples_.push_back(us); }
  std::size_t size() const { return samples_.size(); }
  // p in [0, 100]; 0 for an empty window. Sorts the samples (call once per window).
  double Percentile(double p);
  double Max() const;
  void Clear() {
    samples_.clear();
    sorted_ = false;
  }
  const std::vector<double>& samples() const { return samples_; }

 private:
  std::vector<double> samples_;
  bool sorted_ = false;
};

// CPU time of this process (user + system), ns.
std::int64_t ProcessCpuNs();

}  // namespace vdyn
