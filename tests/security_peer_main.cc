// A DDS participant with whatever identity CYCLONEDDS_URI gives it (tests/test_security.cc): it
// tries to change vehicle 1's mass and to drive vehicle 1, and watches the states, then prints
// what happened, one fact a line:
//   control writer refused: REASON | reply accepted | reply rejected: REASON | no reply: REASON
//   input writer refused: REASON | input matched readers N      (the most it saw at once)
//   states received N
//   states driven by SOURCE N                                    (states naming its source)
// Usage: security_peer DOMAIN SECONDS SOURCE [MASS_KG]
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <optional>
#include <string>

#include "vdyn/control.pb.h"
#include "vdyn/input.pb.h"
#include "vdyn/state.pb.h"
#include "vdyn/transport/control_client.h"
#include "vdyn/transport/dds.h"

using namespace std::chrono_literals;
using vdyn::transport::TopicId;

int main(int argc, char** argv) {
  if (argc < 4) {
    std::fprintf(stderr, "usage: %s DOMAIN SECONDS SOURCE [MASS_KG]\n", argv[0]);
    return 2;
  }
  const auto domain = static_cast<std::uint32_t>(std::atoi(argv[1]));
  const auto seconds = std::chrono::seconds(std::atol(argv[2]));
  const std::string source = argv[3];
  const bool set_mass = argc > 4;
  const double mass_kg = set_mass ? std::atof(argv[4]) : 0.0;
  vdyn::transport::Participant p(domain);
  vdyn::transport::DropCounters drops;
  const auto end = std::chrono::steady_clock::now() + seconds;

  if (set_mass) {
    try {
      vdyn::transport::ControlClient control(p, source);
      vdyn::pb::ControlRequest req;
      req.set_vehicle_id(1);
      req.mutable_set_params()->mutable_params()->set_mass(mass_kg);
      std::optional<vdyn::pb::ControlReply> reply;
      if (control.WaitForServer(seconds / 2)) reply = control.Call(req, seconds / 4);
      if (!reply) {
        std::printf("no reply: %s\n", control.last_error().c_str());
      } else if (reply->accepted()) {
        std::printf("reply accepted\n");
      } else {
        std::printf("reply rejected: %s\n", reply->reason().c_str());
      }
    } catch (const vdyn::transport::TransportError& e) {
      std::printf("control writer refused: %s\n", e.what());
    }
  }

  // Stronger than any rig (vdyn-input: 10), so its input would drive if the server took it.
  std::unique_ptr<vdyn::transport::Writer<vdyn::pb::DriverInput>> input;
  try {
    input = std::make_unique<vdyn::transport::Writer<vdyn::pb::DriverInput>>(p, TopicId::kInput, 100);
  } catch (const vdyn::transport::TransportError& e) {
    std::printf("input writer refused: %s\n", e.what());
  }
  vdyn::transport::Reader<vdyn::pb::VehicleState> states(p, TopicId::kState, &drops);
  vdyn::pb::DriverInput in;
  in.set_vehicle_id(1);
  in.set_source_id(source);
  in.set_throttle(0.3);
  long received = 0, driven = 0, write_failures = 0;
  std::uint32_t matched = 0;
  while (std::chrono::steady_clock::now() < end) {
    if (input) {
      in.set_sequence(in.sequence() + 1);
      write_failures += !input->Write(1, in);
      matched = std::max(matched, input->MatchedReaders());
    }
    (void)states.Wait(10ms);
    (void)states.Take([&](const vdyn::pb::VehicleState& s, const vdyn::transport::SampleInfo&) {
      ++received;
      if (s.input().source_id() == source) ++driven;
    });
  }
  if (input) std::printf("input matched readers %u, writes failed %ld\n", matched, write_failures);
  std::printf("states received %ld\n", received);
  std::printf("states driven by %s %ld\n", source.c_str(), driven);
  std::fflush(stdout);
  return 0;
}
