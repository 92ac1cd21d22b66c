// A state subscriber in a process of its own (tests): reads vdyn/state on a domain until it has
// seen `count` samples or `seconds` passed, then prints how many it read. A writer whose readers
// live in other processes takes the network path, as the server's does.
#include <chrono>
#include <cstdio>
#include <cstdlib>

#include "vdyn/state.pb.h"
#include "vdyn/transport/dds.h"

int main(int argc, char** argv) {
  if (argc < 4) {
    std::fprintf(stderr, "usage: %s DOMAIN COUNT SECONDS\n", argv[0]);
    return 2;
  }
  const auto domain = static_cast<std::uint32_t>(std::atoi(argv[1]));
  const long want = std::atol(argv[2]);
  const auto seconds = std::chrono::seconds(std::atol(argv[3]));
  vdyn::transport::Participant p(domain);
  vdyn::transport::DropCounters drops;
  vdyn::transport::Reader<vdyn::pb::VehicleState> states(p, vdyn::transport::TopicId::kState, &drops);
  long n = 0;
  const auto end = std::chrono::steady_clock::now() + seconds;
  while (n < want && std::chrono::steady_clock::now() < end) {
    states.Wait(std::chrono::milliseconds(100));
    n += states.Take([](const vdyn::pb::VehicleState&, const vdyn::transport::SampleInfo&) {});
  }
  std::printf("received %ld\n", n);
  return 0;
}
