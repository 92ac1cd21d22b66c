// Command-line numbers checked in one place, for every vdyn program: a CLI11 validator that
// accepts only a finite number inside a range of the table of limits (vdyn/base/limits.h), with
// the limit written as a person writes it; and one rule for exit codes (2 for a usage error).
#pragma once

#include <string>

#include <CLI/CLI.hpp>

#include "vdyn/base/limits.h"
#include "vdyn/base/text.h"

namespace vdyn::cli {

// The value must be a finite number in `r` ("nan", "inf", "1e300" for a bounded option are
// refused; "1e-400" is a number: it underflows to 0). The text is rewritten to the parsed number,
// so CLI11 converts exactly what was checked.
inline CLI::Validator InRange(const limits::Range& r) {
  return CLI::Validator(
      [r](std::string& text) -> std::string {
        const auto v = base::ParseNumber(text);
        if (!v) return "'" + base::Quote(text, 40) + "' is not a finite number";
        std::string why = limits::Check(r, *v);
        if (!why.empty()) return why;
        text = base::FormatNumber(*v);
        return {};
      },
      limits::Describe(r));
}

// An integer option: in range and whole.
inline CLI::Validator WholeInRange(const limits::Range& r) {
  return CLI::Validator(
      [r](std::string& text) -> std::string {
        const auto v = base::ParseNumber(text);
        if (!v) return "'" + base::Quote(text, 40) + "' is not a number";
        if (*v != static_cast<double>(static_cast<long long>(*v))) {
          return "'" + base::Quote(text, 40) + "' is not a whole number";
        }
        std::string why = limits::Check(r, *v);
        if (!why.empty()) return why;
        text = std::to_string(static_cast<long long>(*v));
        return {};
      },
      limits::Describe(r));
}

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

// Parses argv; on --help prints and returns 0, on a usage error prints why and returns 2.
// Returns -1 when the program should go on.
inline int Parse(CLI::App& app, int argc, char** argv) {
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;
  }
  return -1;
}

}  // namespace vdyn::cli
