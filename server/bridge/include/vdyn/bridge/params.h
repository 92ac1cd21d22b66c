// Vehicle parameters from messages and files to the physics: presence and enum checks on the
// message, then the physics' own validation (vdyn/physics/params.h) against the table of limits.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include "vdyn/io/vehicle_params.h"
#include "vdyn/physics/params.h"
#include "vdyn/vehicle_params.pb.h"

namespace vdyn {

// Checks a complete message: every field present, enums known, every value valid. Empty when
// valid; each issue names the field path and the reason.
std::vector<ParamIssue> ValidateVehicleParams(const pb::VehicleParams& msg);

// The physics' validated parameters from a valid, complete message. Throws ParamsError naming
// every issue otherwise.
ValidParams ParamsFromProto(const pb::VehicleParams& msg);

// A Magic Formula tyre from its message, checked (the message's model version and side, every
// coefficient the equations need; issues named "magic_formula.pdy1") and derived, as a wheel
// would carry it. Throws ParamsError naming every issue.
MagicFormula MagicFormulaFromProto(const pb::MagicFormulaTire& tire);

// Parses text (as a file holds it), merges it over `base` and validates the result. Throws
// ParamsError naming `source_name`, the line/field and the reason.
pb::VehicleParams ParseVehicleParams(const std::string& text, bool json,
                                     const std::string& source_name,
                                     const pb::VehicleParams& base = DefaultVehicleParams());

// Reads a parameter file (protobuf text, or JSON when the name ends in .json), merges it over
// `base` and validates the result.
pb::VehicleParams LoadVehicleParamsFile(const std::filesystem::path& path,
                                        const pb::VehicleParams& base = DefaultVehicleParams());

}  // namespace vdyn
