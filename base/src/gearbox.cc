#include "vdyn/base/gearbox.h"

#include <cmath>

namespace vdyn::base {

double GearRatioStep(double first, double top, int count) {
  return count > 1 ? std::pow(top / first, 1.0 / (count - 1)) : 1.0;
}

double ForwardGearRatio(double first, double top, int count, int gear) {
  return gear == count ? top : first * std::pow(GearRatioStep(first, top, count), gear - 1);
}

}  // namespace vdyn::base
