// Command-line numbers checked in one place, for every vdyn program: a CLI11 validator that
// accepts only a finite number inside a range of the table of limits (vdyn/base/limits.h), with
// the limit written as a person writes it; one rule for exit codes (2 for a usage error) and one
// way of telling what is wrong with a command line.
#pragma once

#include <cmath>
#include <cstdint>
#include <iostream>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "vdyn/base/limits.h"
#include "vdyn/base/text.h"

namespace vdyn::cli {

// The value must be a finite number in `r` ("nan", "inf", "1e300" for a bounded option are
// refused; "1e-400" is a number: it underflows to 0). CLI11 converts the text as ParseNumber
// reads it (a check cannot change the text; whole numbers are made decimal first, by Parse).
inline CLI::Validator InRange(const limits::Range& r) {
  return CLI::Validator(
      [r](std::string& text) -> std::string {
        const auto v = base::ParseNumber(text);
        if (!v) return "'" + base::Quote(text, 40) + "' is not a finite number";
        return limits::Check(r, *v);
      },
      limits::Describe(r));
}

// An integer option: in range and whole.
inline CLI::Validator WholeInRange(const limits::Range& r) {
  return CLI::Validator(
      [r](std::string& text) -> std::string {
        const auto v = base::ParseNumber(text);
        if (!v) return "'" + base::Quote(text, 40) + "' is not a number";
        if (*v != std::trunc(*v)) return "'" + base::Quote(text, 40) + "' is not a whole number";
        return limits::Check(r, *v);
      },
      limits::Describe(r));
}

// A vehicle id: a whole number in limits::kVehicleId (0 names no vehicle).
inline CLI::Validator VehicleId() { return WholeInRange(limits::kVehicleId); }

// An entry of a list of vehicle ids (vdyn-server --vehicle-ids 1,2,10..20): an id, or an ascending
// range of them, both ends included, of at most limits::kMaxVehicles ids.
CLI::Validator VehicleIds();
// The ids of a list of entries VehicleIds() accepted, each range written out, in order.
std::vector<std::uint32_t> ExpandVehicleIds(const std::vector<std::string>& entries);

// An id that goes into messages (a server id): not empty or blank, at most limits::kMaxIdBytes
// bytes (every reader refuses a longer one), no control characters. `what` names it.
inline CLI::Validator Id(const std::string& what) {
  return CLI::Validator(
      [what](std::string& text) -> std::string {
        if (text.find_first_not_of(" \t") == std::string::npos) return "the " + what + " is empty";
        if (text.size() > limits::kMaxIdBytes) {
          return "the " + what + " is " + std::to_string(text.size()) + " bytes long; at most " +
                 std::to_string(limits::kMaxIdBytes);
        }
        for (const char c : text) {
          if (static_cast<unsigned char>(c) < 0x20 || c == 0x7f) {
            return "the " + what + " holds a control character: '" + base::Quote(text, 80) + "'";
          }
        }
        return {};
      },
      "ID");
}

// Parses argv; on --help prints and returns 0, on a usage error prints why to `err` and returns 2.
// Returns -1 when the program should go on. Every program's command line goes through here, so
// the errors read alike (vdyn/cli/errors.h): each names the program (and command), an unknown
// option or command comes with the nearest one, and a list with an empty entry is refused.
int Parse(CLI::App& app, int argc, char** argv, std::ostream& err = std::cerr);

}  // namespace vdyn::cli
