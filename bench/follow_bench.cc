// follow_bench: what a client that follows one vehicle costs, and what the server's 1 kHz loop
// thread costs, against the number of vehicles the server runs (issue 19: a reader pays only for
// what it reads; 256 vehicles per server).
//
// For each vehicle count N (1, 16, 64, 256) and each run: a real-time vdyn-server on `flat` with
// vehicles 1..N (--max-vehicles 256); then, one after another and each alone with the server,
//  - the one-vehicle client: `vdyn-input play demo --clock wall --loop` driving vehicle 1 at
//    1 kHz (it reads vehicle 1's states in its partition, SessionView::Topics::only_vehicle),
//  - the peer: the same 1 kHz client loop reading every vehicle's states (a SessionView without
//    only_vehicle, as vdyn-input read before; this binary with --all-reader),
//  - `vdyn-recorder record` of everything, alone, and then with 8 one-vehicle rigs
//    (`vdyn-input play demo` on vehicles 1..8, at most N) driving meanwhile: the recorder's CPU,
//    and the states it lost before they reached it plus the samples its full buffer dropped
//    (its own summary line),
// each process's CPU (user + system, /proc/PID/stat) over `seconds` after a 3 s warm-up, and the
// server's loop thread (its SCHED_FIFO thread, /proc/PID/task/TID/stat) and whole process over the
// one-vehicle client's window. Medians over the runs; the load average is printed with each run.
//
// With a list of stepping thread counts (`--step-threads`, runtime/step_pool.h), each vehicle
// count runs once per thread count in every run (the peer of a pool: the same server stepping on
// one thread, in the same run): the loop thread (the SCHED_FIFO thread that is not a stepping
// worker `vdyn-step-K`), the workers together, the whole server, and from the server's
// --stats-out over its whole life: steps lost (due by the end, never run), schedule rebases, tick
// lateness p50 / p99 / p99.9 / max, and states the state writer refused (queue full).
//
// With VDYN_BENCH_PLOT=DIR the medians go to DIR/follow_bench.dat and gnuplot draws them into
// DIR/follow_bench.png (CPU and tick lateness against the vehicle count).
//
// Usage: follow_bench [seconds=10] [runs=3] [counts=1,16,64,256] [step_threads=1]
#include <signal.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <initializer_list>
#include <fstream>
#include <map>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include <fmt/format.h>

#include "child.h"
#include "vdyn/base/time.h"
#include "vdyn/client/loop.h"
#include "vdyn/client/session_view.h"
#include "vdyn/transport/dds.h"

namespace {

using vdyn::base::MonotonicNow;
using vdyn::bench::Median;
using vdyn::bench::ProcessCpuSeconds;
using vdyn::bench::Spawn;
using vdyn::bench::WaitPid;

vdyn::base::Nanos Secs(double s) {
  return vdyn::base::Nanos{static_cast<std::int64_t>(s * 1e9)};
}

// The peer: a 1 kHz client loop that reads every vehicle's states (and keeps vehicle 1's).
int AllReader(std::uint32_t domain, double seconds) {
  vdyn::transport::Participant participant(domain);
  vdyn::client::SessionView view(participant, {.states = true,
                                               .params = false,
                                               .world = false,
                                               .diagnostics = false,
                                               .inputs = false,
                                               .only_vehicle = std::nullopt, .only_server = {}});
  vdyn::client::FixedRateLoop loop(vdyn::base::Milliseconds(1));
  const auto end = MonotonicNow() + Secs(seconds);
  while (MonotonicNow() < end) {
    loop.Wait();
    view.Poll();
  }
  const auto* v = view.vehicle(1);
  std::printf("all-reader: %zu vehicles, %llu states of vehicle 1\n", view.vehicles().size(),
              static_cast<unsigned long long>(v != nullptr ? v->states : 0));
  return 0;
}

// A thread's name (/proc/PID/task/TID/comm).
std::string ThreadName(pid_t pid, const std::string& tid) {
  std::string name = vdyn::bench::Slurp(fmt::format("/proc/{}/task/{}/comm", pid, tid));
  while (!name.empty() && (name.back() == '\n')) name.pop_back();
  return name;
}

bool IsStepWorker(pid_t pid, const std::string& tid) {
  return ThreadName(pid, tid).rfind("vdyn-step-", 0) == 0;
}

// utime + stime of one thread, and its scheduling policy (field 41; 1 = SCHED_FIFO).
bool ThreadStat(pid_t pid, const std::string& tid, double& cpu_s, int& policy) {
  std::FILE* file = std::fopen(fmt::format("/proc/{}/task/{}/stat", pid, tid).c_str(), "r");
  if (file == nullptr) return false;
  char buf[2048];
  const std::size_t got = std::fread(buf, 1, sizeof buf - 1, file);
  std::fclose(file);
  const std::string all(buf, got);
  const std::size_t close = all.rfind(')');
  if (close == std::string::npos) return false;
  std::istringstream rest(all.substr(close + 2));
  std::vector<std::string> f;  // fields from 3 (state) on
  for (std::string x; rest >> x;) f.push_back(x);
  if (f.size() < 39) return false;
  const double tick = static_cast<double>(sysconf(_SC_CLK_TCK));
  cpu_s = (std::stod(f[11]) + std::stod(f[12])) / tick;  // fields 14, 15
  policy = std::stoi(f[38]);                             // field 41
  return true;
}

// The server's 1 kHz loop: its SCHED_FIFO thread that is not a stepping worker, else its main
// thread (ServerNode::Run runs the loop on the thread that calls it, and sets SCHED_FIFO when it
// is permitted; the workers share it).
std::string LoopThread(pid_t pid) {
  const std::string dir = fmt::format("/proc/{}/task", pid);
  for (const auto& e : std::filesystem::directory_iterator(dir)) {
    const std::string tid = e.path().filename().string();
    double cpu = 0;
    int policy = 0;
    if (ThreadStat(pid, tid, cpu, policy) && policy == 1 && !IsStepWorker(pid, tid)) return tid;
  }
  return std::to_string(pid);
}

std::vector<std::string> StepWorkers(pid_t pid) {
  std::vector<std::string> tids;
  for (const auto& e : std::filesystem::directory_iterator(fmt::format("/proc/{}/task", pid))) {
    const std::string tid = e.path().filename().string();
    if (IsStepWorker(pid, tid)) tids.push_back(tid);
  }
  return tids;
}

double ThreadCpu(pid_t pid, const std::string& tid) {
  double cpu = -1;
  int policy = 0;
  if (tid.empty() || !ThreadStat(pid, tid, cpu, policy)) return -1;
  return cpu;
}

double ThreadsCpu(pid_t pid, const std::vector<std::string>& tids) {
  double sum = 0;
  for (const std::string& tid : tids) sum += std::max(0.0, ThreadCpu(pid, tid));
  return sum;
}

double LoadAverage() {
  double l = 0;
  if (std::FILE* f = std::fopen("/proc/loadavg", "r"); f != nullptr) {
    if (std::fscanf(f, "%lf", &l) != 1) l = 0;
    std::fclose(f);
  }
  return l;
}

// The medians against the vehicle count, one data block per stepping-thread count, in
// DIR/follow_bench.dat, drawn by gnuplot into DIR/follow_bench.png: CPU (clients, server, loop,
// recorder) and tick lateness (log scale).
void Plot(const std::string& dir, const std::vector<int>& counts, const std::vector<int>& threads,
          const std::function<std::vector<double>(int, int)>& row) {
  std::filesystem::create_directories(dir);
  const std::string dat = dir + "/follow_bench.dat", png = dir + "/follow_bench.png";
  {
    std::ofstream out(dat);
    out << "# vehicles client peer loop workers server lateness_p50_us p99 p999 max "
           "recorder recorder_8_rigs recorder_lost recorder_8_rigs_lost steps_lost states_refused\n";
    for (int t : threads) {
      out << "# stepping threads " << t << "\n";
      for (int n : counts) {
        out << n;
        for (double v : row(n, t)) out << ' ' << v;
        out << '\n';
      }
      out << "\n\n";
    }
  }
  const std::string gp = dir + "/follow_bench.gp";
  {
    std::ofstream g(gp);
    g << "set terminal pngcairo size 1400,560 font ',10'\nset output '" << png << "'\n"
      << "set multiplot layout 1,2 title 'vdyn-server at 1 kHz on flat: medians of runs against "
         "the vehicle count'\n"
      << "set logscale x 2\nset xlabel 'vehicles'\nset key top left\nset grid\n"
      << "set ylabel '% of one core'\nset title 'CPU'\n";
    // One curve per (data column, name) and stepping-thread count.
    const auto plot = [&](std::initializer_list<std::pair<int, const char*>> curves) {
      g << "plot ";
      for (std::size_t i = 0; i < threads.size(); ++i) {
        for (const auto& [column, name] : curves) {
          if (i > 0 || column != curves.begin()->first) g << ", ";
          g << "'" << dat << "' index " << i << " using 1:" << column
            << " with linespoints title '" << name << " (" << threads[i] << " thr)'";
        }
      }
      g << "\n";
    };
    plot({{4, "server loop thread"}, {6, "server"}, {2, "one-vehicle client"},
          {3, "all-vehicles reader"}, {11, "recorder"}, {12, "recorder, 8 rigs"}});
    g << "set logscale y 10\nset ylabel 'us'\nset title 'tick lateness'\n";
    plot({{7, "p50"}, {8, "p99"}, {9, "p99.9"}, {10, "max"}});
    g << "unset multiplot\n";
  }
  const int rc = std::system(("gnuplot '" + gp + "'").c_str());
  std::printf("%s: %s\n", rc == 0 ? "plot" : "gnuplot failed; data", rc == 0 ? png.c_str() : dat.c_str());
}

}  // namespace

int main(int argc, char** argv) {
  if (argc >= 4 && std::string(argv[1]) == "--all-reader") {
    return AllReader(static_cast<std::uint32_t>(std::atoi(argv[2])), std::atof(argv[3]));
  }
  const double seconds = argc > 1 ? std::atof(argv[1]) : 10.0;
  const int runs = argc > 2 ? std::atoi(argv[2]) : 3;
  auto list = [](const char* text) {
    std::vector<int> v;
    std::istringstream in(text);
    for (std::string x; std::getline(in, x, ',');) v.push_back(std::atoi(x.c_str()));
    return v;
  };
  const std::vector<int> counts = list(argc > 3 ? argv[3] : "1,16,64,256");
  const std::vector<int> thread_counts = list(argc > 4 ? argv[4] : "1");
  if (std::getenv("CYCLONEDDS_URI") == nullptr) {
    setenv("CYCLONEDDS_URI",
           "<General><Interfaces><NetworkInterface name=\"lo\"/></Interfaces></General>"
           "<Discovery><MaxAutoParticipantIndex>64</MaxAutoParticipantIndex></Discovery>",
           1);
  }
  const std::string tmp = fmt::format("/tmp/vdyn-follow-bench-{}", getpid());
  const double warmup = 3.0;
  struct Figures {
    std::vector<double> client, peer, loop, workers, server;
    std::vector<double> lost, rebases, p50, p99, p999, max, refused;
    // The recorder alone with the server, then with 8 one-vehicle rigs driving vehicles 1..8:
    // its CPU, and the states lost before it plus the samples its full buffer dropped.
    std::vector<double> rec_cpu[2], rec_lost[2], rec_messages[2];
  };
  std::map<std::pair<int, int>, Figures> figures;  // (vehicles, stepping threads)
  for (int run = 0; run < runs; ++run) {
    for (int n : counts) {
      for (int threads : thread_counts) {
        const std::uint32_t domain =
            150 + static_cast<std::uint32_t>(getpid() + run * 7 + n + threads * 13) % 60;
        const std::string dom = std::to_string(domain);
        std::string ids;
        for (int i = 1; i <= n; ++i) {
          if (i > 1) ids += ',';
          ids += std::to_string(i);
        }
        const double server_s = 4 * (warmup + seconds) + 20;  // client, peer, recorder twice
        const std::string stats = fmt::format("{}-stats-{}-{}-{}.txt", tmp, n, threads, run);
        const pid_t server = Spawn(
            {VDYN_SERVER_BINARY, "--domain", dom, "--world", "flat", "--no-status",
             "--max-vehicles", "256", "--vehicle-ids", ids, "--duration", std::to_string(server_s),
             "--step-threads", std::to_string(threads), "--stats-out", stats},
            fmt::format("{}-server-{}-{}-{}.log", tmp, n, threads, run));
        vdyn::base::SleepUntil(MonotonicNow() + Secs(2.0));
        const std::string loop_tid = LoopThread(server);
        const std::vector<std::string> workers = StepWorkers(server);
        // The one-vehicle client, with the server's loop and process over its window.
        const pid_t client = Spawn({VDYN_INPUT_BINARY, "--domain", dom, "--strength", "5", "--wait",
                                    "30", "play", "demo", "--clock", "wall", "--loop"},
                                   fmt::format("{}-client-{}-{}.log", tmp, n, run));
        vdyn::base::SleepUntil(MonotonicNow() + Secs(warmup));
        const double c0 = ProcessCpuSeconds(client), l0 = ThreadCpu(server, loop_tid),
                     w0 = ThreadsCpu(server, workers), s0 = ProcessCpuSeconds(server);
        const auto t0 = MonotonicNow();
        vdyn::base::SleepUntil(t0 + Secs(seconds));
        const double wall = (MonotonicNow() - t0).seconds();
        const double c1 = ProcessCpuSeconds(client), l1 = ThreadCpu(server, loop_tid),
                     w1 = ThreadsCpu(server, workers), s1 = ProcessCpuSeconds(server);
        kill(client, SIGTERM);
        WaitPid(client);
        // The peer: every vehicle's states.
        const pid_t peer =
            Spawn({argv[0], "--all-reader", dom, std::to_string(warmup + seconds + 1)},
                  fmt::format("{}-peer-{}-{}.log", tmp, n, run));
        vdyn::base::SleepUntil(MonotonicNow() + Secs(warmup));
        const double p0 = ProcessCpuSeconds(peer);
        const auto tp = MonotonicNow();
        vdyn::base::SleepUntil(tp + Secs(seconds));
        const double pwall = (MonotonicNow() - tp).seconds();
        const double p1 = ProcessCpuSeconds(peer);
        WaitPid(peer);
        Figures& fr = figures[{n, threads}];
        for (int rigs_on = 0; rigs_on < 2; ++rigs_on) {
          std::vector<pid_t> rigs;
          for (int k = 1; rigs_on == 1 && k <= std::min(n, 8); ++k) {
            rigs.push_back(Spawn({VDYN_INPUT_BINARY, "--domain", dom, "--vehicle-id",
                                  std::to_string(k), "--strength", "5", "--wait", "30", "play",
                                  "demo", "--clock", "wall", "--loop"},
                                 fmt::format("{}-rig-{}-{}-{}.log", tmp, n, k, run)));
          }
          const std::string rec_log = fmt::format("{}-recorder-{}-{}-{}.log", tmp, n, rigs_on, run);
          const std::string rec_file = fmt::format("{}-{}-{}.mcap", tmp, n, rigs_on);
          const pid_t rec = Spawn({VDYN_RECORDER_BINARY, "record", "--domain", dom, "--no-status",
                                   "--duration", fmt::format("{:.1f}", warmup + seconds), rec_file},
                                  rec_log);
          vdyn::base::SleepUntil(MonotonicNow() + Secs(warmup));
          const double r0 = ProcessCpuSeconds(rec);
          const auto tr = MonotonicNow();
          vdyn::base::SleepUntil(tr + Secs(seconds));
          const double r1 = ProcessCpuSeconds(rec);
          const double rwall = (MonotonicNow() - tr).seconds();
          WaitPid(rec);
          for (pid_t r : rigs) kill(r, SIGTERM);
          for (pid_t r : rigs) WaitPid(r);
          // "recorded N messages in ...; lost L, dropped D; ..."
          double messages = -1, lost = -1, dropped = -1;
          const std::string log = vdyn::bench::Slurp(rec_log);
          if (const auto at = log.rfind("recorded "); at != std::string::npos) {
            std::sscanf(log.c_str() + at, "recorded %lf messages", &messages);
            if (const auto l = log.find("lost ", at); l != std::string::npos) {
              std::sscanf(log.c_str() + l, "lost %lf, dropped %lf", &lost, &dropped);
            }
          }
          fr.rec_cpu[rigs_on].push_back(100 * (r1 - r0) / rwall);
          fr.rec_lost[rigs_on].push_back(lost < 0 || dropped < 0 ? -1 : lost + dropped);
          fr.rec_messages[rigs_on].push_back(messages);
          std::filesystem::remove(rec_file);
        }
        kill(server, SIGTERM);
        WaitPid(server);
        Figures& f = figures[{n, threads}];
        f.client.push_back(100 * (c1 - c0) / wall);
        f.peer.push_back(100 * (p1 - p0) / pwall);
        f.loop.push_back(loop_tid.empty() ? -1 : 100 * (l1 - l0) / wall);
        f.workers.push_back(100 * (w1 - w0) / wall);
        f.server.push_back(100 * (s1 - s0) / wall);
        const auto st = vdyn::bench::ReadStats(stats);
        auto num = [&st](const char* key) {
          const auto it = st.find(key);
          return it == st.end() ? -1.0 : std::atof(it->second.c_str());
        };
        f.lost.push_back(num("steps_due") - num("steps"));
        f.rebases.push_back(num("schedule_rebases"));
        f.p50.push_back(num("lateness_p50_us"));
        f.p99.push_back(num("lateness_p99_us"));
        f.p999.push_back(num("lateness_p999_us"));
        f.max.push_back(num("lateness_max_us"));
        f.refused.push_back(num("states_refused"));
        std::printf(
            "run %d, %3d vehicles, %d stepping thread(s) (load %.1f): one-vehicle client %.2f %%, "
            "all-vehicles reader %.2f %%, server loop thread %.2f %%, stepping workers %.2f %%, "
            "server %.2f %%; steps lost %.0f, rebases %.0f, lateness p50/p99/p99.9/max "
            "%.1f/%.1f/%.1f/%.1f us, states refused %.0f\n",
            run + 1, n, threads, LoadAverage(), f.client.back(), f.peer.back(), f.loop.back(),
            f.workers.back(), f.server.back(), f.lost.back(), f.rebases.back(), f.p50.back(),
            f.p99.back(), f.p999.back(), f.max.back(), f.refused.back());
        std::printf("  recorder alone %.2f %% (lost or dropped %.0f of %.0f recorded), with %d rigs "
                    "%.2f %% (lost or dropped %.0f of %.0f)\n",
                    f.rec_cpu[0].back(), f.rec_lost[0].back(), f.rec_messages[0].back(),
                    std::min(n, 8), f.rec_cpu[1].back(), f.rec_lost[1].back(),
                    f.rec_messages[1].back());
        std::fflush(stdout);
      }
    }
  }
  std::printf("\nmedians of %d runs, %% of one core:\n", runs);
  std::printf(
      "| vehicles | stepping threads | one-vehicle client | all-vehicles reader (peer) | server "
      "loop thread | stepping workers | server | steps lost | rebases | lateness p50 / p99 / "
      "p99.9 / max, us | states refused | recorder, alone / with 8 rigs | recorder lost or dropped, alone / with 8 rigs |\n"
      "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |\n");
  for (int n : counts) {
    for (int threads : thread_counts) {
      const Figures& f = figures[{n, threads}];
      std::printf(
          "| %d | %d | %.2f | %.2f | %.2f | %.2f | %.2f | %.0f | %.0f | %.1f / %.1f / %.1f / %.1f "
          "| %.0f | %.2f / %.2f | %.0f / %.0f |\n",
          n, threads, Median(f.client), Median(f.peer), Median(f.loop), Median(f.workers),
          Median(f.server), Median(f.lost), Median(f.rebases), Median(f.p50), Median(f.p99),
          Median(f.p999), Median(f.max), Median(f.refused), Median(f.rec_cpu[0]),
          Median(f.rec_cpu[1]), Median(f.rec_lost[0]), Median(f.rec_lost[1]));
    }
  }
  if (const char* dir = std::getenv("VDYN_BENCH_PLOT"); dir != nullptr && *dir != '\0') {
    Plot(dir, counts, thread_counts, [&](int n, int t) {
      const Figures& f = figures[{n, t}];
      return std::vector<double>{Median(f.client), Median(f.peer), Median(f.loop),
                                 Median(f.workers), Median(f.server), Median(f.p50),
                                 Median(f.p99), Median(f.p999), Median(f.max),
                                 Median(f.rec_cpu[0]), Median(f.rec_cpu[1]),
                                 Median(f.rec_lost[0]), Median(f.rec_lost[1]), Median(f.lost),
                                 Median(f.refused)};
    });
  }
  const int t0 = thread_counts.front();
  const double c1 = Median(figures[{counts.front(), t0}].client);
  for (int n : counts) {
    std::printf("one-vehicle client at %d vehicles / at %d (%d stepping thread(s)): %.2fx\n", n,
                counts.front(), t0, Median(figures[{n, t0}].client) / c1);
  }
  return 0;
}
