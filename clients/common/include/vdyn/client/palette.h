// Colours and names every client that draws vehicles shares (the viewer, the Foxglove scenes), so
// that a vehicle and its force arrows look the same in each: one table, read by each client's own
// colour type.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <string_view>

namespace vdyn::client {

// sRGB bytes of a vehicle's paint, by vehicle id: vehicle 1 gets the first, ids cycle through
// the eight. (Vehicle 6 graphite: the periwinkle it was lay within 30 levels of vehicle 1's blue.)
inline constexpr std::array<std::array<std::uint8_t, 3>, 8> kVehiclePalette = {{
    {90, 170, 200}, {150, 110, 210}, {230, 230, 235}, {80, 190, 160},
    {200, 150, 170}, {110, 110, 118}, {170, 190, 110}, {210, 170, 120},
}};

inline constexpr const std::array<std::uint8_t, 3>& VehiclePaint(std::uint32_t vehicle_id) {
  return kVehiclePalette[(vehicle_id + 7) % kVehiclePalette.size()];
}

// The force arrows: one kind per force the paper's model draws, in the legend's order.
enum class ForceKind { kSpring, kDrive, kBrake, kSide, kDrag, kWall };
inline constexpr int kForceKinds = 6;

// sRGB bytes of each kind's arrow (spring green, drive blue, brake red, side yellow, drag magenta,
// wall orange), drawn unlit in exactly these colours, and its legend's name.
inline constexpr std::array<std::array<std::uint8_t, 3>, kForceKinds> kForcePalette = {{
    {40, 200, 60}, {40, 110, 255}, {235, 40, 40}, {255, 210, 0}, {220, 60, 220}, {255, 130, 0},
}};
inline constexpr std::array<std::string_view, kForceKinds> kForceLabels = {
    "spring Fp", "drive Fh", "brake Fb", "side Fy", "drag Da", "wall",
};

inline constexpr const std::array<std::uint8_t, 3>& ForcePaint(ForceKind kind) {
  return kForcePalette[static_cast<std::size_t>(kind)];
}
inline constexpr std::string_view ForceLabel(ForceKind kind) {
  return kForceLabels[static_cast<std::size_t>(kind)];
}

// The wheels' names (LF, RF, LR, RR), "body" for any other index (a force on the body).
inline constexpr std::string_view WheelName(int wheel) {
  constexpr std::array<std::string_view, 4> kNames = {"LF", "RF", "LR", "RR"};
  return wheel >= 0 && wheel < 4 ? kNames[static_cast<std::size_t>(wheel)] : "body";
}

}  // namespace vdyn::client
