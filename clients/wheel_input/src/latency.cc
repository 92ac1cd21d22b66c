#include "vdyn/wheel_input/latency.h"

#include <algorithm>
#include <cmath>

namespace vdyn::wheel_input {

void LatencyHistogram::Add(base::Nanos d) {
  const std::int64_t ns = std::max<std::int64_t>(d.ns, 0);
  const std::int64_t us = ns / 1000;
  if (us < kBuckets) {
    ++buckets_[static_cast<std::size_t>(us)];
  } else {
    ++above_;
  }
  ++count_;
  max_ns_ = std::max(max_ns_, ns);
}

void LatencyHistogram::Clear() {
  buckets_.fill(0);
  above_ = 0;
  count_ = 0;
  max_ns_ = 0;
}

double LatencyHistogram::PercentileUs(double p) const {
  if (count_ == 0) return 0.0;
  const auto rank = static_cast<std::uint64_t>(
      std::ceil(std::clamp(p, 0.0, 100.0) / 100.0 * static_cast<double>(count_)));
  std::uint64_t seen = 0;
  for (int i = 0; i < kBuckets; ++i) {
    seen += buckets_[static_cast<std::size_t>(i)];
    if (seen >= std::max<std::uint64_t>(rank, 1)) return static_cast<double>(i + 1);
  }
  return MaxUs();
}

}  // namespace vdyn::wheel_input
