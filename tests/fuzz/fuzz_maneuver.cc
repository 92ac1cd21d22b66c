// Fuzz target: the maneuver CSV parser (io). Any bytes: a maneuver or a ManeuverError, never a
// crash; a parsed maneuver answers At() with values inside the limits.
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <string>

#include "vdyn/base/limits.h"
#include "vdyn/io/maneuver.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  try {
    const vdyn::Maneuver m = vdyn::Maneuver::Parse(text, "fuzz.csv");
    for (double t : {-1.0, 0.0, 0.5 * m.end_time(), m.end_time(), m.end_time() + 1.0}) {
      const vdyn::ManeuverInput in = m.At(t);
      if (!std::isfinite(in.steer) || !std::isfinite(in.throttle) || !std::isfinite(in.brake) ||
          !std::isfinite(in.cruise_speed) || in.throttle > 1.0 || in.throttle < -1.0 ||
          in.brake < 0.0 || in.brake > 1.0) {
        std::abort();  // a parsed maneuver must never yield a value outside its limits
      }
    }
  } catch (const vdyn::ManeuverError&) {
  }
  return 0;
}
