// A server's claim on its server id and its vehicles, announced in its DDS participant's
// USER_DATA (transport::ParticipantOptions) from the moment it exists, so that two servers started
// in the same instant see each other's claims during discovery, before either publishes anything.
//
//   "vdyn-server/1 claiming vehicles=1,2 id=lab-a"   while listening for other servers
//   "vdyn-server/1 running vehicles=1,2 id=lab-a"    once it runs them
//
// The rule (ServerNode): a claiming server gives way to every running server that claims one of
// its vehicles or its id, and to every claiming one with a lower participant GUID (the same
// answer in every process); a running server never gives way.
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

}  // namespace vdyn
