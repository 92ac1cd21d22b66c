#include "vdyn/base/doorbell.h"

#include <linux/futex.h>
#include <sys/syscall.h>
#include <time.h>
#include <unistd.h>

#include <climits>

namespace vdyn::base {
namespace {
// std::atomic<std::uint32_t> has the size and alignment of the futex word.
static_assert(sizeof(std::atomic<std::uint32_t>) == sizeof(std::uint32_t));

long Futex(std::atomic<std::uint32_t>* addr, int op, std::uint32_t val, const timespec* timeout) {
  return syscall(SYS_futex, reinterpret_cast<std::uint32_t*>(addr), op, val, timeout, nullptr, 0);
}
}  // namespace

void Doorbell::Ring() {
  seq_.fetch_add(1, std::memory_order_seq_cst);
  if (waiters_.load(std::memory_order_seq_cst) > 0) {
    Futex(&seq_, FUTEX_WAKE_PRIVATE, INT_MAX, nullptr);
  }
}

void Doorbell::Wait(std::uint32_t token, Nanos timeout) {
  if (timeout.ns <= 0) return;
  waiters_.fetch_add(1, std::memory_order_seq_cst);
  if (seq_.load(std::memory_order_seq_cst) == token) {
    timespec ts;
    ts.tv_sec = timeout.ns / 1'000'000'000;
    ts.tv_nsec = timeout.ns % 1'000'000'000;
    // Returns at once if seq_ is no longer `token`; spurious wake-ups are fine for callers.
    Futex(&seq_, FUTEX_WAIT_PRIVATE, token, &ts);
  }
  waiters_.fetch_sub(1, std::memory_order_seq_cst);
}

}  // namespace vdyn::base
