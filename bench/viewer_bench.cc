// viewer_bench: vdyn-viewer's frame time and state-to-screen latency, measured as a person runs
// it: a real-time vdyn-server on `facility` with 1 and then 64 vehicles, and vdyn-viewer (chase
// camera on vehicle 1, 1280x720, HUD on) drawing into a private Xvfb through Mesa (llvmpipe on a
// machine without a GPU: the renderer is printed).
//  - frame time: work per frame, from its first event to its image presented and finished
//    (glFinish), with no frame-rate cap (--fps 0): what the machine can draw;
//  - latency: from a state's DDS source stamp (the server's wall clock, same machine) to the
//    moment the frame that first shows it is presented, at the viewer's default 60 Hz cap.
// Each case runs `runs` times for `frames` frames; medians over the runs of each run's p50 and
// p99 are printed.
//
// Usage: viewer_bench [runs=3] [frames=600]
#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <map>
#include <string>
#include <vector>

extern char** environ;

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

// Starts argv with its output in `log`; `to_fd3` becomes the child's fd 3 (after `close_fd`,
// which may be 3 itself, is closed in the child).
pid_t Spawn(std::vector<std::string> argv, const std::string& log, int to_fd3 = -1,
            int close_fd = -1) {
  std::vector<char*> args;
  for (auto& a : argv) args.push_back(a.data());
  args.push_back(nullptr);
  posix_spawn_file_actions_t fa;
  posix_spawn_file_actions_init(&fa);
  posix_spawn_file_actions_addopen(&fa, 1, log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  posix_spawn_file_actions_adddup2(&fa, 1, 2);
  if (close_fd >= 0) posix_spawn_file_actions_addclose(&fa, close_fd);
  if (to_fd3 >= 0) posix_spawn_file_actions_adddup2(&fa, to_fd3, 3);
  pid_t pid = -1;
  if (posix_spawn(&pid, args[0], &fa, nullptr, args.data(), environ) != 0) {
    std::fprintf(stderr, "viewer_bench: cannot start %s\n", args[0]);
    std::exit(1);
  }
  posix_spawn_file_actions_destroy(&fa);
  return pid;
}

int WaitPid(pid_t pid) {
  int status = 0;
  waitpid(pid, &status, 0);
  return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
}

// Starts Xvfb on a free display (-displayfd) and sets DISPLAY; returns its pid.
pid_t StartXvfb(const std::string& log) {
  int fds[2];
  if (pipe(fds) != 0) std::exit(1);
  const pid_t pid = Spawn({"/usr/bin/Xvfb", "-displayfd", "3", "-screen", "0", "1920x1080x24",
                           "-nolisten", "tcp", "-noreset"},
                          log, fds[1], fds[0]);
  close(fds[1]);
  std::string number;
  pollfd p{fds[0], POLLIN, 0};
  for (int i = 0; i < 200 && number.find('\n') == std::string::npos; ++i) {
    if (poll(&p, 1, 100) <= 0) continue;
    char buf[16];
    const ssize_t n = read(fds[0], buf, sizeof buf);
    if (n <= 0) break;
    number.append(buf, static_cast<std::size_t>(n));
  }
  close(fds[0]);
  while (!number.empty() && number.back() == '\n') number.pop_back();
  if (number.empty()) {
    std::fprintf(stderr, "viewer_bench: Xvfb did not start (install xvfb); see %s\n", log.c_str());
    std::exit(1);
  }
  setenv("DISPLAY", (":" + number).c_str(), 1);
  return pid;
}

std::map<std::string, std::string> ReadStats(const std::string& path) {
  std::map<std::string, std::string> out;
  std::ifstream in(path);
  std::string line;
  while (std::getline(in, line)) {
    const auto sp = line.find(' ');
    if (sp != std::string::npos) out[line.substr(0, sp)] = line.substr(sp + 1);
  }
  return out;
}

double Median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

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
  const pid_t xvfb = StartXvfb(tmp + "/xvfb.log");
  Track(0, xvfb);
  std::string renderer;
  std::printf(
      "viewer_bench: vdyn-viewer on facility, chase camera, 1280x720, HUD on, %d runs x "
      "%d frames per case; load average %s at the start\n",
      runs, frames, LoadAverage().c_str());
  std::printf("%-9s %-24s %-7s %-24s %-24s\n", "vehicles", "frame p50/p99 ms no cap", "fps",
              "frame p50/p99 ms 60 Hz", "latency p50/p99 ms 60 Hz");
  const int domain_base = 150 + getpid() % 40;
  int domain = domain_base;
  for (int vehicles : {1, 64}) {
    std::string ids;
    for (int i = 1; i <= vehicles; ++i) {
      if (i > 1) ids += ',';
      ids += std::to_string(i);
    }
    std::vector<double> f50, f99, c50, c99, l50, l99;
    for (int r = 0; r < runs; ++r) {
      for (bool capped : {false, true}) {
        ++domain;
        const pid_t server =
            Spawn({VDYN_SERVER_BINARY, "--domain", std::to_string(domain), "--world", "facility",
                   "--vehicle-ids", ids, "--duration", "600"},
                  tmp + "/server.log");
        Track(1, server);
        const std::string stats = tmp + "/stats.txt";
        std::remove(stats.c_str());
        const pid_t viewer = Spawn(
            {VDYN_VIEWER_BINARY, "--domain", std::to_string(domain), "--follow", "1", "--camera",
             "chase", "--width", "1280", "--height", "720", "--fps", capped ? "60" : "0",
             "--frames", std::to_string(frames), "--wait", "60", "--stats-out", stats},
            tmp + "/viewer.log");
        Track(2, viewer);
        const int code = WaitPid(viewer);
        Track(2, -1);
        kill(server, SIGINT);
        WaitPid(server);
        Track(1, -1);
        const auto kv = ReadStats(stats);
        if (code != 0 || kv.empty() || Num(kv, "vehicles") < vehicles) {
          std::fprintf(stderr, "viewer_bench: run failed (exit %d, %g vehicles seen); see %s\n",
                       code, Num(kv, "vehicles"), tmp.c_str());
          kill(xvfb, SIGTERM);
          return 1;
        }
        renderer = kv.count("renderer") ? kv.at("renderer") : "?";
        if (capped) {
          c50.push_back(Num(kv, "frame_ms_p50"));
          c99.push_back(Num(kv, "frame_ms_p99"));
          l50.push_back(Num(kv, "latency_ms_p50"));
          l99.push_back(Num(kv, "latency_ms_p99"));
        } else {
          f50.push_back(Num(kv, "frame_ms_p50"));
          f99.push_back(Num(kv, "frame_ms_p99"));
        }
      }
    }
    const double fp50 = Median(f50);
    std::printf("%-9d %8.2f / %-13.2f %-7.1f %8.2f / %-13.2f %8.2f / %-13.2f\n", vehicles, fp50,
                Median(f99), fp50 > 0 ? 1000.0 / fp50 : 0.0, Median(c50), Median(c99), Median(l50),
                Median(l99));
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
