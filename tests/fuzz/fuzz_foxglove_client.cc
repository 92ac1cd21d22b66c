// Fuzz target: what a Foxglove client sends vdyn-foxglove. The first byte sets the size of the
// pieces the rest arrives in (as reads from a socket cut it); the rest goes through the WebSocket
// frame reader, and every message it yields through the protocol's parsers (text: JSON ops;
// binary: client message data) and, for parameters, into a VehicleParams. Any bytes: messages or a
// ProtocolError with an RFC 6455 close code, never a crash.
#include <cstdint>
#include <cstdlib>
#include <string_view>

#include "vdyn/foxglove/params.h"
#include "vdyn/foxglove/protocol.h"

namespace pr = vdyn::foxglove::protocol;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size == 0) return 0;
  const std::size_t piece = data[0] % 64 + 1;
  std::string_view rest(reinterpret_cast<const char*>(data + 1), size - 1);
  pr::FrameReader reader(1 << 16);
  pr::FrameReader::Event ev;
  try {
    while (!rest.empty()) {
      std::string_view chunk = rest.substr(0, piece);
      rest.remove_prefix(chunk.size());
      while (reader.Next(chunk, ev)) {
        if (ev.kind == pr::FrameReader::Event::Kind::kText) {
          try {
            const pr::ClientMessage m = pr::ParseClientText(ev.payload);
            if (const auto* s = std::get_if<pr::SetParameters>(&m)) {
              vdyn::pb::VehicleParams p;
              for (const pr::Parameter& q : s->parameters) {
                const auto name = vdyn::foxglove::ParseParameterName(q.name);
                if (name && q.value) (void)vdyn::foxglove::SetParameter(p, name->path, *q.value);
              }
            }
          } catch (const pr::ProtocolError&) {
          }
        } else if (ev.kind == pr::FrameReader::Event::Kind::kBinary) {
          try {
            (void)pr::ParseClientBinary(
                {reinterpret_cast<const std::uint8_t*>(ev.payload.data()), ev.payload.size()});
          } catch (const pr::ProtocolError&) {
          }
        }
      }
      if (!chunk.empty()) std::abort();  // Next() consumes everything it was given
    }
  } catch (const pr::ProtocolError&) {
    const std::uint16_t code = reader.close_code();
    if (code != 1002 && code != 1007 && code != 1009) std::abort();
  }
  return 0;
}
