// Colours every client that draws vehicles shares (the viewer, the Foxglove scenes), so that a
// vehicle looks the same in each: one table, read by each client's own colour type.
#pragma once

#include <array>
#include <cstdint>

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

}  // namespace vdyn::client
