// Child processes for end-to-end tests: started with posix_spawn, output to a log file, waited
// for with a bound, killed at the end of the test whatever happens.
#pragma once

#include <sys/types.h>

#include <chrono>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

namespace vdyn::testing {

class Process {
 public:
  // Starts argv[0] with the arguments; stdout and stderr go to `log`.
  Process(std::vector<std::string> argv, std::filesystem::path log);
  ~Process();  // SIGKILL if still running
  Process(const Process&) = delete;
  Process& operator=(const Process&) = delete;

  bool running();
  void Signal(int sig);
  // Waits up to `timeout` for the exit; the exit code (128 + signal when killed), or nullopt.
  std::optional<int> Wait(std::chrono::milliseconds timeout);
  std::string Log() const;
  pid_t pid() const { return pid_; }

 private:
  pid_t pid_ = -1;
  std::optional<int> exit_code_;
  std::filesystem::path log_;
};

// Path of a built executable (set by CMake).
std::string ServerBinary();
std::string InputBinary();
std::string StateSubscriberBinary();
std::string RecorderBinary();

// Cyclone DDS restricted to loopback, with room for many processes per domain.
void UseLoopbackDds();
// A DDS domain id no other test of this binary uses.
std::uint32_t FreshDomain();

}  // namespace vdyn::testing
