#include "vdyn/base/memory.h"

#include <malloc.h>

#include <climits>

namespace vdyn::base {

bool KeepFreedMemory(std::size_t mmap_from, std::size_t trim_above) {
  // mallopt takes an int; M_MMAP_THRESHOLD is capped by glibc at 32 MiB on 64-bit (HEAP_MAX/2),
  // a larger value is refused, so clamp to what it accepts.
  const auto clamp = [](std::size_t v, std::size_t most) {
    return static_cast<int>(v < most ? v : most);
  };
  const bool mmap_ok = mallopt(M_MMAP_THRESHOLD, clamp(mmap_from, std::size_t{32} << 20)) == 1;
  const bool trim_ok = mallopt(M_TRIM_THRESHOLD, clamp(trim_above, INT_MAX)) == 1;
  return mmap_ok && trim_ok;
}

}  // namespace vdyn::base
