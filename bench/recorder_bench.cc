// recorder_bench: vdyn-recorder against a live server over loopback DDS.
//
//   record   1, 8 and 64 vehicles at 1 kHz (vdyn-server --vehicle-ids, world flat) for SECONDS:
//            the recorder's CPU per simulated minute (all its threads, from wait4's rusage), the
//            bytes it wrote per simulated minute, and what it lost or dropped. Peer, same run: a
//            plain subscriber that takes and decodes every state and writes nothing, in a session of its own.
//   export   the 1-vehicle recording to CSV, as a multiple of real time; peer: the batch run of
//            the same simulated time writing the same CSV (vdyn-server --batch --csv).
//   verify   the same recording re-simulated and checked, as a multiple of real time; peer: the
//            batch run of the same time without output.
// Medians of REPS runs. Usage: recorder_bench [SECONDS=30] [REPS=3]
//                              recorder_bench --subscribe DOMAIN SECONDS   (the peer subscriber)
#include <signal.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <regex>
#include <string>
#include <thread>
#include <vector>

#include "child.h"
#include "vdyn/state.pb.h"
#include "vdyn/transport/dds.h"


namespace {

using vdyn::bench::Median;
using vdyn::bench::Slurp;
using vdyn::bench::Spawn;
using vdyn::bench::WaitPid;

// Wall seconds of a command run to its end (exits on failure).
double Timed(const std::vector<std::string>& args, const std::filesystem::path& log) {
  const auto t0 = std::chrono::steady_clock::now();
  const int code = WaitPid(Spawn(args, log));
  const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (code != 0) {
    std::fprintf(stderr, "%s failed (%d):\n%s\n", args[0].c_str(), code, Slurp(log).c_str());
    std::exit(1);
  }
  return s;
}

int Subscribe(std::uint32_t domain, double seconds) {
  vdyn::transport::Participant p(domain);
  vdyn::transport::DropCounters drops;
  vdyn::transport::Reader<vdyn::pb::VehicleState> states(p, vdyn::transport::TopicId::kState, &drops,
                                                          vdyn::transport::ReaderRole::kRecorder);
  long n = 0;
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
  while (std::chrono::steady_clock::now() < end) {
    (void)states.Wait(std::chrono::milliseconds(100));
    n += states.Take([](const vdyn::pb::VehicleState&, const vdyn::transport::SampleInfo&) {});
  }
  std::printf("received %ld\n", n);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc >= 4 && std::string(argv[1]) == "--subscribe") {
    return Subscribe(static_cast<std::uint32_t>(std::atoi(argv[2])), std::atof(argv[3]));
  }
  const double seconds = argc > 1 ? std::atof(argv[1]) : 30.0;
  const int reps = argc > 2 ? std::atoi(argv[2]) : 3;
  const std::string server = VDYN_SERVER_BINARY, recorder = VDYN_RECORDER_BINARY;
  if (std::getenv("CYCLONEDDS_URI") == nullptr) {
    setenv("CYCLONEDDS_URI",
           "<General><Interfaces><NetworkInterface name=\"lo\"/></Interfaces></General>"
           "<Discovery><MaxAutoParticipantIndex>120</MaxAutoParticipantIndex></Discovery>", 1);
  }
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / ("recorder_bench_" + std::to_string(getpid()));
  std::filesystem::create_directories(dir);
  const double sim_min = seconds / 60.0;
  std::printf("recorder_bench: %g s of simulated time per run, %d runs, medians; world flat, loopback\n", seconds, reps);
  std::printf("%-9s %-26s %-22s %-15s %-12s %-26s\n", "vehicles", "recorder CPU per sim min", "recorder CPU",
              "bytes/sim min", "lost+drop", "peer subscriber CPU/sim min");
  std::uint32_t domain = 200 + static_cast<std::uint32_t>(getpid() % 20);
  std::filesystem::path one_vehicle;
  for (int n : {1, 8, 64}) {
    std::vector<double> cpu, core, bytes, peer;
    std::uint64_t losses = 0;
    for (int r = 0; r < reps; ++r) {
      ++domain;
      // Appends, not "literal" + std::to_string(): GCC 12's -Wrestrict false positive at -O3.
      std::string name = "v";
      name += std::to_string(n);
      name += '-';
      name += std::to_string(r);
      name += ".mcap";
      const auto file = dir / name;
      std::string ids;
      for (int v = 1; v <= n; ++v) {
        if (v > 1) ids += ',';
        ids += std::to_string(v);
      }
      // The same session twice, one after the other: once recorded, once read by the peer (on two
      // vCPUs the two together would share the cores the server leaves).
      auto run_server = [&]() {
        const pid_t srv = Spawn({server, "--domain", std::to_string(domain), "--world", "flat", "--vehicle-ids",
                                 ids, "--duration", std::to_string(seconds), "--no-status"},
                                dir / "server.log");
        if (WaitPid(srv) != 0) {
          std::fprintf(stderr, "server failed:\n%s\n", Slurp(dir / "server.log").c_str());
          std::exit(1);
        }
      };
      const pid_t rec = Spawn({recorder, "record", file.string(), "--domain", std::to_string(domain), "--no-status"},
                              dir / "rec.log");
      std::this_thread::sleep_for(std::chrono::seconds(1));  // joined before the server starts
      run_server();
      kill(rec, SIGINT);
      double rec_cpu = 0, sub_cpu = 0;
      const int rec_code = WaitPid(rec, &rec_cpu);
      ++domain;
      const pid_t sub = Spawn({argv[0], "--subscribe", std::to_string(domain), std::to_string(seconds + 4)},
                              dir / "sub.log");
      std::this_thread::sleep_for(std::chrono::seconds(1));
      run_server();
      WaitPid(sub, &sub_cpu);
      const std::string log = Slurp(dir / "rec.log");
      std::smatch m;
      if (rec_code != 0 || !std::regex_search(log, m, std::regex("lost ([0-9]+), dropped ([0-9]+); CPU [0-9.]+ s \\(([0-9.]+)%"))) {
        std::fprintf(stderr, "recorder failed (%d):\n%s\n", rec_code, log.c_str());
        return 1;
      }
      losses += std::stoull(m[1]) + std::stoull(m[2]);
      cpu.push_back(rec_cpu / sim_min);
      core.push_back(std::stod(m[3]));
      bytes.push_back(static_cast<double>(std::filesystem::file_size(file)) / sim_min);
      peer.push_back(sub_cpu / sim_min);
      if (n == 1 && r == reps - 1) {
        one_vehicle = file;
      } else {
        std::filesystem::remove(file);
      }
    }
    char a[64], b[64], c[64];
    std::snprintf(a, sizeof a, "%.2f s", Median(cpu));
    std::snprintf(b, sizeof b, "%.1f%% of one core", Median(core));
    std::snprintf(c, sizeof c, "%.1f MB", Median(bytes) / 1e6);
    std::printf("%-9d %-26s %-22s %-15s %-12llu %.2f s\n", n, a, b, c, static_cast<unsigned long long>(losses),
                Median(peer));
    std::fflush(stdout);
  }
  // Export and verify of the 1-vehicle recording, against batch runs of the same simulated time.
  std::vector<double> exp, exp_peer, ver, ver_peer;
  for (int r = 0; r < reps; ++r) {
    exp.push_back(seconds / Timed({recorder, "export", one_vehicle.string(), "--csv", (dir / "e.csv").string()}, dir / "e.log"));
    exp_peer.push_back(seconds / Timed({server, "--batch", "--world", "flat", "--maneuver", "demo", "--duration",
                                        std::to_string(seconds), "--csv", (dir / "b.csv").string(), "--quiet"},
                                       dir / "b.log"));
    ver.push_back(seconds / Timed({recorder, "verify", one_vehicle.string()}, dir / "v.log"));
    ver_peer.push_back(seconds / Timed({server, "--batch", "--world", "flat", "--maneuver", "demo", "--duration",
                                        std::to_string(seconds), "--quiet"},
                                       dir / "n.log"));
  }
  std::printf("export  %.0fx real time (peer: batch run writing the same CSV %.0fx; ratio %.2f)\n", Median(exp),
              Median(exp_peer), Median(exp) / Median(exp_peer));
  std::printf("verify  %.0fx real time (peer: batch run without output %.0fx; ratio %.2f)\n", Median(ver),
              Median(ver_peer), Median(ver) / Median(ver_peer));
  std::printf("%s", Slurp(dir / "v.log").c_str());
  std::filesystem::remove_all(dir);
  return 0;
}
