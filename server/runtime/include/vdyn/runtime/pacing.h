// Pacing of the real-time loop: lateness statistics that fill without allocating (the 1 kHz
// thread records, the reporter thread computes). Its scheduling: base/scheduling.h.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace vdyn {

// Lateness samples of one reporting window (microseconds) in a fixed array; beyond its capacity
// only the maximum is kept. Percentile() sorts in place (call it off the real-time thread).
class LatenessWindow {
 public:
  static constexpr int kCapacity = 8192;
  void Add(float us) {
    if (us > max_) max_ = us;
    if (n_ < kCapacity) samples_[n_++] = us;
    ++count_;
  }
  int size() const { return n_; }
  std::uint64_t count() const { return count_; }
  // p in [0, 100]; 0 for an empty window.
  double Percentile(double p);
  double Max() const { return static_cast<double>(max_); }
  void Clear() {
    n_ = 0;
    count_ = 0;
    max_ = 0.0f;
  }

 private:
  std::array<float, kCapacity> samples_{};
  int n_ = 0;
  std::uint64_t count_ = 0;
  float max_ = 0.0f;
};

// A histogram of durations in 1 us bins up to 100 ms (and one overflow bin): fixed memory for
// runs of any length, exact percentiles to 1 us. Add() does not allocate.
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

}  // namespace vdyn
