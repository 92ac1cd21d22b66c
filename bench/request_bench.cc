// request_bench: the real-time server's tick lateness with and without bursts of control requests
// (issue 19: "requests never stall the loop"). One run, on one machine, over loopback:
//  - vdyn-server in real time on `facility` with 48 vehicles for N s, idle (the peer), then the
//    same with a burst of 16 spawns every 250 ms (each burst's vehicles removed by the next burst:
//    the vehicle count stays 48..64), alternating, R runs each;
//  - from the server's run summary (--stats-out): tick lateness p50 / p99 / p99.9 / max, and how
//    long requests held a boundary (the boundaries that applied any: p50 / p99 / max);
//  - every reply counted at this client: each request must get exactly one.
//
// Usage: request_bench [seconds=20] [runs=3] [server binary (default: this build's vdyn-server)]
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <string>
#include <thread>
#include <vector>

#include "child.h"
#include "vdyn/base/time.h"
#include "vdyn/control.pb.h"
#include "vdyn/transport/dds.h"

namespace {

using vdyn::bench::Median;
using vdyn::bench::ReadStats;
using vdyn::bench::Spawn;
using vdyn::bench::WaitPid;
using vdyn::transport::TopicId;

constexpr int kVehicles = 48;
constexpr int kBurst = 16;

struct Run {
  std::map<std::string, double> stats;
  std::uint64_t sent = 0, replies = 0, duplicates = 0, refused = 0;
  std::string first_refusal;
};

// One server run: idle, or with bursts. The server is a child; this process is its client.
Run RunOnce(const std::string& server, std::uint32_t domain, double seconds, bool bursts,
            const std::filesystem::path& dir, int index) {
  // Built by appending (GCC 12 warns, wrongly, on a literal + std::string here).
  std::string tag = bursts ? "burst" : "idle";
  tag += std::to_string(index);
  const auto stats = dir / (tag + std::string(".stats"));
  std::string ids;
  for (int i = 1; i <= kVehicles; ++i) {
    if (i > 1) ids += ',';
    ids += std::to_string(i);
  }
  const pid_t pid = Spawn({server, "--world", "facility", "--domain", std::to_string(domain),
                           "--server-id", "bench", "--vehicle-ids", ids, "--duration",
                           std::to_string(seconds), "--no-status", "--stats-out", stats.string()},
                          dir / (tag + std::string(".log")));
  Run run;
  {
    vdyn::transport::Participant p(domain);
    vdyn::transport::DropCounters drops;
    vdyn::transport::Writer<vdyn::pb::ControlRequest> writer(p, TopicId::kControl);
    vdyn::transport::Reader<vdyn::pb::ControlReply> replies(p, TopicId::kControlReply, &drops);
    std::map<std::uint64_t, int> answered;
    auto take = [&] {
      (void)replies.Take([&](const vdyn::pb::ControlReply& r, const vdyn::transport::SampleInfo&) {
        if (r.client_id() != "request_bench") return;
        if (++answered[r.request_id()] > 1) ++run.duplicates;
        if (!r.accepted()) {
          ++run.refused;
          if (run.first_refusal.empty()) run.first_refusal = r.reason();
        }
      });
    };
    // The server is up when its reader matches ours (its start, 48 vehicles, takes a while).
    const auto start = std::chrono::steady_clock::now();
    while (writer.MatchedReaders() == 0 &&
           std::chrono::steady_clock::now() - start < std::chrono::seconds(60)) {
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    const auto t0 = std::chrono::steady_clock::now();
    std::uint64_t id = 0;
    int burst = 0;
    // Bursts until 1 s before the end; the last reply waits at most 5 s more.
    while (std::chrono::steady_clock::now() - t0 < std::chrono::duration<double>(seconds - 1.0)) {
      const auto next = std::chrono::steady_clock::now() + std::chrono::milliseconds(250);
      if (bursts) {
        const bool spawn = burst % 2 == 0;
        for (int k = 0; k < kBurst; ++k) {
          vdyn::pb::ControlRequest r;
          r.set_request_id(++id);
          r.set_client_id("request_bench");
          r.set_server_id("bench");
          r.set_vehicle_id(static_cast<std::uint32_t>(1000 + k));
          if (spawn) {
            r.mutable_spawn()->mutable_pose()->set_x(-240.0 + 10.0 * k);
            r.mutable_spawn()->mutable_pose()->set_y(-3.0);
          } else {
            r.mutable_remove();
          }
          if (writer.Write(r.vehicle_id(), r)) ++run.sent;
        }
        ++burst;
      }
      while (std::chrono::steady_clock::now() < next) {
        (void)replies.Wait(std::chrono::milliseconds(10));
        take();
      }
    }
    const auto wait_end = std::chrono::steady_clock::now() + std::chrono::seconds(5);
    while (answered.size() < run.sent && std::chrono::steady_clock::now() < wait_end) {
      (void)replies.Wait(std::chrono::milliseconds(10));
      take();
    }
    run.replies = answered.size();
  }
  const int code = WaitPid(pid);
  if (code != 0) std::fprintf(stderr, "%s: the server ended with %d\n", tag.c_str(), code);
  for (const auto& [k, v] : ReadStats(stats)) run.stats[k] = std::atof(v.c_str());
  return run;
}

}  // namespace

int main(int argc, char** argv) {
  const double seconds = argc > 1 ? std::atof(argv[1]) : 20.0;
  const int runs = argc > 2 ? std::atoi(argv[2]) : 3;
  const std::string server = argc > 3 ? argv[3] : VDYN_SERVER_BINARY;
  std::string name = "vdyn-request-bench-";
  name += std::to_string(getpid());
  const auto dir = std::filesystem::temp_directory_path() / name;
  std::filesystem::create_directories(dir);
  const std::uint32_t domain = 200 + static_cast<std::uint32_t>(getpid() % 30);
  std::printf("request_bench: %s, facility, %d vehicles, %g s per run, %d runs each, domain %u\n",
              server.c_str(), kVehicles, seconds, runs, domain);
  std::map<bool, std::vector<Run>> all;
  for (int i = 0; i < runs; ++i) {
    for (const bool bursts : {false, true}) {
      Run r = RunOnce(server, domain, seconds, bursts, dir, i);
      std::printf(
          "  %-5s run %d: lateness p50 %6.1f p99 %6.1f p99.9 %7.1f max %8.1f us; "
          "requests held a boundary p50 %5.1f p99 %5.1f max %6.1f us (%.0f boundaries); "
          "%llu sent, %llu answered, %llu twice, %llu refused%s%s\n",
          bursts ? "burst" : "idle", i, r.stats["lateness_p50_us"], r.stats["lateness_p99_us"],
          r.stats["lateness_p999_us"], r.stats["lateness_max_us"],
          r.stats["request_boundary_p50_us"], r.stats["request_boundary_p99_us"],
          r.stats["request_boundary_max_us"], r.stats["request_boundaries"],
          static_cast<unsigned long long>(r.sent), static_cast<unsigned long long>(r.replies),
          static_cast<unsigned long long>(r.duplicates), static_cast<unsigned long long>(r.refused),
          r.refused ? ": " : "", r.first_refusal.c_str());
      std::fflush(stdout);
      all[bursts].push_back(std::move(r));
    }
  }
  auto median = [&](bool bursts, const char* key) {
    std::vector<double> v;
    for (const Run& r : all[bursts]) {
      const auto it = r.stats.find(key);
      v.push_back(it == r.stats.end() ? 0.0 : it->second);
    }
    return Median(v);
  };
  std::printf("\nmedians of %d runs         idle      bursts of %d spawns   bursts / idle\n", runs,
              kBurst);
  for (const char* key : {"lateness_p50_us", "lateness_p99_us", "lateness_p999_us",
                          "lateness_max_us", "steps_caught_up"}) {
    const double a = median(false, key), b = median(true, key);
    std::printf("  %-22s %9.1f %18.1f %14.2f\n", key, a, b, a > 0 ? b / a : 0.0);
  }
  for (const char* key : {"request_boundary_p50_us", "request_boundary_p99_us",
                          "request_boundary_max_us", "cpu_percent"}) {
    std::printf("  %-22s %9.1f %18.1f\n", key, median(false, key), median(true, key));
  }
  std::uint64_t sent = 0, replies = 0, duplicates = 0;
  for (const Run& r : all[true]) {
    sent += r.sent;
    replies += r.replies;
    duplicates += r.duplicates;
  }
  std::printf("  requests sent %llu, answered %llu, answered twice %llu\n",
              static_cast<unsigned long long>(sent), static_cast<unsigned long long>(replies),
              static_cast<unsigned long long>(duplicates));
  std::filesystem::remove_all(dir);
  return replies == sent && duplicates == 0 ? 0 : 1;
}
