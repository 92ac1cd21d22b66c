// The flat built-in world the parameter fuzzers step their simulators on, built once before the
// first input (outside libFuzzer's per-input wall-clock timeout). Each fuzzer is its own program:
// one source of each includes this.
#pragma once

#include <memory>

#include "vdyn/physics/world.h"

namespace vdyn::fuzz {

inline const std::shared_ptr<const World>& FlatWorld() {
  static const std::shared_ptr<const World> world = BuildBuiltinWorld("flat");
  return world;
}

}  // namespace vdyn::fuzz

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  (void)vdyn::fuzz::FlatWorld();
  return 0;
}
