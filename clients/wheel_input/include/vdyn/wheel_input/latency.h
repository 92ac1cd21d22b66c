// A latency histogram that never allocates after construction (the rig loop adds to it every
// tick): 1 us buckets up to 50 ms, the rest counted above, the largest kept exactly.
#pragma once

#include <array>
#include <cstdint>

#include "vdyn/base/time.h"

namespace vdyn::wheel_input {

class LatencyHistogram {
 public:
  void Add(base::Nanos d);
  void Clear();
  std::uint64_t count() const { return count_; }
  // The upper edge of the bucket holding the p-th percentile (0 < p <= 100), us; 0 when empty.
  double PercentileUs(double p) const;
  double MaxUs() const { return static_cast<double>(max_ns_) * 1e-3; }

 private:
  static constexpr int kBuckets = 50'000;  // 1 us each
  std::array<std::uint32_t, kBuckets> buckets_{};
  std::uint64_t above_ = 0;
  std::uint64_t count_ = 0;
  std::int64_t max_ns_ = 0;
};

}  // namespace vdyn::wheel_input
