// Magic Formula tyre property files (.tir: the TeimOrbit format of MSC Adams and TNO MF-Tyre),
// read into the message the full model's `magic_formula` law takes (vdyn.pb.MagicFormulaTire).
// Syntax, units and the model version only: which coefficients the equations need is checked by
// the bridge (ValidateVehicleParams), which names each one a file lacks. docs/formats.md has the
// format as vdyn reads it.
#pragma once

#include <filesystem>
#include <string>
#include <string_view>

#include "vdyn/io/vehicle_params.h"
#include "vdyn/vehicle_params.pb.h"

namespace vdyn {

// A .tir file that cannot be used; what() names the file, the line and key where there is one,
// and the reason ("tyre.tir:12: PDY1: '1.0.5' is not a number").
class TireFileError : public ParamsError {
 public:
  using ParamsError::ParamsError;
};

// The largest .tir file read (real ones are tens of kilobytes).
inline constexpr std::size_t kMaxTireFileBytes = 4u << 20;

// Parses a .tir file's text: `[SECTION]` lines, `KEY = value` lines (keys in any case, numbers in
// Fortran's forms too: .315E+01, 1.5D-3; strings in quotes), `$` comments to the end of a line
// and `!` comment lines, tables in braces (read and skipped). [UNITS] is honoured: each quantity
// with a dimension is converted to SI (meter, millimeter, centimeter, inch; newton, kilonewton,
// pound_force; radian, degree; kg, gram; second, millisecond; pressure in pascal, kilopascal,
// bar or psi, else force / length^2); another unit is refused by name. FITTYP must be 61 or 62
// (MF 6.1, 6.2); MF 5.2 and PAC2002 files are refused with what was found. `name` is the file
// name without its folder. Throws TireFileError.
pb::MagicFormulaTire ParseTireFile(std::string_view text, const std::string& source_name);

// Reads and parses a .tir file (a missing file, a directory or one larger than
// kMaxTireFileBytes is refused by name). Throws TireFileError.
pb::MagicFormulaTire ReadTireFile(const std::filesystem::path& path);

// Replaces the tire_file, tire_file_front, tire_file_rear and per-wheel tire_file fields of a
// parameter file's content by the tyres they name (paths relative to `folder`): a wheel's own
// file wins over its axle's, an axle's over the one for every wheel; the fields are cleared.
// Throws TireFileError for a file that cannot be read.
void ResolveTireFiles(pb::VehicleParams& update, const std::filesystem::path& folder);

}  // namespace vdyn
