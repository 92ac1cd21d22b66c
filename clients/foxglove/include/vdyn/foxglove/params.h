// Vehicle parameters as Foxglove parameters: each field of a vehicle's VehicleParams (the
// transient-local topic) by its path, `vehicle/<id>/mass`, `vehicle/<id>/lf/radius`; numbers as
// float64 (whole numbers for counts), enums by their names, and back into a partial
// VehicleParams for a set_params request.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "vdyn/foxglove/protocol.h"
#include "vdyn/vehicle_params.pb.h"

namespace vdyn::foxglove {

// Every field set in `params`, named for vehicle `vehicle_id`.
std::vector<protocol::Parameter> ParametersOf(std::uint32_t vehicle_id,
                                              const pb::VehicleParams& params);

// "vehicle/7/lf/radius" -> vehicle 7, field path "lf/radius"; nullopt for another name.
struct ParameterName {
  std::uint32_t vehicle_id = 0;
  std::string path;
};
std::optional<ParameterName> ParseParameterName(const std::string& name);

// Sets the field at `path` of `params` to `value`; empty when done, else why not (no such
// field, a value of the wrong type, a negative or fractional count, an unknown enum name).
std::string SetParameter(pb::VehicleParams& params, const std::string& path,
                         const protocol::ParameterValue& value);

}  // namespace vdyn::foxglove
