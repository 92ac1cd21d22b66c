#include "vdyn/runtime/pacing.h"

#include <algorithm>
#include <cmath>

namespace vdyn {

double LatenessWindow::Percentile(double p) {
  if (n_ == 0) return 0.0;
  std::sort(samples_.begin(), samples_.begin() + n_);
  const double rank = std::clamp(p, 0.0, 100.0) / 100.0 * static_cast<double>(n_ - 1);
  return samples_[static_cast<std::size_t>(std::llround(rank))];
}

void Histogram::Add(double us) {
  const double v = std::max(0.0, us);
  const auto bin = static_cast<std::size_t>(std::min(v, static_cast<double>(kBins)));
  ++bins_[bin];
  ++count_;
  sum_us_ += v;
  max_us_ = std::max(max_us_, v);
}

double Histogram::Percentile(double p) const {
  if (count_ == 0) return 0.0;
  const auto rank = static_cast<std::uint64_t>(
      std::ceil(std::clamp(p, 0.0, 100.0) / 100.0 * static_cast<double>(count_)));
  std::uint64_t seen = 0;
  for (std::size_t i = 0; i < bins_.size(); ++i) {
    seen += bins_[i];
    if (seen >= std::max<std::uint64_t>(rank, 1)) {
      return i == bins_.size() - 1 ? max_us_ : static_cast<double>(i) + 0.5;
    }
  }
  return max_us_;
}

double Histogram::FractionBelow(double us) const {
  if (count_ == 0) return 1.0;
  std::uint64_t below = 0;
  const auto limit = static_cast<std::size_t>(std::clamp(us, 0.0, static_cast<double>(kBins)));
  for (std::size_t i = 0; i < limit; ++i) below += bins_[i];
  return static_cast<double>(below) / static_cast<double>(count_);
}

}  // namespace vdyn
