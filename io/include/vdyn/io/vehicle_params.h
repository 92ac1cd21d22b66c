// Vehicle parameter files and messages: the defaults, text/JSON syntax, merging, the dump.
// Validation of the values is the physics' (vdyn/bridge/params.h joins the two).
#pragma once

#include <filesystem>
#include <stdexcept>
#include <string>

#include "vdyn/vehicle_params.pb.h"

namespace vdyn {

// Thrown for a parameter file or message that cannot be used; what() names file/field and reason.
class ParamsError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Defaults of a mid-size car (every field set; valid).
pb::VehicleParams DefaultVehicleParams();

// base with every field present in `update` overriding it (the way a file or a live change
// applies); a wheel's magic_formula with a name (a file's) replaces the wheel's tyre whole, one
// without a name changes the coefficients it has, and an empty one removes the tyre (brush law
// again).
pb::VehicleParams MergeVehicleParams(const pb::VehicleParams& base, const pb::VehicleParams& update);

// Parses text that a file would hold (protobuf text format, or JSON) and merges it over `base`.
// Syntax only: throws ParamsError naming `source_name`, the line and column, or the unknown field.
// With `folder`, the tyre files the text names (tire_file...) are read from there into the
// wheels' magic_formula (vdyn/io/tire_file.h); without, the names stay for the checks to refuse.
pb::VehicleParams ParseVehicleParamsText(const std::string& text, bool json,
                                         const std::string& source_name,
                                         const pb::VehicleParams& base,
                                         const std::filesystem::path* folder = nullptr);

// Reads a parameter file (JSON when the name ends in .json) and merges it over `base`. Throws
// ParamsError for a missing file, a directory, a read error or bad syntax.
pb::VehicleParams ReadVehicleParamsFile(const std::filesystem::path& path,
                                        const pb::VehicleParams& base);

// The protobuf text format that a parameter file holds, with a header comment.
std::string DumpVehicleParamsText(const pb::VehicleParams& msg);

}  // namespace vdyn
