// A state subscriber in a process of its own (tests): reads vdyn/state on a domain until it has
// seen `count` samples or `seconds` passed, then prints how many it read. A writer whose readers
// live in other processes takes the network path, as the server's does.
//
// With --states it reads vdyn/states instead (a step of every vehicle a sample, as a recorder or
// a viewer reads) and counts the vehicle states in them (tests/lab/states_multicast.sh).
//
// With --print it also prints one line per state as it takes it, for scripts that watch a session
// (tests/lab/multihost.sh):
//   TAKE_NS PUBLISH_NS VEHICLE STEP SOURCE_ID SEQUENCE SAFE SPEED_KMH
// TAKE_NS is CLOCK_REALTIME when this process took the sample, PUBLISH_NS the server's wall clock
// when it wrote it (the DDS source timestamp): both comparable with `date +%s%N` in every network
// namespace of the machine. SOURCE_ID and SEQUENCE name the input the step applied ("-" for no
// source, blanks as "_"); SAFE is 1 when the input watchdog's safe state replaced the driver's
// input. It then reads with the recorder's QoS (a second of states kept per vehicle), so a
// process the machine's load holds up a moment still prints every state that arrived.
#include <time.h>

#include <cctype>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>

#include "vdyn/base/deadline.h"
#include "vdyn/state.pb.h"
#include "vdyn/transport/dds.h"
#include "vdyn/transport/topics.h"

namespace {

long long RealtimeNs() {
  timespec ts{};
  clock_gettime(CLOCK_REALTIME, &ts);
  return static_cast<long long>(ts.tv_sec) * 1'000'000'000LL + ts.tv_nsec;
}

}  // namespace

int main(int argc, char** argv) {
  const bool batches = argc == 5 && std::strcmp(argv[4], "--states") == 0;
  if (argc < 4 || (argc == 5 && !batches && std::strcmp(argv[4], "--print") != 0) || argc > 5) {
    std::fprintf(stderr, "usage: %s DOMAIN COUNT SECONDS [--print | --states]\n", argv[0]);
    return 2;
  }
  const auto domain = static_cast<std::uint32_t>(std::atoi(argv[1]));
  const long want = std::atol(argv[2]);
  const auto seconds = std::chrono::seconds(std::atol(argv[3]));
  const bool print = argc == 5 && !batches;
  // Line-buffered: a script reading the file sees each state as soon as it is taken.
  if (print) std::setvbuf(stdout, nullptr, _IOLBF, 0);
  vdyn::transport::Participant p(domain);
  vdyn::transport::DropCounters drops;
  if (batches) {
    vdyn::transport::Reader<vdyn::pb::VehicleStates> steps(p, vdyn::transport::TopicId::kStates,
                                                           &drops);
    long n = 0;
    const auto end = std::chrono::steady_clock::now() + seconds;
    while (n < want && std::chrono::steady_clock::now() < end) {
      (void)steps.Wait(std::chrono::milliseconds(100));
      (void)steps.Take([&n](const vdyn::pb::VehicleStates& b, const vdyn::transport::SampleInfo&) {
        n += b.states_size();
      });
    }
    std::printf("received %ld\n", n);
    return 0;
  }
  vdyn::transport::Reader<vdyn::pb::VehicleState> states(
      p, vdyn::transport::TopicId::kState, &drops,
      print ? vdyn::transport::ReaderRole::kRecorder : vdyn::transport::ReaderRole::kDefault);
  long n = 0;
  const auto take = [&] {
    n += states.Take([print](const vdyn::pb::VehicleState& s,
                             const vdyn::transport::SampleInfo& info) {
      if (!print) return;
      std::string source = s.input().source_id();
      for (char& c : source)
        c = std::isspace(static_cast<unsigned char>(c)) != 0 ? '_' : c;  // one column
      std::printf("%lld %lld %u %llu %s %llu %d %.3f\n", RealtimeNs(),
                  static_cast<long long>(info.source_timestamp_ns), s.vehicle_id(),
                  static_cast<unsigned long long>(s.step()), source.empty() ? "-" : source.c_str(),
                  static_cast<unsigned long long>(s.input().sequence()),
                  s.control().watchdog_safe_state() ? 1 : 0, s.speed_kmh());
    });
  };
  (void)vdyn::base::PollUntil(
      vdyn::base::Deadline::After(vdyn::base::FromChrono(seconds)), vdyn::base::Milliseconds(100),
      [&] {
        take();
        return n >= want;
      },
      [&](vdyn::base::Nanos slice) { (void)states.Wait(vdyn::base::Chrono(slice)); });
  std::printf("received %ld\n", n);
  return 0;
}
