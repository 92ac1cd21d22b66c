#include "progress.h"

#include <unistd.h>

#include <algorithm>
#include <cstdio>

namespace vdyn {

ProgressBar::ProgressBar(std::string label)
    : label_(std::move(label)), enabled_(isatty(STDERR_FILENO) == 1) {}

ProgressBar::~ProgressBar() { Finish(); }

void ProgressBar::Update(double fraction) {
  if (!enabled_) return;
  const int percent = std::clamp(static_cast<int>(fraction * 100.0), 0, 100);
  if (percent == last_percent_) return;
  last_percent_ = percent;
  constexpr int kWidth = 40;
  const int filled = percent * kWidth / 100;
  std::fprintf(stderr, "\r%s [%.*s%*s] %3d%%", label_.c_str(), filled,
               "########################################", kWidth - filled, "", percent);
  std::fflush(stderr);
}

void ProgressBar::Finish() {
  if (!enabled_ || last_percent_ < 0) return;
  std::fprintf(stderr, "\n");
  last_percent_ = -1;
  enabled_ = false;
}

}  // namespace vdyn
