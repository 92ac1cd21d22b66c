// Wheel mappings (vdyn.pb.WheelMapping, proto/vdyn/wheel_mapping.proto): the built-in table of
// common rigs, user mapping files (protobuf text format) that override it, their checks, and where
// `vdyn-input calibrate` writes them.
#pragma once

#include <cstdint>
#include <filesystem>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

#include "vdyn/wheel_mapping.pb.h"

namespace vdyn::wheel_input {

class MappingError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// The built-in table: one mapping per wheel model (docs in clients/wheel_input/README.md).
std::span<const pb::WheelMapping> BuiltinWheels();
// The table's entry for a device, or nullptr.
const pb::WheelMapping* FindBuiltinWheel(std::uint16_t vendor_id, std::uint16_t product_id);
// For a device SDL calls a wheel that the table does not know: steering on axis 0 (900 degrees),
// throttle and brake on axes 1 and 2 when present, resting at the low end. `calibrate` fixes it.
pb::WheelMapping GenericWheel(std::uint16_t vendor_id, std::uint16_t product_id, int axes);

// Everything wrong with a mapping, one reason each ("throttle: rest and full are the same raw
// value 0"); empty when it can be used. `axes` and `buttons` are the device's counts (-1: unknown).
std::vector<std::string> ValidateMapping(const pb::WheelMapping& m, int axes = -1,
                                         int buttons = -1);

// Parses a mapping file's text and checks it; throws MappingError naming `source`, the line and
// column, or the reasons.
pb::WheelMapping ParseMappingText(const std::string& text, const std::string& source);
// Reads and checks a mapping file (missing, a directory, unreadable, bad syntax or values: throws).
pb::WheelMapping ReadMappingFile(const std::filesystem::path& path);
// The text a mapping file holds, with a header comment.
std::string DumpMappingText(const pb::WheelMapping& m);
// Writes a mapping file whole or not at all (a temporary file renamed over it); creates folders.
void WriteMappingFile(const std::filesystem::path& path, const pb::WheelMapping& m);

// Where a device's user mapping lives: $VDYN_CONFIG_DIR, else $XDG_CONFIG_HOME/vdyn, else
// ~/.config/vdyn; then wheels/VVVV_PPPP.txt (hex vendor and product id).
std::filesystem::path DefaultMappingPath(std::uint16_t vendor_id, std::uint16_t product_id);

// "046d:c24f"
std::string VidPid(std::uint16_t vendor_id, std::uint16_t product_id);

}  // namespace vdyn::wheel_input
