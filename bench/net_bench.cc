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
// Usage: net_bench [seconds=60] [ddsperf_seconds=20] [subscribers=3] [route=follow|states|tool]
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
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "child.h"
#include "vdyn/base/time.h"
#include "vdyn/input.pb.h"
#include "vdyn/runtime/pacing.h"
#include "vdyn/state.pb.h"
#include "vdyn/transport/dds.h"

namespace {

using vdyn::bench::ProcessCpuSeconds;
using vdyn::bench::ReadStats;
using vdyn::bench::Spawn;
using vdyn::bench::WaitPid;
using vdyn::transport::TopicId;

// What a subscriber reads: vehicle 1's states in its partition (what a rig, the lowest-latency
// reader, follows), a step of every vehicle on vdyn/states (a viewer, a recorder), or vdyn/state
// in the default partition (an independent DDS tool).
enum class Route { kFollow, kStates, kTool };

Route ParseRoute(const std::string& s) {
  if (s == "states") return Route::kStates;
  if (s == "tool") return Route::kTool;
  return Route::kFollow;
}

// One subscriber's latency: each state's DDS source timestamp (the server's dds_write) to the
// listener's call (before take and decode) and to the state decoded in hand, on DDS's receive
// thread (a listener: the lowest-latency way to read, as ddsperf does).
class Subscription {
 public:
  Subscription(vdyn::transport::Participant& p, vdyn::transport::DropCounters& drops, Route route) {
    if (route == Route::kStates) {
      batches_ = std::make_unique<vdyn::transport::Reader<vdyn::pb::VehicleStates>>(
          p, TopicId::kStates, &drops);
    } else {
      states_ = std::make_unique<vdyn::transport::Reader<vdyn::pb::VehicleState>>(
          p, TopicId::kState, &drops, vdyn::transport::ReaderRole::kDefault,
          route == Route::kFollow ? vdyn::transport::VehiclePartition(1) : std::string());
    }
  }
  // fn(state, listener_ns, source_ns) for each state, on the receive thread.
  template <class F>
  void Listen(F fn) {
    auto on_state = [this, fn](const vdyn::pb::VehicleState& s, std::int64_t at,
                               const vdyn::transport::SampleInfo& info) {
      if (s.vehicle_id() == 1) fn(s, at, info.source_timestamp_ns);
    };
    if (batches_) {
      batches_->OnDataAvailable([this, on_state] {
        const std::int64_t at = dds_time();
        (void)batches_->Take(
            [&](const vdyn::pb::VehicleStates& b, const vdyn::transport::SampleInfo& i) {
              for (const vdyn::pb::VehicleState& s : b.states()) on_state(s, at, i);
            });
      });
    } else {
      states_->OnDataAvailable([this, on_state] {
        const std::int64_t at = dds_time();
        (void)states_->Take([&](const vdyn::pb::VehicleState& s,
                                const vdyn::transport::SampleInfo& i) { on_state(s, at, i); });
      });
    }
  }

 private:
  std::unique_ptr<vdyn::transport::Reader<vdyn::pb::VehicleState>> states_;
  std::unique_ptr<vdyn::transport::Reader<vdyn::pb::VehicleStates>> batches_;
};

struct Latency {
  vdyn::Histogram one_way, to_listener;
  void Add(std::int64_t listener_ns, std::int64_t source_ns) {
    const std::int64_t now = dds_time();
    one_way.Add(static_cast<double>(now - source_ns) * 1e-3);
    to_listener.Add(static_cast<double>(listener_ns - source_ns) * 1e-3);
  }
};

// Subscriber child: measures from `from_s` for `seconds` after its start, prints its figures.
int Subscriber(std::uint32_t domain, double from_s, double seconds, Route route) {
  Latency lat;  // before the reader: its listener may run until the reader is deleted
  std::mutex mu;
  vdyn::transport::Participant p(domain);
  vdyn::transport::DropCounters drops;
  // Before the reader too: its listener reads them until the reader is deleted.
  const std::int64_t t0 = vdyn::base::MonotonicNow().ns;
  const std::int64_t from = t0 + static_cast<std::int64_t>(from_s * 1e9);
  const std::int64_t end = from + static_cast<std::int64_t>(seconds * 1e9);
  Subscription sub(p, drops, route);
  sub.Listen([&](const vdyn::pb::VehicleState&, std::int64_t at, std::int64_t source) {
    const std::int64_t mono = vdyn::base::MonotonicNow().ns;
    if (mono < from || mono >= end) return;
    std::lock_guard lock(mu);
    lat.Add(at, source);
  });
  vdyn::base::SleepUntil({end + 500'000'000});
  std::lock_guard lock(mu);
  std::printf("subscriber %llu %.1f %.1f %.1f %.1f\n",
              static_cast<unsigned long long>(lat.one_way.count()), lat.one_way.Percentile(50),
              lat.one_way.Percentile(99), lat.to_listener.Percentile(50),
              lat.to_listener.Percentile(99));
  std::fflush(stdout);
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

// --- bare UDP to several receivers: the kernel's part of serving several readers on one host ---

constexpr char kFanGroup[] = "239.255.77.1";  // on lo only: nothing leaves the machine

// A receiver of the fan-out: binds `port` (joins the group on lo when `multicast`), says so to
// `reply_port`, records the one-way latency of each datagram (stamp, then sequence: a multicast
// copy that comes twice is counted once) and prints its p50 and p99.
int UdpFanPeer(std::uint16_t port, std::uint16_t reply_port, bool multicast) {
  const int fd = socket(AF_INET, SOCK_DGRAM, 0);
  const int one = 1;
  setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_addr.s_addr = htonl(multicast ? INADDR_ANY : INADDR_LOOPBACK);
  addr.sin_port = htons(port);
  if (fd < 0 || bind(fd, reinterpret_cast<const sockaddr*>(&addr), sizeof addr) != 0) {
    std::perror("net_bench: udp fan socket");
    return 1;
  }
  if (multicast) {
    ip_mreq m{};
    inet_pton(AF_INET, kFanGroup, &m.imr_multiaddr);
    m.imr_interface.s_addr = htonl(INADDR_LOOPBACK);
    if (setsockopt(fd, IPPROTO_IP, IP_ADD_MEMBERSHIP, &m, sizeof m) != 0) {
      std::perror("net_bench: IP_ADD_MEMBERSHIP on lo");
      return 1;
    }
  }
  timeval tv{2, 0};
  setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
  const sockaddr_in back = Loopback(reply_port);
  std::vector<std::uint8_t> buf(65536);
  sendto(fd, buf.data(), 1, 0, reinterpret_cast<const sockaddr*>(&back), sizeof back);  // ready
  vdyn::Histogram one_way;
  std::int64_t last_seq = -1;
  while (one_way.count() < static_cast<std::uint64_t>(kUdpDatagrams)) {
    const ssize_t n = recv(fd, buf.data(), buf.size(), 0);
    const std::int64_t now = vdyn::base::MonotonicNow().ns;
    if (n < 16) break;
    std::int64_t stamp, seq;
    std::memcpy(&stamp, buf.data(), sizeof stamp);
    std::memcpy(&seq, buf.data() + 8, sizeof seq);
    if (seq <= last_seq) continue;
    last_seq = seq;
    one_way.Add(static_cast<double>(now - stamp) * 1e-3);
  }
  std::printf("udp_fan %llu %.1f %.1f\n", static_cast<unsigned long long>(one_way.count()),
              one_way.Percentile(50), one_way.Percentile(99));
  return 0;
}

// `receivers` processes, each stamped datagram sent to every one of them (one sendto each) or
// once to a group they joined on lo; each receiver's one-way p50 and p99, by p50.
std::vector<std::pair<double, double>> MeasureUdpFanout(const char* self, std::size_t size,
                                                        const std::string& tmp, int receivers,
                                                        bool multicast) {
  const auto base_port = static_cast<std::uint16_t>(30000 + getpid() % 4000 * 2);
  const auto reply_port = static_cast<std::uint16_t>(base_port + 1);
  sockaddr_in mine;
  const int fd = UdpSocket(reply_port, mine);
  std::vector<pid_t> children;
  for (int i = 0; i < receivers; ++i) {
    const auto port = static_cast<std::uint16_t>(multicast ? base_port + 2 : base_port + 2 + i);
    children.push_back(Spawn({self, "--udp-fan", std::to_string(port), std::to_string(reply_port),
                              multicast ? "multi" : "uni"},
                             tmp + "-udp-fan" + std::to_string(i) + ".log"));
  }
  std::vector<std::uint8_t> buf(std::max<std::size_t>(size, 16));
  for (int i = 0; i < receivers; ++i) {
    if (recv(fd, buf.data(), buf.size(), 0) < 1)
      std::fprintf(stderr, "net_bench: a UDP receiver did not start\n");
  }
  if (multicast) {
    in_addr lo{};
    lo.s_addr = htonl(INADDR_LOOPBACK);
    setsockopt(fd, IPPROTO_IP, IP_MULTICAST_IF, &lo, sizeof lo);
    const unsigned char loop = 1;
    setsockopt(fd, IPPROTO_IP, IP_MULTICAST_LOOP, &loop, sizeof loop);
  }
  std::vector<sockaddr_in> to;
  if (multicast) {
    sockaddr_in g{};
    g.sin_family = AF_INET;
    inet_pton(AF_INET, kFanGroup, &g.sin_addr);
    g.sin_port = htons(static_cast<std::uint16_t>(base_port + 2));
    to.push_back(g);
  } else {
    for (int i = 0; i < receivers; ++i)
      to.push_back(Loopback(static_cast<std::uint16_t>(base_port + 2 + i)));
  }
  std::int64_t next = vdyn::base::MonotonicNow().ns;
  for (std::int64_t seq = 0; seq < kUdpDatagrams; ++seq) {
    vdyn::base::SleepUntil({next += 1'000'000});
    const std::int64_t t0 = vdyn::base::MonotonicNow().ns;
    std::memcpy(buf.data(), &t0, sizeof t0);
    std::memcpy(buf.data() + 8, &seq, sizeof seq);
    for (const sockaddr_in& a : to) {
      sendto(fd, buf.data(), buf.size(), 0, reinterpret_cast<const sockaddr*>(&a), sizeof a);
    }
  }
  std::vector<std::pair<double, double>> r;
  for (int i = 0; i < receivers; ++i) {
    WaitPid(children[static_cast<std::size_t>(i)]);
    const std::string out = vdyn::bench::Slurp(tmp + "-udp-fan" + std::to_string(i) + ".log");
    double p50 = 0, p99 = 0;
    unsigned long long n = 0;
    if (const auto at = out.find("udp_fan "); at != std::string::npos) {
      std::sscanf(out.c_str() + at, "udp_fan %llu %lf %lf", &n, &p50, &p99);
    }
    r.emplace_back(p50, p99);
  }
  close(fd);
  std::sort(r.begin(), r.end());
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
  if (argc >= 5 && std::string(argv[1]) == "--udp-fan") {
    return UdpFanPeer(static_cast<std::uint16_t>(std::atoi(argv[2])),
                      static_cast<std::uint16_t>(std::atoi(argv[3])),
                      std::string(argv[4]) == "multi");
  }
  if (argc >= 6 && std::string(argv[1]) == "--subscriber") {
    return Subscriber(static_cast<std::uint32_t>(std::atoi(argv[2])), std::atof(argv[3]),
                      std::atof(argv[4]), ParseRoute(argv[5]));
  }
  const double seconds = argc > 1 ? std::atof(argv[1]) : 60.0;
  const double ddsperf_seconds = argc > 2 ? std::atof(argv[2]) : 20.0;
  const int subscribers = argc > 3 ? std::atoi(argv[3]) : 3;
  const std::string route_name = argc > 4 ? argv[4] : "follow";
  const Route route = ParseRoute(route_name);
  if (seconds <= 0 || ddsperf_seconds <= 0 || subscribers < 1 || subscribers > 16 ||
      (route_name != "follow" && route_name != "states" && route_name != "tool")) {
    std::fprintf(stderr,
                 "usage: net_bench [seconds > 0] [ddsperf_seconds > 0] [subscribers 1-16] "
                 "[follow|states|tool]\n");
    return 2;
  }
  // VDYN_SERVER: another server binary (a peer build) measured by this same bench.
  const char* server_binary =
      std::getenv("VDYN_SERVER") ? std::getenv("VDYN_SERVER") : VDYN_SERVER_BINARY;
  if (std::getenv("CYCLONEDDS_URI") == nullptr) {
    setenv("CYCLONEDDS_URI",
           "<General><Interfaces><NetworkInterface name=\"lo\"/></Interfaces></General>"
           "<Discovery><MaxAutoParticipantIndex>64</MaxAutoParticipantIndex></Discovery>",
           1);
  }
  const std::uint32_t domain = 150 + static_cast<std::uint32_t>(getpid()) % 60;
  const std::string tmp = "/tmp/vdyn-net-bench-" + std::to_string(getpid());
  const double warmup = 3.0;

  const pid_t server =
      Spawn({server_binary, "--domain", std::to_string(domain), "--world", "facility",
             "--no-status", "--duration", std::to_string(seconds + warmup + 1.0), "--stats-out",
             tmp + "-stats.txt", "--watchdog-ms", "100"},
            tmp + "-server.log");
  std::vector<pid_t> subs;
  for (int i = 0; i + 1 < subscribers; ++i) {
    subs.push_back(Spawn({argv[0], "--subscriber", std::to_string(domain), std::to_string(warmup),
                          std::to_string(seconds), route_name},
                         tmp + "-sub" + std::to_string(i) + ".log"));
  }

  // Declared before the reader, whose listener uses them until the reader is deleted.
  Latency own;
  vdyn::Histogram input_to_state;
  std::uint64_t received = 0, last_seq = 0;
  std::atomic<bool> measuring{false};
  std::atomic<std::size_t> state_bytes{0};
  std::mutex mu;  // the histograms are read by the main thread at the end
  vdyn::transport::Participant participant(domain);
  vdyn::transport::DropCounters drops;
  Subscription states(participant, drops, route);
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

  const std::int64_t t0 = vdyn::base::MonotonicNow().ns;
  const std::int64_t measure_from = t0 + static_cast<std::int64_t>(warmup * 1e9);
  const std::int64_t measure_to = measure_from + static_cast<std::int64_t>(seconds * 1e9);
  states.Listen([&](const vdyn::pb::VehicleState& s, std::int64_t at, std::int64_t source) {
    const std::int64_t now_mono = vdyn::base::MonotonicNow().ns;
    if (!measuring) return;
    std::lock_guard<std::mutex> lock(mu);
    state_bytes = s.ByteSizeLong();
    ++received;
    own.Add(at, source);
    if (s.input().sequence() > last_seq && s.input().stamp_ns() > 0) {
      last_seq = s.input().sequence();
      input_to_state.Add(static_cast<double>(now_mono - s.input().stamp_ns()) * 1e-3);
    }
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
  // Every subscriber's figures: this process's and the children's (one_way p50, p99, to the
  // listener p50, p99), by one-way p50.
  struct Sub {
    unsigned long long n = 0;
    double p50 = 0, p99 = 0, l50 = 0, l99 = 0;
  };
  std::vector<Sub> all;
  {
    std::lock_guard<std::mutex> lock(mu);
    all.push_back({own.one_way.count(), own.one_way.Percentile(50), own.one_way.Percentile(99),
                   own.to_listener.Percentile(50), own.to_listener.Percentile(99)});
  }
  for (std::size_t i = 0; i < subs.size(); ++i) {
    WaitPid(subs[i]);
    const std::string out = vdyn::bench::Slurp(tmp + "-sub" + std::to_string(i) + ".log");
    Sub sub;
    const auto at = out.find("subscriber ");
    if (at != std::string::npos) {
      std::sscanf(out.c_str() + at, "subscriber %llu %lf %lf %lf %lf", &sub.n, &sub.p50, &sub.p99,
                  &sub.l50, &sub.l99);
    }
    all.push_back(sub);
  }
  std::sort(all.begin(), all.end(), [](const Sub& a, const Sub& b) { return a.p50 < b.p50; });
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
  std::vector<std::pair<double, double>> fan_uni, fan_multi;
  if (subscribers > 1) {
    fan_uni = MeasureUdpFanout(argv[0], size, tmp, subscribers, false);
    fan_multi = MeasureUdpFanout(argv[0], size, tmp, subscribers, true);
  }

  const double cpu = 100.0 * (cpu1 - cpu0) / seconds;
  std::printf(
      "net_bench: %.0f s of the real-time server on facility, %d state subscriber(s), input at 1 "
      "kHz\n",
      seconds, subscribers);
  std::printf("server exit code %d, scheduling: %s\n", server_code, stats["scheduling"].c_str());
  std::printf("tick lateness: p50 %s us, p99 %s us, p99.9 %s us, max %s us; under 1 ms: %.3f %%\n",
              stats["lateness_p50_us"].c_str(), stats["lateness_p99_us"].c_str(),
              stats["lateness_p999_us"].c_str(), stats["lateness_max_us"].c_str(),
              100.0 * std::atof(stats["fraction_under_1ms"].c_str()));
  std::printf(
      "steps %s of %s due (never run: %lld), caught up %s, largest lag %s steps, rebases %s\n",
      stats["steps"].c_str(), stats["steps_due"].c_str(),
      std::atoll(stats["steps_due"].c_str()) - std::atoll(stats["steps"].c_str()),
      stats["steps_caught_up"].c_str(), stats["max_lag_steps"].c_str(),
      stats["schedule_rebases"].c_str());
  std::printf("drift of simulation time against the wall clock at the end: %s ms over %s s\n",
              stats["drift_ms"].c_str(), stats["wall_s"].c_str());
  std::printf("server CPU with %d subscriber(s): %.1f %% of one core (whole run: %s %%)\n",
              subscribers, cpu, stats["cpu_percent"].c_str());
  const Latency& one = own;
  const auto& one_way = one.one_way;
  std::printf(
      "state one-way latency, this process (%llu states, %zu B, route %s): p50 %.1f us, "
      "p99 %.1f us, max %.1f us\n",
      static_cast<unsigned long long>(received), state_bytes.load(), route_name.c_str(),
      one_way.Percentile(50), one_way.Percentile(99), one_way.Max());
  std::printf(
      "  of which to the listener's call (before take and decode): p50 %.1f us, p99 %.1f us\n",
      one.to_listener.Percentile(50), one.to_listener.Percentile(99));
  for (std::size_t k = 0; k < all.size(); ++k) {
    std::printf(
        "subscriber %zu of %zu by p50 (%llu states): one-way p50 %.1f us, p99 %.1f us; to the "
        "listener p50 %.1f us, p99 %.1f us; p50 / first's %.2f\n",
        k + 1, all.size(), all[k].n, all[k].p50, all[k].p99, all[k].l50, all[k].l99,
        all[0].p50 > 0 ? all[k].p50 / all[0].p50 : 0.0);
  }
  std::vector<double> p50s, p99s;
  for (const Sub& x : all) {
    p50s.push_back(x.p50);
    p99s.push_back(x.p99);
  }
  const double sub_p50 = vdyn::bench::Median(p50s), sub_p99 = vdyn::bench::Median(p99s);
  std::printf(
      "subscribers' median: one-way p50 %.1f us, p99 %.1f us; the last's p50 / the first's %.2f\n",
      sub_p50, sub_p99, all[0].p50 > 0 ? all.back().p50 / all[0].p50 : 0.0);
  std::printf(
      "server's state writer (%s rounds): hand-over to wake-up p50 %s us, p99 %s us; "
      "writes and flush p50 %s us, p99 %s us, of it the thread's CPU p50 %s us, p99 %s us\n",
      stats["state_rounds"].c_str(), stats["state_wake_p50_us"].c_str(),
      stats["state_wake_p99_us"].c_str(), stats["state_send_p50_us"].c_str(),
      stats["state_send_p99_us"].c_str(), stats["state_send_cpu_p50_us"].c_str(),
      stats["state_send_cpu_p99_us"].c_str());
  if (input_write_failures > 0) {
    std::printf("input writes that failed: %llu\n",
                static_cast<unsigned long long>(input_write_failures.load()));
  }
  std::printf(
      "input to first state applying it (%llu inputs): p50 %.1f us, p99 %.1f us, max %.1f us\n",
      static_cast<unsigned long long>(input_to_state.count()), input_to_state.Percentile(50),
      input_to_state.Percentile(99), input_to_state.Max());
  std::printf(
      "ddsperf ping/pong 1 kHz, %zu B, same run: round trip p50 %.1f us, p99 %.1f us -> "
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
  for (const auto* fan : {&fan_uni, &fan_multi}) {
    if (fan->empty()) continue;
    std::string list;
    for (const auto& [p50, p99] : *fan) {
      char item[48];
      std::snprintf(item, sizeof item, " %.1f / %.1f;", p50, p99);
      list += item;
    }
    std::printf(
        "bare UDP to %d receivers, %s, same run: one-way p50 / p99 by receiver (us):%s the "
        "last's p50 / the first's %.2f\n",
        subscribers, fan == &fan_uni ? "one sendto each (unicast)" : "one multicast sendto on lo",
        list.c_str(), fan->front().first > 0 ? fan->back().first / fan->front().first : 0.0);
  }
  if (udp.one_way50 > 0) {
    std::printf(
        "ratio vdyn state one-way / bare UDP one-way: p50 %.2f, p99 %.2f (this process); "
        "subscribers' median p50 %.2f, p99 %.2f; the last subscriber's p50 %.2f (what DDS, the "
        "server's state writer, the take and the decode add to the same wake-up)\n",
        one_way.Percentile(50) / udp.one_way50, one_way.Percentile(99) / udp.one_way99,
        sub_p50 / udp.one_way50, sub_p99 / udp.one_way99, all.back().p50 / udp.one_way50);
  }
  return server_code;
}
