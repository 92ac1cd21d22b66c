// A one-line progress bar on an interactive terminal (stderr); silent otherwise.
#pragma once

#include <string>

namespace vdyn {

class ProgressBar {
 public:
  explicit ProgressBar(std::string label);
  ~ProgressBar();
  void Update(double fraction);
  void Finish();

 private:
  std::string label_;
  bool enabled_;
  int last_percent_ = -1;
};

}  // namespace vdyn
