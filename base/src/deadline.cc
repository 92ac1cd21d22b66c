#include "vdyn/base/deadline.h"

#include <cmath>

namespace vdyn::base {

namespace {
constexpr std::int64_t kMax = std::numeric_limits<std::int64_t>::max();
}  // namespace

Deadline Deadline::After(Nanos d, MonoTime now) {
  const std::int64_t add = std::max<std::int64_t>(d.ns, 0);
  if (add >= kMax - now.ns) return Never();
  return Deadline(MonoTime{now.ns + add});
}

Deadline Deadline::AfterSeconds(double seconds, MonoTime now) {
  if (!(seconds > 0)) return Deadline(now);  // 0, negative and NaN: now
  // 2^63 ns is 292 years: a longer wait is a wait without end.
  if (seconds * 1e9 >= static_cast<double>(kMax - now.ns)) return Never();
  return After(FromSeconds(seconds), now);
}

Nanos Deadline::Left(MonoTime now) const {
  if (never()) return Nanos{kMax};
  return Nanos{std::max<std::int64_t>(at_.ns - now.ns, 0)};
}

}  // namespace vdyn::base
