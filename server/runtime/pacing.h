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

// A histogram of durations in 1 us bins up to 100 ms (and one overflow bin): fixed memory for
// runs of any length, exact percentiles to 1 us.
class Histogram {
 public:
  void Add(double us);
  std::uint64_t count() const { return count_; }
  double Percentile(double p) const;  // us; the overflow bin reads as max
  double Max() const { return max_us_; }
  double Mean() const { return count_ ? sum_us_ / static_cast<double>(count_) : 0.0; }
  // Fraction of samples below `us`.
  double FractionBelow(double us) const;

 private:
  static constexpr int kBins = 100'000;
  std::vector<std::uint64_t> bins_ = std::vector<std::uint64_t>(kBins + 1, 0);
  std::uint64_t count_ = 0;
  double sum_us_ = 0, max_us_ = 0;
};

// CPU time of this process (user + system), ns.
std::int64_t ProcessCpuNs();

}  // namespace vdyn
