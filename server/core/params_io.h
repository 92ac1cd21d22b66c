// Parameter exchange: defaults, validation with field and reason, text/JSON files, dump.
#pragma once

#include <filesystem>
#include <stdexcept>
#include <string>
#include <vector>

#include "params.h"
#include "vdyn/vehicle_params.pb.h"

namespace vdyn {

// One rejected value: the field's path in the message ("lf.free_length") and why.
struct ParamIssue {
  std::string field;
  std::string reason;
};

// Thrown for a parameter file or message that cannot be used; what() names file/field and reason.
class ParamsError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Validated defaults of a mid-size car (every field set).
pb::VehicleParams DefaultVehicleParams();

// Checks every field of a complete message; empty when valid. Missing fields are reported too.
std::vector<ParamIssue> ValidateVehicleParams(const pb::VehicleParams& msg);

// Joins issues as "field: reason; field: reason".
std::string FormatIssues(const std::vector<ParamIssue>& issues);

// base with every field present in `update` overriding it (the way a file or a live change applies).
pb::VehicleParams MergeVehicleParams(const pb::VehicleParams& base, const pb::VehicleParams& update);

// Builds the core's struct from a valid, complete message. Throws ParamsError if it is not valid.
Params ParamsFromProto(const pb::VehicleParams& msg);

// Reads a parameter file (protobuf text format, or JSON when the name ends in .json), merges it over
// `base` and validates the result. Throws ParamsError naming the file, the line/field and the reason.
pb::VehicleParams LoadVehicleParamsFile(const std::filesystem::path& path,
                                        const pb::VehicleParams& base = DefaultVehicleParams());

// Parses text that a file would hold; `source_name` is used in messages. Same rules as the file.
pb::VehicleParams ParseVehicleParams(const std::string& text, bool json,
                                     const std::string& source_name,
                                     const pb::VehicleParams& base = DefaultVehicleParams());

// The protobuf text format that LoadVehicleParamsFile reads back, with a header comment.
std::string DumpVehicleParamsText(const pb::VehicleParams& msg);

}  // namespace vdyn
