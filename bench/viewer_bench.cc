// viewer_bench: vdyn-viewer's frame time and state-to-screen latency, measured as a person runs
// it: a real-time vdyn-server on `facility` with 1 and then 64 vehicles, and vdyn-viewer (chase
// camera on vehicle 1, 1280x720, HUD on) drawing into a private Xvfb through Mesa (llvmpipe on a
// machine without a GPU: the renderer is printed). Each case is run for --quality low and high,
// and, when a peer binary is given (the viewer of an earlier commit, built apart), for it too, in
// the same run, interleaved (peer, low, high each time), so that load on a shared machine falls on
// all alike.
//  - frame time: work per frame, from its first event to its image presented and finished
//    (glFinish), with no frame-rate cap (--fps 0): what the machine can draw;
//  - latency: from a state's DDS source stamp (the server's wall clock, same machine) to the
//    moment the frame that first shows it is presented, at the viewer's default 60 Hz cap.
// Each case runs `runs` times for `frames` frames; medians over the runs of each run's p50 and
// p99 are printed, and each viewer's frame-time p50 over the peer's. With `both` after the peer,
// the peer runs at --quality low and high too, and each quality is compared with the peer's same.
//
// Usage: viewer_bench [runs=3] [frames=600] [peer-viewer-binary [both]]
#include <signal.h>
#include <unistd.h>

#include <algorithm>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <map>
#include <string>
#include <vector>

#include "child.h"

namespace {

// Children still running (Xvfb, server, viewer): a signal to the bench ends them too.
volatile pid_t g_children[3] = {-1, -1, -1};
extern "C" void OnSignal(int sig) {
  for (pid_t p : g_children) {
    if (p > 0) kill(p, SIGKILL);
  }
  _exit(128 + sig);
}
void Track(int slot, pid_t pid) {
  g_children[slot] = pid;
}

using vdyn::bench::Median;
using vdyn::bench::ReadStats;
using vdyn::bench::Spawn;
using vdyn::bench::WaitPid;

// The 1-minute load average (other work on a shared machine slows a CPU renderer down).
std::string LoadAverage() {
  std::ifstream in("/proc/loadavg");
  std::string one;
  in >> one;
  return one.empty() ? "?" : one;
}

double Num(const std::map<std::string, std::string>& kv, const std::string& key) {
  const auto it = kv.find(key);
  return it == kv.end() ? 0.0 : std::atof(it->second.c_str());
}

}  // namespace

int main(int argc, char** argv) {
  const int runs = argc > 1 ? std::max(1, std::atoi(argv[1])) : 3;
  const int frames = argc > 2 ? std::max(10, std::atoi(argv[2])) : 600;
  setenv("CYCLONEDDS_URI",
         "<General><Interfaces><NetworkInterface name=\"lo\"/></Interfaces></General>"
         "<Discovery><MaxAutoParticipantIndex>120</MaxAutoParticipantIndex></Discovery>",
         1);
  const std::string tmp = "/tmp/vdyn-viewer-bench-" + std::to_string(getpid());
  std::system(("mkdir -p " + tmp).c_str());
  std::signal(SIGINT, OnSignal);
  std::signal(SIGTERM, OnSignal);
  const pid_t xvfb = vdyn::bench::StartXvfb(tmp + "/xvfb.log", "1920x1080x24");
  if (xvfb < 0) {
    std::fprintf(stderr, "viewer_bench: Xvfb did not start (install xvfb); see %s/xvfb.log\n",
                 tmp.c_str());
    return 1;
  }
  Track(0, xvfb);
  std::string renderer;
  std::printf(
      "viewer_bench: vdyn-viewer on facility, chase camera, 1280x720, HUD on, %d runs x "
      "%d frames per case; load average %s at the start\n",
      runs, frames, LoadAverage().c_str());
  if (argc > 3) std::printf("peer: %s\n", argv[3]);
  struct Variant {
    std::string name, binary, quality;  // quality empty: the peer (no --quality option)
  };
  std::vector<Variant> variants;
  if (argc > 4 && std::string(argv[4]) == "both") {
    variants.push_back({"peer-low", argv[3], "low"});
    variants.push_back({"peer-high", argv[3], "high"});
  } else if (argc > 3) {
    variants.push_back({"peer", argv[3], ""});
  }
  variants.push_back({"low", VDYN_VIEWER_BINARY, "low"});
  variants.push_back({"high", VDYN_VIEWER_BINARY, "high"});
  std::printf("%-9s %-9s %-24s %-7s %-10s %-24s %-24s\n", "vehicles", "viewer",
              "frame p50/p99 ms no cap", "fps", "p50/peer", "frame p50/p99 ms 60 Hz",
              "latency p50/p99 ms 60 Hz");
  const int domain_base = 150 + getpid() % 40;
  int domain = domain_base;
  for (int vehicles : {1, 64}) {
    std::string ids;
    for (int i = 1; i <= vehicles; ++i) {
      if (i > 1) ids += ',';
      ids += std::to_string(i);
    }
    struct Samples {
      std::vector<double> f50, f99, c50, c99, l50, l99;
    };
    std::vector<Samples> samples(variants.size());
    for (int r = 0; r < runs; ++r) {
      for (bool capped : {false, true}) {
        ++domain;
        const pid_t server =
            Spawn({VDYN_SERVER_BINARY, "--domain", std::to_string(domain), "--world", "facility",
                   "--vehicle-ids", ids, "--duration", "3600", "--no-status"},
                  tmp + "/server.log");
        Track(1, server);
        for (std::size_t k = 0; k < variants.size(); ++k) {
          const Variant& var = variants[k];
          const std::string stats = tmp + "/stats.txt";
          std::remove(stats.c_str());
          std::vector<std::string> args = {var.binary,
                                           "--domain",
                                           std::to_string(domain),
                                           "--follow",
                                           "1",
                                           "--camera",
                                           "chase",
                                           "--width",
                                           "1280",
                                           "--height",
                                           "720",
                                           "--fps",
                                           capped ? "60" : "0",
                                           "--frames",
                                           std::to_string(frames),
                                           "--wait",
                                           "60",
                                           "--stats-out",
                                           stats};
          if (!var.quality.empty()) {
            args.push_back("--quality");
            args.push_back(var.quality);
          }
          const pid_t viewer = Spawn(args, tmp + "/viewer-" + var.name + ".log");
          Track(2, viewer);
          const int code = WaitPid(viewer);
          Track(2, -1);
          const auto kv = ReadStats(stats);
          if (code != 0 || kv.empty() || Num(kv, "vehicles") < vehicles) {
            std::fprintf(stderr,
                         "viewer_bench: run of the %s viewer failed (exit %d, %g vehicles seen); "
                         "see %s\n",
                         var.name.c_str(), code, Num(kv, "vehicles"), tmp.c_str());
            kill(server, SIGKILL);
            kill(xvfb, SIGTERM);
            return 1;
          }
          renderer = kv.count("renderer") ? kv.at("renderer") : "?";
          Samples& sm = samples[k];
          if (capped) {
            sm.c50.push_back(Num(kv, "frame_ms_p50"));
            sm.c99.push_back(Num(kv, "frame_ms_p99"));
            sm.l50.push_back(Num(kv, "latency_ms_p50"));
            sm.l99.push_back(Num(kv, "latency_ms_p99"));
          } else {
            sm.f50.push_back(Num(kv, "frame_ms_p50"));
            sm.f99.push_back(Num(kv, "frame_ms_p99"));
          }
        }
        kill(server, SIGINT);
        WaitPid(server);
        Track(1, -1);
      }
    }
    // Each viewer against the peer at its quality (or the one peer).
    auto peer50_for = [&](const Variant& v) {
      for (std::size_t k = 0; k < variants.size(); ++k) {
        if (variants[k].name == "peer" || variants[k].name == "peer-" + v.quality) {
          return Median(samples[k].f50);
        }
      }
      return 0.0;
    };
    for (std::size_t k = 0; k < variants.size(); ++k) {
      const Samples& sm = samples[k];
      const double fp50 = Median(sm.f50);
      const double peer50 = peer50_for(variants[k]);
      char ratio[32] = "-";
      if (peer50 > 0) std::snprintf(ratio, sizeof ratio, "%.2f", fp50 / peer50);
      std::printf("%-9d %-9s %8.2f / %-13.2f %-7.1f %-10s %8.2f / %-13.2f %8.2f / %-13.2f\n",
                  vehicles, variants[k].name.c_str(), fp50, Median(sm.f99),
                  fp50 > 0 ? 1000.0 / fp50 : 0.0, ratio, Median(sm.c50), Median(sm.c99),
                  Median(sm.l50), Median(sm.l99));
    }
    std::fflush(stdout);
  }
  std::printf(
      "renderer: %s (Mesa under Xvfb: software rendering on the CPU); load average %s "
      "at the end\n",
      renderer.c_str(), LoadAverage().c_str());
  kill(xvfb, SIGTERM);
  WaitPid(xvfb);
  std::system(("rm -rf " + tmp).c_str());
  return 0;
}
