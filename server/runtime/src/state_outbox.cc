#include "vdyn/runtime/state_outbox.h"

#include <pthread.h>
#include <sys/resource.h>
#include <sys/syscall.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <string>

namespace vdyn {
namespace {

// CPU time of the calling thread (the writer's own work in a round, without the time it waited
// for a core).
std::int64_t ThreadCpuNs() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return std::int64_t{ts.tv_sec} * 1'000'000'000 + ts.tv_nsec;
}

}  // namespace

StateOutbox::StateOutbox(transport::Participant& participant, transport::DropCounters& drops,
                         std::uint32_t states_key, std::size_t frames,
                         std::span<const std::uint32_t> vehicles)
    : writer_(participant, drops, transport::StateWriters::Options{.states_key = states_key}),
      drops_(drops),
      frames_(frames) {
  for (const std::uint32_t key : vehicles) writer_.Prepare(key);
  drop_full_ = drops_.Register("state queue full, state not sent");
  drop_large_ = drops_.Register("state larger than a frame, not sent");
  drop_write_ = drops_.Register("write failed on vdyn/state");
  drop_batch_ = drops_.Register("write failed on vdyn/states");
  thread_ = std::thread([this] { WriterLoop(); });
}

StateOutbox::~StateOutbox() {
  stop_ = true;
  bell_.Ring();
  if (thread_.joinable()) thread_.join();
}

std::size_t StateOutbox::Open(std::size_t n) {
  open_ = std::min(n, frames_.Room());
  empty_.store(0, std::memory_order_relaxed);
  return open_;
}

std::span<std::uint8_t> StateOutbox::Buffer(std::size_t i) {
  return frames_.Slot(i)->bytes;
}

void StateOutbox::Fill(std::size_t i, std::uint32_t key, std::size_t size, bool too_large) {
  Frame* f = frames_.Slot(i);
  f->key = key;
  f->size = static_cast<std::uint32_t>(size);
  f->step_end = 0;
  if (size > 0) return;
  empty_.fetch_add(1, std::memory_order_relaxed);
  if (too_large) {
    drops_.Count(drop_large_);
    refused_.fetch_add(1, std::memory_order_relaxed);
  }
}

void StateOutbox::Close(std::size_t n) {
  // What the stepping threads wrote is visible here (the step's barrier); the release in Commit
  // passes it on to the writer.
  if (open_ > 0) frames_.Slot(open_ - 1)->step_end = 1;
  frames_.Commit(open_);
  pushed_.store(
      pushed_.load(std::memory_order_relaxed) + open_ - empty_.load(std::memory_order_relaxed),
      std::memory_order_relaxed);
  for (std::size_t k = open_; k < n; ++k) {
    drops_.Count(drop_full_);
    refused_.fetch_add(1, std::memory_order_relaxed);
  }
  open_ = 0;
}

void StateOutbox::Send() {
  handed_ns_.store(base::MonotonicNow().ns, std::memory_order_relaxed);
  bell_.Ring();
}

StateOutbox::Times StateOutbox::WriterTimes() const {
  std::lock_guard lock(times_mu_);
  return {send_us_.count(),           wake_us_.Percentile(50), wake_us_.Percentile(99),
          send_us_.Percentile(50),    send_us_.Percentile(99), send_cpu_us_.Percentile(50),
          send_cpu_us_.Percentile(99)};
}

bool StateOutbox::Drain(base::Nanos timeout) {
  const base::MonoTime end = base::MonotonicNow() + timeout;
  const std::uint64_t target = pushed_.load();
  while (written() + write_failures() < target) {
    if (base::MonotonicNow() >= end) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  return true;
}

std::string StateOutbox::SetWriterNice(int nice) {
  writer_tid_.wait(0, std::memory_order_acquire);  // the thread runs from construction on
  const auto tid = static_cast<id_t>(writer_tid_.load(std::memory_order_acquire));
  if (setpriority(PRIO_PROCESS, tid, nice) == 0) return "state writer nice " + std::to_string(nice);
  const std::string why = std::strerror(errno);
  return WriterNice() + " (nice " + std::to_string(nice) + " refused: " + why + ")";
}

std::string StateOutbox::WriterNice() {
  writer_tid_.wait(0, std::memory_order_acquire);
  const auto tid = static_cast<id_t>(writer_tid_.load(std::memory_order_acquire));
  errno = 0;
  const int now = getpriority(PRIO_PROCESS, tid);  // -1 is a nice value too: errno tells
  if (errno != 0) return std::string("state writer nice unknown (") + std::strerror(errno) + ")";
  return "state writer nice " + std::to_string(now);
}

void StateOutbox::WriterLoop() {
  // Ordinary scheduling on purpose: a SCHED_FIFO writer (one below the loop) measured worse at
  // 256 vehicles on 2 cores. With the loop and the stepping worker it passed the kernel's
  // real-time budget (sched_rt_runtime_us: 95 % of the CPUs), and the throttled loop lost steps.
  // A lower nice value instead puts it ahead of the machine's other ordinary threads (rigs,
  // recorders, builds): `vdyn-server --state-writer-nice`, off by default.
  pthread_setname_np(pthread_self(), "vdyn-states");
  writer_tid_.store(static_cast<int>(syscall(SYS_gettid)), std::memory_order_release);
  writer_tid_.notify_all();
  while (true) {
    const std::uint32_t token = bell_.Token();
    const std::int64_t handed = handed_ns_.exchange(0, std::memory_order_relaxed);
    const base::MonoTime start = base::MonotonicNow();
    const std::int64_t cpu_start = ThreadCpuNs();
    std::uint64_t written = 0;
    while (Frame* f = frames_.Front()) {
      // An empty frame: a vehicle without a state this step (contained, or too large).
      if (f->size > 0) {
        if (writer_.WriteBytes(f->key, {f->bytes.data(), f->size})) {
          ++written;
        } else {
          failures_.fetch_add(1, std::memory_order_relaxed);
          drops_.Count(drop_write_, writer_.last_error());
        }
      }
      // Behind, a step's states close a vdyn/states sample once it is large enough.
      if (f->step_end != 0 && !writer_.EndStep()) drops_.Count(drop_batch_, writer_.last_error());
      frames_.Pop();
    }
    // Whatever the loop handed over so far goes out together: one vdyn/states sample, and on
    // vdyn/state shared datagrams (a frame the loop commits meanwhile waits for the next round).
    if (!writer_.Flush()) drops_.Count(drop_batch_, writer_.last_error());
    if (written > 0) {
      const double send_us = static_cast<double>((base::MonotonicNow() - start).ns) * 1e-3;
      const double cpu_us = static_cast<double>(ThreadCpuNs() - cpu_start) * 1e-3;
      std::lock_guard lock(times_mu_);
      if (handed > 0) wake_us_.Add(static_cast<double>(start.ns - handed) * 1e-3);
      send_us_.Add(send_us);
      send_cpu_us_.Add(cpu_us);
    }
    written_.fetch_add(written, std::memory_order_relaxed);
    if (stop_.load()) return;
    bell_.Wait(token, base::Milliseconds(200));
  }
}

}  // namespace vdyn
