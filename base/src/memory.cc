#include "vdyn/base/memory.h"

#include <malloc.h>

#include <algorithm>
#include <climits>

namespace vdyn::base {

bool KeepFreedMemory(std::size_t mmap_from, std::size_t trim_above) {
  // mallopt takes an int; glibc refuses a mapping threshold above 32 MiB (the header says so).
  const auto as_int = [](std::size_t v) {
    return static_cast<int>(std::min<std::size_t>(v, INT_MAX));
  };
  const bool mmap_ok = mallopt(M_MMAP_THRESHOLD, as_int(mmap_from)) == 1;
  const bool trim_ok = mallopt(M_TRIM_THRESHOLD, as_int(trim_above)) == 1;
  return mmap_ok && trim_ok;
}

}  // namespace vdyn::base
