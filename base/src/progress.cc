#include "vdyn/base/progress.h"

#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <utility>

namespace vdyn::base {

ProgressBar::ProgressBar(std::string label, AtFinish at_finish)
    : label_(std::move(label)), at_finish_(at_finish), enabled_(isatty(STDERR_FILENO) == 1) {}

ProgressBar::~ProgressBar() {
  Finish();
}

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
  std::fputs(at_finish_ == AtFinish::kKeepLine ? "\n" : "\r\033[K", stderr);
  std::fflush(stderr);
  last_percent_ = -1;
  enabled_ = false;
}

}  // namespace vdyn::base
