// net_bench: the networked server measured as a lab uses it (issue: the simulation server over
// DDS). One run, on one machine, over loopback:
//  - the server in real time on `facility` for N s: tick lateness distribution (p50, p99, p99.9,
//    max), steps that never ran, drift of simulation time against the wall clock, its CPU;
//  - subscriber processes on the state topic: this one and SUBSCRIBERS - 1 children (default 3;
//    1 is ddsperf's shape: one writer, one reader);
//  - one-way state latency (DDS source timestamp to the subscriber's hand, same clock);
//  - latency from a driver input to the first state that applied it (the input's monotonic stamp
//    travels back in the state);
//  - Cyclone's own ddsperf ping/pong at 1 kHz with a payload of the state's size, in the same run:
//    its round trip / 2 is the one-way peer figure;
//  - the floor under both, without DDS: bare UDP datagrams of that size over loopback between two
//    processes at 1 kHz, measured both ways: one-way (a stamp in the datagram, as the state's
//    latency is measured) and round trip / 2 (as ddsperf's is). On a virtual machine whose idle
//    vCPUs halt, waking a receiver that slept for a millisecond costs more than waking one that
//    sent a moment ago, which a round trip's second half does: the two differ before any DDS.
//
// Usage: net_bench [seconds=60] [ddsperf_seconds=20] [subscribers=3]
#include <arpa/inet.h>
#include <netinet/in.h>
#include <signal.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <map>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "child.h"
#include "vdyn/transport/dds.h"
#include "vdyn/base/time.h"
#include "vdyn/runtime/pacing.h"
#include "vdyn/input.pb.h"
#include "vdyn/state.pb.h"


namespace {

using vdyn::transport::TopicId;
using vdyn::bench::ProcessCpuSeconds;
using vdyn::bench::ReadStats;
using vdyn::bench::Spawn;
using vdyn::bench::WaitPid;

// Subscriber child: takes every state for `seconds`, prints how many it got.
int Subscriber(std::uint32_t domain, double seconds) {
  vdyn::transport::Participant p(domain);
  vdyn::transport::DropCounters drops;
  vdyn::transport::Reader<vdyn::pb::VehicleState> states(p, TopicId::kState, &drops);
  const std::int64_t end = vdyn::base::MonotonicNow().ns + static_cast<std::int64_t>(seconds * 1e9);
  std::uint64_t n = 0;
  while (vdyn::base::MonotonicNow().ns < end) {
    (void)states.Wait(std::chrono::milliseconds(10));
    n += static_cast<std::uint64_t>(
        states.Take([](const vdyn::pb::VehicleState&, const vdyn::transport::SampleInfo&) {}));
  }
  std::printf("subscriber received %llu states\n", static_cast<unsigned long long>(n));
  return 0;
}

// --- bare UDP over loopback: the floor without DDS ---------------------------------------------

constexpr int kUdpDatagrams = 5000;  // 5 s at 1 kHz

int UdpSocket(std::uint16_t port, sockaddr_in& addr) {
  const int fd = socket(AF_INET, SOCK_DGRAM, 0);
  addr = {};
  addr.sin_family = AF_INET;
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  addr.sin_port = htons(port);
  if (fd < 0 || bind(fd, reinterpret_cast<const sockaddr*>(&addr), sizeof addr) != 0) {
    std::perror("net_bench: udp socket");
    std::exit(1);
  }
  timeval tv{2, 0};  // a lost datagram ends the probe instead of hanging it
  setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
  return fd;
}

sockaddr_in Loopback(std::uint16_t port) {
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  a.sin_port = htons(port);
  return a;
}

// The child: binds `port`, says so to `reply_port`, then per datagram either records its one-way
// latency (the sender's monotonic stamp in its first 8 bytes) or echoes it back.
int UdpPeer(std::uint16_t port, std::uint16_t reply_port, bool echo) {
  sockaddr_in self;
  const int fd = UdpSocket(port, self);
  const sockaddr_in back = Loopback(reply_port);
  std::vector<std::uint8_t> buf(65536);
  buf[0] = 0;
  sendto(fd, buf.data(), 1, 0, reinterpret_cast<const sockaddr*>(&back), sizeof back);  // ready
  vdyn::Histogram one_way;
  for (int i = 0; i < kUdpDatagrams; ++i) {
    const ssize_t n = recv(fd, buf.data(), buf.size(), 0);
    const std::int64_t now = vdyn::base::MonotonicNow().ns;
    if (n < 8) break;
    if (echo) {
      sendto(fd, buf.data(), static_cast<std::size_t>(n), 0,
             reinterpret_cast<const sockaddr*>(&back), sizeof back);
      continue;
    }
    std::int64_t stamp;
    std::memcpy(&stamp, buf.data(), sizeof stamp);
    one_way.Add(static_cast<double>(now - stamp) * 1e-3);
  }
  if (!echo) {
    std::printf("udp_one_way %llu %.1f %.1f\n", static_cast<unsigned long long>(one_way.count()),
                one_way.Percentile(50), one_way.Percentile(99));
  }
  return 0;
}

struct UdpFloor {
  std::uint64_t one_way_n = 0, rtt_n = 0;
  double one_way50 = 0, one_way99 = 0, rtt50 = 0, rtt99 = 0;
};

// One-way, then round trip, each kUdpDatagrams at 1 kHz against a child process.
UdpFloor MeasureUdpFloor(const char* self, std::size_t size, const std::string& tmp) {
  const auto base_port = static_cast<std::uint16_t>(40000 + getpid() % 10000 * 2);
  UdpFloor r;
  for (const bool echo : {false, true}) {
    sockaddr_in mine;
    const int fd = UdpSocket(static_cast<std::uint16_t>(base_port + 1), mine);
    const std::string log = tmp + (echo ? "-udp-echo.log" : "-udp-oneway.log");
    const pid_t child = Spawn({self, "--udp-peer", std::to_string(base_port),
                               std::to_string(base_port + 1), echo ? "echo" : "oneway"},
                              log);
    std::vector<std::uint8_t> buf(std::max<std::size_t>(size, 8));
    if (recv(fd, buf.data(), buf.size(), 0) < 1) {  // the child is bound
      std::fprintf(stderr, "net_bench: the UDP peer did not start\n");
      kill(child, SIGTERM);
    }
    const sockaddr_in to = Loopback(base_port);
    vdyn::Histogram rtt;
    std::int64_t next = vdyn::base::MonotonicNow().ns;
    for (int i = 0; i < kUdpDatagrams; ++i) {
      vdyn::base::SleepUntil({next += 1'000'000});
      const std::int64_t t0 = vdyn::base::MonotonicNow().ns;
      std::memcpy(buf.data(), &t0, sizeof t0);
      sendto(fd, buf.data(), buf.size(), 0, reinterpret_cast<const sockaddr*>(&to), sizeof to);
      if (echo) {
        if (recv(fd, buf.data(), buf.size(), 0) < 8) break;
        rtt.Add(static_cast<double>(vdyn::base::MonotonicNow().ns - t0) * 1e-3);
      }
    }
    WaitPid(child);
    close(fd);
    if (echo) {
      r.rtt_n = rtt.count();
      r.rtt50 = rtt.Percentile(50);
      r.rtt99 = rtt.Percentile(99);
    } else {
      const std::string out = vdyn::bench::Slurp(log);
      const auto at = out.find("udp_one_way ");
      unsigned long long n = 0;
      if (at != std::string::npos) {
        std::sscanf(out.c_str() + at, "udp_one_way %llu %lf %lf", &n, &r.one_way50, &r.one_way99);
      }
      r.one_way_n = n;
    }
  }
  return r;
}

// Median of the per-second "50%" and "99%" round trips that ddsperf ping prints.
std::pair<double, double> ParseDdsperf(const std::string& log) {
  std::ifstream in(log);
  std::string line;
  std::vector<double> p50, p99;
  while (std::getline(in, line)) {
    const auto a = line.find(" 50% "), b = line.find(" 99% ");
    if (a == std::string::npos || b == std::string::npos) continue;
    p50.push_back(std::atof(line.c_str() + a + 5));
    p99.push_back(std::atof(line.c_str() + b + 5));
  }
  auto median = [](std::vector<double> v) {
    if (v.empty()) return 0.0;
    std::sort(v.begin(), v.end());
    return v[v.size() / 2];
  };
  return {median(p50), median(p99)};
}

}  // namespace

int main(int argc, char** argv) {
  if (argc >= 5 && std::string(argv[1]) == "--udp-peer") {
    return UdpPeer(static_cast<std::uint16_t>(std::atoi(argv[2])),
                   static_cast<std::uint16_t>(std::atoi(argv[3])), std::string(argv[4]) == "echo");
  }
  if (argc >= 4 && std::string(argv[1]) == "--subscriber") {
    return Subscriber(static_cast<std::uint32_t>(std::atoi(argv[2])), std::atof(argv[3]));
  }
  const double seconds = argc > 1 ? std::atof(argv[1]) : 60.0;
  const double ddsperf_seconds = argc > 2 ? std::atof(argv[2]) : 20.0;
  const int subscribers = argc > 3 ? std::atoi(argv[3]) : 3;
  if (seconds <= 0 || ddsperf_seconds <= 0 || subscribers < 1 || subscribers > 16) {
    std::fprintf(stderr, "usage: net_bench [seconds > 0] [ddsperf_seconds > 0] [subscribers 1-16]\n");
    return 2;
  }
  if (std::getenv("CYCLONEDDS_URI") == nullptr) {
    setenv("CYCLONEDDS_URI",
           "<General><Interfaces><NetworkInterface name=\"lo\"/></Interfaces></General>"
           "<Discovery><MaxAutoParticipantIndex>64</MaxAutoParticipantIndex></Discovery>",
           1);
  }
  const std::uint32_t domain = 150 + static_cast<std::uint32_t>(getpid()) % 60;
  const std::string tmp = "/tmp/vdyn-net-bench-" + std::to_string(getpid());
  const double warmup = 3.0;

  const pid_t server = Spawn({VDYN_SERVER_BINARY, "--domain", std::to_string(domain), "--world",
                              "facility", "--no-status", "--duration",
                              std::to_string(seconds + warmup + 1.0), "--stats-out",
                              tmp + "-stats.txt", "--watchdog-ms", "100"},
                             tmp + "-server.log");
  std::vector<pid_t> subs;
  for (int i = 0; i + 1 < subscribers; ++i) {
    subs.push_back(Spawn({argv[0], "--subscriber", std::to_string(domain),
                          std::to_string(seconds + warmup)},
                         tmp + "-sub" + std::to_string(i) + ".log"));
  }

  vdyn::transport::Participant participant(domain);
  vdyn::transport::DropCounters drops;
  vdyn::transport::Reader<vdyn::pb::VehicleState> states(participant, TopicId::kState, &drops);
  vdyn::transport::Writer<vdyn::pb::DriverInput> input(participant, TopicId::kInput, 10);

  // Input at 1 kHz from a thread of its own: the stamp is the monotonic time of the write.
  std::atomic<bool> stop{false};
  std::atomic<std::uint64_t> input_write_failures{0};
  std::thread writer([&] {
    vdyn::pb::DriverInput msg;
    msg.set_vehicle_id(1);
    msg.set_source_id("net_bench");
    msg.set_cruise_on(true);
    msg.set_cruise_set_kmh(30.0);
    std::uint64_t seq = 0;
    std::int64_t next = vdyn::base::MonotonicNow().ns;
    while (!stop) {
      vdyn::base::SleepUntil({next += 1'000'000});
      msg.set_sequence(++seq);
      msg.set_steer(0.05 * std::sin(static_cast<double>(seq) * 1e-3));  // the input really varies
      msg.set_stamp_ns(vdyn::base::MonotonicNow().ns);
      if (!input.Write(1, msg)) ++input_write_failures;
    }
  });

  vdyn::Histogram one_way, to_listener, input_to_state;
  std::uint64_t received = 0, last_seq = 0;
  const std::int64_t t0 = vdyn::base::MonotonicNow().ns;
  const std::int64_t measure_from = t0 + static_cast<std::int64_t>(warmup * 1e9);
  const std::int64_t measure_to = measure_from + static_cast<std::int64_t>(seconds * 1e9);
  std::atomic<bool> measuring{false};
  std::atomic<std::size_t> state_bytes{0};
  std::mutex mu;  // the histograms are read by the main thread at the end
  // Take on DDS's receive thread (a listener): the lowest-latency way to read, as ddsperf does.
  states.OnDataAvailable([&] {
    const std::int64_t arrived_wall = dds_time();  // the listener's call: before take and decode
    (void)states.Take([&](const vdyn::pb::VehicleState& s, const vdyn::transport::SampleInfo& info) {
      const std::int64_t now_wall = dds_time();
      const std::int64_t now_mono = vdyn::base::MonotonicNow().ns;
      if (!measuring) return;
      std::lock_guard<std::mutex> lock(mu);
      state_bytes = s.ByteSizeLong();
      ++received;
      one_way.Add(static_cast<double>(now_wall - info.source_timestamp_ns) * 1e-3);
      to_listener.Add(static_cast<double>(arrived_wall - info.source_timestamp_ns) * 1e-3);
      if (s.input().sequence() > last_seq && s.input().stamp_ns() > 0) {
        last_seq = s.input().sequence();
        input_to_state.Add(static_cast<double>(now_mono - s.input().stamp_ns()) * 1e-3);
      }
    });
  });
  vdyn::base::SleepUntil({measure_from});
  const double cpu0 = ProcessCpuSeconds(server);
  measuring = true;
  vdyn::base::SleepUntil({measure_to});
  measuring = false;
  const double cpu1 = ProcessCpuSeconds(server);
  stop = true;
  writer.join();
  const int server_code = WaitPid(server);
  for (pid_t p : subs) WaitPid(p);
  auto stats = ReadStats(tmp + "-stats.txt");

  // The peer: ddsperf ping/pong at 1 kHz with a payload of the state's size.
  const std::size_t size = std::max<std::size_t>(1024, state_bytes.load());
  const std::string dur = std::to_string(static_cast<int>(ddsperf_seconds));
  const pid_t pong = Spawn({"/usr/bin/ddsperf", "-i", std::to_string(domain + 1), "-D",
                            std::to_string(static_cast<int>(ddsperf_seconds) + 3), "pong"},
                           tmp + "-pong.log");
  const pid_t ping = Spawn({"/usr/bin/ddsperf", "-i", std::to_string(domain + 1), "-D", dur, "ping",
                            "1kHz", "size", std::to_string(size)},
                           tmp + "-ping.log");
  WaitPid(ping);
  kill(pong, SIGTERM);
  WaitPid(pong);
  const auto [rtt50, rtt99] = ParseDdsperf(tmp + "-ping.log");
  const UdpFloor udp = MeasureUdpFloor(argv[0], size, tmp);

  const double cpu = 100.0 * (cpu1 - cpu0) / seconds;
  std::printf("net_bench: %.0f s of the real-time server on facility, %d state subscriber(s), input at 1 kHz\n",
              seconds, subscribers);
  std::printf("server exit code %d, scheduling: %s\n", server_code, stats["scheduling"].c_str());
  std::printf("tick lateness: p50 %s us, p99 %s us, p99.9 %s us, max %s us; under 1 ms: %.3f %%\n",
              stats["lateness_p50_us"].c_str(), stats["lateness_p99_us"].c_str(),
              stats["lateness_p999_us"].c_str(), stats["lateness_max_us"].c_str(),
              100.0 * std::atof(stats["fraction_under_1ms"].c_str()));
  std::printf("steps %s of %s due (never run: %lld), caught up %s, largest lag %s steps, rebases %s\n",
              stats["steps"].c_str(), stats["steps_due"].c_str(),
              std::atoll(stats["steps_due"].c_str()) - std::atoll(stats["steps"].c_str()),
              stats["steps_caught_up"].c_str(), stats["max_lag_steps"].c_str(),
              stats["schedule_rebases"].c_str());
  std::printf("drift of simulation time against the wall clock at the end: %s ms over %s s\n",
              stats["drift_ms"].c_str(), stats["wall_s"].c_str());
  std::printf("server CPU with %d subscriber(s): %.1f %% of one core (whole run: %s %%)\n", subscribers, cpu,
              stats["cpu_percent"].c_str());
  std::printf("state one-way latency (%llu states, %zu B): p50 %.1f us, p99 %.1f us, max %.1f us\n",
              static_cast<unsigned long long>(received), state_bytes.load(),
              one_way.Percentile(50), one_way.Percentile(99), one_way.Max());
  std::printf("  of which to the listener's call (before take and decode): p50 %.1f us, p99 %.1f us\n",
              to_listener.Percentile(50), to_listener.Percentile(99));
  if (input_write_failures > 0) {
    std::printf("input writes that failed: %llu\n",
                static_cast<unsigned long long>(input_write_failures.load()));
  }
  std::printf("input to first state applying it (%llu inputs): p50 %.1f us, p99 %.1f us, max %.1f us\n",
              static_cast<unsigned long long>(input_to_state.count()), input_to_state.Percentile(50),
              input_to_state.Percentile(99), input_to_state.Max());
  std::printf("ddsperf ping/pong 1 kHz, %zu B, same run: round trip p50 %.1f us, p99 %.1f us -> "
              "one way ~ p50 %.1f us, p99 %.1f us\n",
              size, rtt50, rtt99, rtt50 / 2.0, rtt99 / 2.0);
  if (rtt50 > 0) {
    std::printf("ratio vdyn state one-way / ddsperf one-way: p50 %.2f, p99 %.2f\n",
                one_way.Percentile(50) / (rtt50 / 2.0), one_way.Percentile(99) / (rtt99 / 2.0));
  }
  std::printf(
      "bare UDP over loopback, %zu B at 1 kHz, same run (no DDS): one-way (%llu) p50 %.1f us, "
      "p99 %.1f us; round trip / 2 (%llu) p50 %.1f us, p99 %.1f us\n",
      size, static_cast<unsigned long long>(udp.one_way_n), udp.one_way50, udp.one_way99,
      static_cast<unsigned long long>(udp.rtt_n), udp.rtt50 / 2.0, udp.rtt99 / 2.0);
  if (udp.rtt50 > 0) {
    std::printf(
        "ratio bare UDP one-way / bare UDP round trip / 2: p50 %.2f (the machine's part of "
        "the ratio above)\n",
        udp.one_way50 / (udp.rtt50 / 2.0));
  }
  if (udp.one_way50 > 0) {
    std::printf(
        "ratio vdyn state one-way / bare UDP one-way: p50 %.2f (what DDS, the server's state "
        "writer, the take and the decode add to the same wake-up)\n",
        one_way.Percentile(50) / udp.one_way50);
  }
  return server_code;
}
