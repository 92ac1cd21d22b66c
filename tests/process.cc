#include "process.h"

#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <poll.h>
#include <sys/file.h>
#include <sys/syscall.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <mutex>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <thread>

extern char** environ;

namespace vdyn::testing {

Process::Process(std::vector<std::string> argv, std::filesystem::path log) : log_(std::move(log)) {
  std::vector<char*> args;
  for (std::string& a : argv) args.push_back(a.data());
  args.push_back(nullptr);
  posix_spawn_file_actions_t fa;
  posix_spawn_file_actions_init(&fa);
  posix_spawn_file_actions_addopen(&fa, 1, log_.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  posix_spawn_file_actions_adddup2(&fa, 1, 2);
  const int rc = posix_spawn(&pid_, args[0], &fa, nullptr, args.data(), environ);
  posix_spawn_file_actions_destroy(&fa);
  if (rc != 0) throw std::runtime_error("cannot start " + argv[0]);
}

Process::~Process() {
  if (running()) {
    kill(pid_, SIGKILL);
    Wait(std::chrono::seconds(10));
  }
}

bool Process::running() {
  if (exit_code_) return false;
  int status = 0;
  const pid_t r = waitpid(pid_, &status, WNOHANG);
  if (r == pid_) {
    exit_code_ = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
    return false;
  }
  return r == 0;
}

void Process::Signal(int sig) {
  if (running()) kill(pid_, sig);
}

std::optional<int> Process::Wait(std::chrono::milliseconds timeout) {
  if (!running()) return exit_code_;
  // Wait on the child's exit as an event: a pidfd becomes readable when it ends.
  const int fd = static_cast<int>(syscall(SYS_pidfd_open, pid_, 0));
  if (fd >= 0) {
    pollfd p{fd, POLLIN, 0};
    poll(&p, 1, static_cast<int>(timeout.count()));
    close(fd);
    running();
    return exit_code_;
  }
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (running()) {  // kernels without pidfd: poll the exit status, bounded
    if (std::chrono::steady_clock::now() >= deadline) return std::nullopt;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return exit_code_;
}

std::string Process::Log() const {
  std::ifstream in(log_);
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

std::string ServerBinary() { return VDYN_SERVER_BINARY; }
std::string InputBinary() { return VDYN_INPUT_BINARY; }
std::string StateSubscriberBinary() { return VDYN_STATE_SUBSCRIBER_BINARY; }
std::string RecorderBinary() { return VDYN_RECORDER_BINARY; }

void UseLoopbackDds() {
  setenv("CYCLONEDDS_URI",
         "<General><Interfaces><NetworkInterface name=\"lo\"/></Interfaces></General>"
         "<Discovery><MaxAutoParticipantIndex>120</MaxAutoParticipantIndex></Discovery>",
         1);
}

std::uint32_t FreshDomain() {
  // Domains 100..229, each taken by at most one test process on this machine at a time: a
  // process holds a lock file per domain it uses (released when it exits), so test binaries
  // that run side by side (ctest -j) never meet on a domain.
  static std::mutex mu;
  static std::uint32_t next = static_cast<std::uint32_t>(getpid()) % 130;
  std::lock_guard<std::mutex> lock(mu);
  for (int tries = 0; tries < 130; ++tries) {
    const std::uint32_t domain = 100 + (next++ % 130);
    const std::string path = "/tmp/vdyn-test-domain-" + std::to_string(domain) + ".lock";
    const int fd = open(path.c_str(), O_CREAT | O_RDWR | O_CLOEXEC, 0666);
    if (fd < 0) continue;
    if (flock(fd, LOCK_EX | LOCK_NB) == 0) return domain;  // fd stays open: the lock is held
    close(fd);
  }
  throw std::runtime_error("no free DDS domain among 100..229 for this test");
}

}  // namespace vdyn::testing
