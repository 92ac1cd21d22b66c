// Fuzz target: a world description as a viewer or the recorder's re-simulation receives it: the
// envelope's checks (whatever they accept, the reflective check accepts too), then the terrain
// rebuilt from its meshes (bridge).
#include <cstdint>
#include <cstdlib>
#include <string_view>

#include "vdyn/bridge/convert.h"
#include "vdyn/messages/checks.h"
#include "vdyn/transport/dds.h"
#include "vdyn/world.pb.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  vdyn::pb::WorldDescription w;
  const auto d = vdyn::transport::DecodeEnvelope(vdyn::transport::TopicId::kWorld,
                                                 "vdyn.pb.WorldDescription", {data, size}, w);
  if (d.outcome != vdyn::transport::Decoded::Outcome::kOk) return 0;
  // Accepted: the reflective check must agree (DecodeEnvelope may have passed it on the wire
  // check alone); packed vertices, nested meshes and landmarks are where the two could differ.
  if (vdyn::messages::CheckMessage(w).problem != vdyn::messages::Problem::kNone) std::abort();
  try {
    const auto world = vdyn::WorldFromDescription(w);
    (void)vdyn::TerrainHash(w);
  } catch (const vdyn::WorldError&) {
  }
  return 0;
}
