// The full model's gearbox ratios (docs/model.md, section 8), in one place for the two that need
// them: the physics, which turns the engine with them, and a rig (vdyn-input), which refuses a
// shift that would turn the engine past its limit. Forward gears 1..count run in geometric
// progression from `first` to `top`.
#pragma once

namespace vdyn::base {

// The ratio between neighbouring forward gears, (top / first)^(1 / (count - 1)); 1 for one gear.
double GearRatioStep(double first, double top, int count);
// The ratio of forward gear `gear` (1..count): first * step^(gear - 1); the top gear is `top`.
double ForwardGearRatio(double first, double top, int count, int gear);

}  // namespace vdyn::base
