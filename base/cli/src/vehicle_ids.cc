#include <cmath>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "vdyn/base/text.h"
#include "vdyn/cli/options.h"

namespace vdyn::cli {
namespace {

struct IdRange {
  std::uint32_t first = 0, last = 0;
};

// One entry: "7" or "1..256"; the reason when it is neither (empty `why`: `out` holds it).
std::string ReadEntry(const std::string& text, IdRange& out) {
  auto id = [](std::string_view t, std::uint32_t& v) -> std::string {
    const std::string quoted = "'" + base::Quote(t, 40) + "'";
    const auto n = base::ParseNumber(t);
    if (!n) return quoted + " is not a number";
    if (*n != std::trunc(*n)) return quoted + " is not a whole number";
    if (std::string why = limits::Check(limits::kVehicleId, *n); !why.empty()) return why;
    v = static_cast<std::uint32_t>(*n);
    return {};
  };
  const std::size_t dots = text.find("..");
  if (dots == std::string::npos) {
    std::string why = id(text, out.first);
    out.last = out.first;
    return why;
  }
  const std::string_view all(text);
  if (std::string why = id(all.substr(0, dots), out.first); !why.empty()) return why;
  if (std::string why = id(all.substr(dots + 2), out.last); !why.empty()) return why;
  if (out.last < out.first) {
    return "the range '" + base::Quote(text, 40) + "' goes down; write it as " +
           std::to_string(out.last) + ".." + std::to_string(out.first);
  }
  const auto most = static_cast<std::uint64_t>(limits::kMaxVehicles.hi);
  if (std::uint64_t{out.last} - out.first + 1 > most) {
    return "the range '" + base::Quote(text, 40) + "' holds " +
           std::to_string(std::uint64_t{out.last} - out.first + 1) +
           " ids; a server runs at most " + std::to_string(most);
  }
  return {};
}

}  // namespace

CLI::Validator VehicleIds() {
  return CLI::Validator(
      [](std::string& text) -> std::string {
        IdRange r;
        return ReadEntry(text, r);
      },
      "ID or FIRST..LAST");
}

std::vector<std::uint32_t> ExpandVehicleIds(const std::vector<std::string>& entries) {
  std::vector<std::uint32_t> ids;
  for (const std::string& e : entries) {
    IdRange r;
    if (!ReadEntry(e, r).empty()) continue;  // refused by VehicleIds() before
    for (std::uint64_t v = r.first; v <= r.last; ++v) ids.push_back(static_cast<std::uint32_t>(v));
  }
  return ids;
}

}  // namespace vdyn::cli
