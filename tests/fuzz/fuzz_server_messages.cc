// Fuzz target: what the server reads from the network - an envelope (type name and payload) on
// vdyn/input or vdyn/control, through the reader's checks (transport), the receiver's checks
// (input ranges), and into a session (runtime): inputs offered and requests applied at step
// boundaries, then steps. The first byte picks the topic and the type name's validity; a state
// that leaves its bounds aborts, and so does a payload the wire check passes that the reflective
// check refuses.
#include <cstdint>
#include <cstdlib>
#include <memory>
#include <string>

#include "vdyn/bridge/params.h"
#include "vdyn/control.pb.h"
#include "vdyn/input.pb.h"
#include "vdyn/messages/checks.h"
#include "vdyn/runtime/session.h"
#include "vdyn/transport/dds.h"

namespace {

vdyn::Session& TheSession() {
  static std::unique_ptr<vdyn::Session> s;
  if (!s) {
    vdyn::SessionConfig c;
    c.server_id = "fuzz";
    c.default_params = vdyn::DefaultVehicleParams();
    s = std::make_unique<vdyn::Session>(vdyn::BuildBuiltinWorld("facility"), c, nullptr);
    s->Spawn(1, s->world().spawn, 0.0, vdyn::pb::VehicleParams());
  }
  return *s;
}

}  // namespace

// libFuzzer calls this once before the first input: the session (a world built, its terrain
// hashed) is made here, outside the per-input timeout, which counts wall-clock time and runs at
// nice 19 beside the sanitizer suite. The driver without libFuzzer makes it on the first input.
extern "C" int LLVMFuzzerInitialize(int*, char***) {
  (void)TheSession();
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size == 0) return 0;
  using vdyn::transport::Decoded;
  using vdyn::transport::TopicId;
  const bool control = (data[0] & 1) != 0;
  const bool wrong_type = (data[0] & 2) != 0;
  const std::span<const std::uint8_t> payload(data + 1, size - 1);
  vdyn::Session& session = TheSession();
  // The wire check's promise: whatever it passes, the reflective check passes once parsed.
  {
    vdyn::pb::ControlRequest r;
    vdyn::pb::DriverInput in;
    google::protobuf::Message& m = control ? static_cast<google::protobuf::Message&>(r) : in;
    if (m.ParseFromArray(payload.data(), static_cast<int>(payload.size())) &&
        vdyn::messages::WireClean(*m.GetDescriptor(), payload) &&
        vdyn::messages::CheckMessage(m).problem != vdyn::messages::Problem::kNone) {
      std::abort();
    }
  }
  if (control) {
    vdyn::pb::ControlRequest r;
    const Decoded d = vdyn::transport::DecodeEnvelope(
        TopicId::kControl, wrong_type ? "acme.Joystick" : "vdyn.pb.ControlRequest", payload, r);
    if (d.outcome != Decoded::Outcome::kOk) return 0;
    const vdyn::pb::ControlReply reply = session.Apply(r);
    if (!reply.accepted() && reply.reason().empty()) std::abort();  // every refusal says why
    if (session.pending_steps() > 0) session.CancelPendingSteps(session.pending_steps());
  } else {
    vdyn::pb::DriverInput in;
    const Decoded d = vdyn::transport::DecodeEnvelope(
        TopicId::kInput, wrong_type ? "vdyn.pb.State" : "vdyn.pb.DriverInput", payload, in);
    if (d.outcome != Decoded::Outcome::kOk) return 0;
    if (!vdyn::CheckInputRanges(in).empty()) return 0;  // the receiver refuses it
    (void)session.OfferInput(in, nullptr);  // refused for a vehicle that is not there: fine
  }
  for (int i = 0; i < 5; ++i) session.Step();
  for (std::uint32_t id : session.vehicle_ids()) {
    const auto& x = session.simulator(id).state().x;
    if (!x.allFinite() || vdyn::Velocity(x).norm() > 500.0) std::abort();
  }
  return 0;
}
