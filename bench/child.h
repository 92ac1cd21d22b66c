// What the benchmarks that start processes share: start a program with its output in a log, wait
// for it (exit code and CPU), read a running process's CPU, a private Xvfb display, and small
// helpers for their results.
#pragma once

#include <sys/types.h>

#include <filesystem>
#include <map>
#include <string>
#include <vector>

namespace vdyn::bench {

// Starts argv[0] with `argv`, its stdout and stderr into `log`. `to_fd3` becomes the child's fd 3
// (after `close_fd`, which may be 3 itself, is closed in the child). Ends the bench when the
// program cannot be started.
pid_t Spawn(std::vector<std::string> argv, const std::filesystem::path& log, int to_fd3 = -1,
            int close_fd = -1);
// Waits for a child: its exit code, 128 + the signal when a signal ended it; its user + system
// CPU seconds (all its threads, from wait4's rusage) into `cpu_s` when given.
int WaitPid(pid_t pid, double* cpu_s = nullptr);
// User + system CPU seconds of a running process so far (/proc/PID/stat).
double ProcessCpuSeconds(pid_t pid);
// Starts Xvfb on a free display (-displayfd) with a screen of `screen` (e.g. "1920x1080x24") and
// sets DISPLAY to it; its pid, or -1 (and the reason in `log`) when there is no Xvfb.
pid_t StartXvfb(const std::filesystem::path& log, const std::string& screen);

double Median(std::vector<double> v);
std::string Slurp(const std::filesystem::path& p);
// "key value" lines (the stats files vdyn's programs write for benches).
std::map<std::string, std::string> ReadStats(const std::filesystem::path& p);

}  // namespace vdyn::bench
