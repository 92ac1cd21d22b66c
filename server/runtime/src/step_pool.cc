#include "vdyn/runtime/step_pool.h"

#include <pthread.h>
#include <sched.h>

#include <cstdio>
#include <cstring>
#include <stdexcept>

#include "vdyn/base/limits.h"

namespace vdyn {
namespace {

// About 20-60 us of spinning before a thread sleeps: a part of a step is far shorter than the
// time between steps, so the loop usually finds the workers done within the spin, and a worker
// that misses the next job sleeps instead of burning a core that another thread needs.
constexpr int kSpins = 1000;

inline void CpuRelax() {
#if defined(__x86_64__) || defined(__i386__)
  __builtin_ia32_pause();
#elif defined(__aarch64__)
  asm volatile("yield" ::: "memory");
#endif
}

}  // namespace

StepPool::StepPool(int threads) : threads_(threads) {
  if (const std::string why = limits::Check(limits::kStepThreads, threads); !why.empty()) {
    throw std::invalid_argument(why);
  }
  workers_.reserve(static_cast<std::size_t>(threads_ - 1));
  try {
    for (int k = 1; k < threads_; ++k) workers_.emplace_back([this, k] { WorkerLoop(k); });
  } catch (...) {
    Stop();  // the started ones stop; then the error goes on
    throw;
  }
}

StepPool::~StepPool() {
  Stop();
}

void StepPool::Stop() {
  if (workers_.empty()) return;
  stop_ = true;
  generation_.fetch_add(1, std::memory_order_release);
  generation_.notify_all();
  for (std::thread& t : workers_) {
    if (t.joinable()) t.join();
  }
  workers_.clear();
}

void StepPool::WaitWhile(const std::atomic<std::uint32_t>& a, std::uint32_t old) {
  for (int i = 0; i < kSpins; ++i) {
    if (a.load(std::memory_order_acquire) != old) return;
    CpuRelax();
  }
  while (a.load(std::memory_order_acquire) == old) a.wait(old, std::memory_order_acquire);
}

void StepPool::Run(std::size_t n, PartFn fn, void* context) {
  if (threads_ == 1 || n < 2) {
    if (n > 0) fn(context, 0, n);
    return;
  }
  n_ = n;
  fn_ = fn;
  context_ = context;
  remaining_.store(static_cast<std::uint32_t>(threads_ - 1), std::memory_order_relaxed);
  generation_.fetch_add(1, std::memory_order_release);  // publishes the job
  generation_.notify_all();
  if (const std::size_t end = Begin(n, threads_, 1); end > 0) fn(context, 0, end);
  for (std::uint32_t r; (r = remaining_.load(std::memory_order_acquire)) != 0;)
    WaitWhile(remaining_, r);
}

void StepPool::WorkerLoop(int k) {
  char name[16];
  std::snprintf(name, sizeof name, "vdyn-step-%d", k);
  pthread_setname_np(pthread_self(), name);
  // The generation at construction: a job published before this thread got here is still seen.
  std::uint32_t seen = 0;
  for (;;) {
    WaitWhile(generation_, seen);
    seen = generation_.load(std::memory_order_acquire);
    if (stop_) return;
    const std::size_t begin = Begin(n_, threads_, k), end = Begin(n_, threads_, k + 1);
    if (begin < end) fn_(context_, begin, end);
    if (remaining_.fetch_sub(1, std::memory_order_acq_rel) == 1) remaining_.notify_one();
  }
}

std::string StepPool::SetRealtimePriority(int priority) {
  sched_param sp{};
  sp.sched_priority = priority;
  for (std::thread& t : workers_) {
    if (const int rc = pthread_setschedparam(t.native_handle(), SCHED_FIFO, &sp); rc != 0) {
      return std::string("SCHED_FIFO refused: ") + std::strerror(rc);
    }
  }
  return {};
}

}  // namespace vdyn
