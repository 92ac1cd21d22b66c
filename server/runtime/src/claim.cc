#include "vdyn/runtime/claim.h"

#include <algorithm>
#include <charconv>

namespace vdyn {
namespace {
constexpr std::string_view kPrefix = "vdyn-server/1 ";
}  // namespace

std::string ServerClaim::Encode() const {
  std::string out(kPrefix);
  out += running ? "running vehicles=" : "claiming vehicles=";
  for (std::size_t i = 0; i < vehicle_ids.size(); ++i) {
    if (i > 0) out += ',';
    out += std::to_string(vehicle_ids[i]);
  }
  // The id last: it may hold blanks.
  out += " id=" + server_id;
  return out;
}

std::optional<ServerClaim> ServerClaim::Decode(std::string_view text) {
  if (!text.starts_with(kPrefix)) return std::nullopt;
  text.remove_prefix(kPrefix.size());
  ServerClaim c;
  if (text.starts_with("running ")) {
    c.running = true;
    text.remove_prefix(8);
  } else if (text.starts_with("claiming ")) {
    text.remove_prefix(9);
  } else {
    return std::nullopt;
  }
  if (!text.starts_with("vehicles=")) return std::nullopt;
  text.remove_prefix(9);
  const std::size_t id_at = text.find(" id=");
  if (id_at == std::string_view::npos) return std::nullopt;
  std::string_view list = text.substr(0, id_at);
  c.server_id = std::string(text.substr(id_at + 4));
  while (!list.empty()) {
    const std::size_t comma = list.find(',');
    const std::string_view item = list.substr(0, comma);
    std::uint32_t v = 0;
    const auto [ptr, ec] = std::from_chars(item.data(), item.data() + item.size(), v);
    if (ec != std::errc() || ptr != item.data() + item.size()) return std::nullopt;
    c.vehicle_ids.push_back(v);
    if (comma == std::string_view::npos) break;
    list.remove_prefix(comma + 1);
  }
  return c;
}

bool ServerClaim::Clashes(const ServerClaim& other) const {
  if (server_id == other.server_id) return true;
  return std::any_of(vehicle_ids.begin(), vehicle_ids.end(), [&](std::uint32_t v) {
    return std::find(other.vehicle_ids.begin(), other.vehicle_ids.end(), v) !=
           other.vehicle_ids.end();
  });
}

std::vector<bool> ChooseRunners(const std::vector<const ServerClaim*>& by_guid) {
  std::vector<bool> runs(by_guid.size(), false);
  std::vector<const ServerClaim*> chosen;
  auto free_of_chosen = [&](const ServerClaim& c) {
    return std::none_of(chosen.begin(), chosen.end(),
                        [&](const ServerClaim* k) { return c.Clashes(*k); });
  };
  for (std::size_t i = 0; i < by_guid.size(); ++i) {
    if (by_guid[i]->running) {
      runs[i] = true;
      chosen.push_back(by_guid[i]);
    }
  }
  for (std::size_t i = 0; i < by_guid.size(); ++i) {
    if (runs[i] || !free_of_chosen(*by_guid[i])) continue;
    runs[i] = true;
    chosen.push_back(by_guid[i]);
  }
  return runs;
}

}  // namespace vdyn
