// A server's claim on its server id and its vehicles, announced in its DDS participant's
// USER_DATA (transport::ParticipantOptions) from the moment it exists, so that two servers started
// in the same instant see each other's claims during discovery, before either publishes anything.
//
//   "vdyn-server/1 claiming vehicles=1,2 id=lab-a"   while listening for other servers
//   "vdyn-server/1 running vehicles=1,2 id=lab-a"    once it runs them
//
// The rule (ServerNode, ChooseRunners): every running server runs; then, in the order of their
// participant GUIDs, each claiming server runs unless it clashes (a vehicle or the id in common)
// with one chosen before it. Every process that sees the same claims computes the same answer, and
// a server never gives way to one that itself gives way (issue 33: A={1}, B={2}, C={1,2} started
// together left vehicle 2 unserved when B gave way to C and C to A). A running server never gives
// way.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace vdyn {

struct ServerClaim {
  std::string server_id;
  std::vector<std::uint32_t> vehicle_ids;
  bool running = false;

  std::string Encode() const;
  // Nullopt for anything that is not a claim (another program's participant, or a malformed one).
  [[nodiscard]] static std::optional<ServerClaim> Decode(std::string_view text);
  // Whether the two claims want the same server id or a vehicle in common.
  bool Clashes(const ServerClaim& other) const;
};

// Which claims run, given every claim seen sorted by participant GUID (the rule above): entry i
// answers by_guid[i].
std::vector<bool> ChooseRunners(const std::vector<const ServerClaim*>& by_guid);

}  // namespace vdyn
