#include "mapped_file.h"

#include <signal.h>
#include <sys/mman.h>
#include <unistd.h>

#include <atomic>
#include <limits>
#include <mutex>

namespace vdyn::mcap {
namespace {

// The mappings the SIGBUS handler may repair: a fixed table (a signal handler may not allocate
// or lock), claimed and released with atomics.
constexpr int kSlots = 256;
constexpr std::uint64_t kNoFault = std::numeric_limits<std::uint64_t>::max();
struct Slot {
  std::atomic<bool> used{false};
  std::atomic<std::uintptr_t> begin{0}, end{0};
  std::atomic<std::uint64_t> fault{kNoFault};
};
Slot g_slots[kSlots];
struct sigaction g_previous {};
std::once_flag g_installed;

void OnSigbus(int sig, siginfo_t* info, void* context) {
  const auto addr = reinterpret_cast<std::uintptr_t>(info->si_addr);
  for (Slot& s : g_slots) {
    const std::uintptr_t begin = s.begin.load(std::memory_order_acquire);
    const std::uintptr_t end = s.end.load(std::memory_order_acquire);
    if (begin == 0 || addr < begin || addr >= end) continue;
    const auto page_size = static_cast<std::uintptr_t>(::sysconf(_SC_PAGESIZE));
    void* const page = reinterpret_cast<void*>(addr & ~(page_size - 1));
    // Zeroes where the file was: the read that faulted finishes, and the reader sees the flag.
    if (::mmap(page, page_size, PROT_READ, MAP_PRIVATE | MAP_ANONYMOUS | MAP_FIXED, -1, 0) ==
        MAP_FAILED) {
      break;
    }
    const std::uint64_t offset = addr - begin;
    std::uint64_t seen = s.fault.load(std::memory_order_relaxed);
    while (offset < seen && !s.fault.compare_exchange_weak(seen, offset)) {
    }
    return;
  }
  // Not one of ours: whoever handled it before, or the default action (the instruction runs
  // again and the signal kills the process, as it would have).
  if ((g_previous.sa_flags & SA_SIGINFO) != 0 && g_previous.sa_sigaction != nullptr) {
    g_previous.sa_sigaction(sig, info, context);
    return;
  }
  if ((g_previous.sa_flags & SA_SIGINFO) == 0 && g_previous.sa_handler != SIG_DFL &&
      g_previous.sa_handler != SIG_IGN) {
    g_previous.sa_handler(sig);
    return;
  }
  struct sigaction dfl {};
  dfl.sa_handler = SIG_DFL;
  ::sigemptyset(&dfl.sa_mask);
  ::sigaction(SIGBUS, &dfl, nullptr);
}

void Install() {
  struct sigaction sa {};
  sa.sa_sigaction = OnSigbus;
  sa.sa_flags = SA_SIGINFO | SA_NODEFER;
  ::sigemptyset(&sa.sa_mask);
  ::sigaction(SIGBUS, &sa, &g_previous);
}

}  // namespace

bool MappedFile::Map(int fd, std::uint64_t size) {
  std::call_once(g_installed, Install);
  void* m = ::mmap(nullptr, static_cast<std::size_t>(size), PROT_READ, MAP_PRIVATE, fd, 0);
  if (m == MAP_FAILED) return false;
  data_ = static_cast<const std::uint8_t*>(m);
  size_ = size;
  for (int i = 0; i < kSlots; ++i) {
    bool expected = false;
    if (g_slots[i].used.compare_exchange_strong(expected, true)) {
      g_slots[i].fault.store(kNoFault, std::memory_order_relaxed);
      g_slots[i].end.store(reinterpret_cast<std::uintptr_t>(data_) + size,
                           std::memory_order_release);
      g_slots[i].begin.store(reinterpret_cast<std::uintptr_t>(data_), std::memory_order_release);
      slot_ = i;
      break;
    }
  }
  return true;
}

std::optional<std::uint64_t> MappedFile::fault() const {
  if (slot_ < 0) return std::nullopt;
  const std::uint64_t f = g_slots[slot_].fault.load(std::memory_order_acquire);
  if (f == kNoFault) return std::nullopt;
  return f;
}

MappedFile::~MappedFile() {
  if (slot_ >= 0) {
    g_slots[slot_].begin.store(0, std::memory_order_release);
    g_slots[slot_].end.store(0, std::memory_order_release);
    g_slots[slot_].used.store(false, std::memory_order_release);
  }
  if (data_ != nullptr) ::munmap(const_cast<std::uint8_t*>(data_), static_cast<std::size_t>(size_));
}

}  // namespace vdyn::mcap
