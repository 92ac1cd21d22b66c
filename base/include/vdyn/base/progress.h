// A one-line progress bar on an interactive terminal (stderr); silent otherwise (pipes, logs,
// tests). Shared by vdyn-server's batch runs and vdyn-recorder's long commands.
#pragma once

#include <string>

namespace vdyn::base {

class ProgressBar {
 public:
  // What Finish leaves on the terminal: the full bar on its own line, or nothing (the line is
  // cleared). Either way the bar is silent from then on.
  enum class AtFinish { kKeepLine, kClearLine };
  explicit ProgressBar(std::string label, AtFinish at_finish = AtFinish::kKeepLine);
  ~ProgressBar();
  ProgressBar(const ProgressBar&) = delete;
  ProgressBar& operator=(const ProgressBar&) = delete;
  void Update(double fraction);  // [0, 1]; redraws only when the whole percent changes
  void Finish();

 private:
  std::string label_;
  AtFinish at_finish_;
  bool enabled_;
  int last_percent_ = -1;
};

}  // namespace vdyn::base
