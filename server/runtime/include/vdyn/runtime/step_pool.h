// StepPool: a fixed set of threads that step a session's vehicles together (issue 19).
//
// The calling thread (the server's loop) and N-1 workers, all created once, share one job at a
// time: [0, n) cut into N contiguous parts in order, part 0 on the calling thread. The calling
// thread also runs the session's serial phases, so its part weighs 2 and each worker's 3:
// part k starts at n * W(k) / W(N), W(0) = 0, W(k) = 2 + 3 (k - 1) (Begin). The cut depends only
// on n and N, never on timing, and each item is stepped by exactly one thread; what an item's
// result is does not depend on which thread computes it (a vehicle's step reads only its own
// simulator and the immutable world), so results are bit for bit the same for any N.
//
//   loop:    publish job, gen++ ──► part 0 ──► wait remaining == 0 ──► (serial phase)
//   worker k:    wait gen changes ──► part k ──► remaining-- (the last one wakes the loop)
//
// The barrier is two atomics: a brief spin, then a futex wait (std::atomic::wait). Run() makes
// no heap allocation on any thread; workers stop and are joined in the destructor.
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <string>
#include <thread>
#include <vector>

namespace vdyn {

class StepPool {
 public:
  using PartFn = void (*)(void* context, std::size_t begin, std::size_t end);

  // `threads` in limits::kStepThreads (std::invalid_argument otherwise, with the reason).
  explicit StepPool(int threads);
  ~StepPool();
  StepPool(const StepPool&) = delete;
  StepPool& operator=(const StepPool&) = delete;

  int threads() const { return threads_; }

  // Part k of [0, n) among `threads` (the fixed partition): [Begin(n, T, k), Begin(n, T, k + 1)).
  static constexpr std::size_t kCallerWeight = 2, kWorkerWeight = 3;
  static std::size_t Begin(std::size_t n, int threads, int k) {
    auto weight = [](int parts) {  // of the first `parts` parts
      return parts <= 0 ? 0 : kCallerWeight + kWorkerWeight * static_cast<std::size_t>(parts - 1);
    };
    return n * weight(k) / weight(threads);
  }

  // Calls fn(context, begin, end) once for each non-empty part of [0, n), part 0 on this thread,
  // and returns when every part is done (what the parts wrote is then visible here). Not
  // reentrant; one caller thread.
  void Run(std::size_t n, PartFn fn, void* context);
  template <class F>
  void Run(std::size_t n, F& f) {
    Run(
        n, [](void* c, std::size_t b, std::size_t e) { (*static_cast<F*>(c))(b, e); }, &f);
  }

  // Gives the workers the loop's scheduling: SCHED_FIFO at `priority`. Empty when done, else
  // the reason it was refused (the workers then keep the normal scheduler).
  std::string SetRealtimePriority(int priority);

 private:
  void WorkerLoop(int k);
  void Stop();
  // Spins briefly, then sleeps in the kernel, until `a` no longer holds `old`.
  static void WaitWhile(const std::atomic<std::uint32_t>& a, std::uint32_t old);

  const int threads_;
  // The job (written by Run before `generation_` moves on; read by workers after they see it).
  std::size_t n_ = 0;
  PartFn fn_ = nullptr;
  void* context_ = nullptr;
  bool stop_ = false;
  alignas(64) std::atomic<std::uint32_t> generation_{0};  // one more per job
  alignas(64) std::atomic<std::uint32_t> remaining_{0};   // workers not done with this job
  std::vector<std::thread> workers_;
};

}  // namespace vdyn
