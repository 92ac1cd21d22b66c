#include "vdyn/transport/drops.h"

#include <algorithm>

#include <spdlog/spdlog.h>

#include "vdyn/base/text.h"
#include "vdyn/base/time.h"

namespace vdyn::transport {

int DropCounters::Find(std::string_view kind) const {
  const int n = used_.load(std::memory_order_acquire);
  for (int i = 0; i < n; ++i) {
    if (slots_[i].name == kind) return i;
  }
  return -1;
}

int DropCounters::Register(std::string_view kind) {
  if (const int i = Find(kind); i >= 0) return i;
  std::lock_guard<std::mutex> lock(register_mu_);
  if (const int i = Find(kind); i >= 0) return i;
  const int n = used_.load(std::memory_order_relaxed);
  if (n >= kMaxKinds) return -1;
  slots_[n].name = std::string(kind);
  used_.store(n + 1, std::memory_order_release);
  return n;
}

void DropCounters::Count(int slot, std::string_view detail) {
  if (slot < 0 || slot >= used_.load(std::memory_order_acquire)) {
    overflow_.fetch_add(1, std::memory_order_relaxed);
    return;
  }
  Slot& s = slots_[slot];
  s.count.fetch_add(1, std::memory_order_relaxed);
  if (!detail.empty() && !s.detail_busy.exchange(true, std::memory_order_acquire)) {
    // Untrusted text: cut and escaped when logged; here only bounded.
    const std::size_t n = std::min(detail.size(), sizeof s.detail - 1);
    std::copy_n(detail.data(), n, s.detail);
    s.detail[n] = '\0';
    s.detail_busy.store(false, std::memory_order_release);
  }
  if (!deferred_) {
    std::lock_guard<std::mutex> lock(report_mu_);
    MaybeLog(s, base::MonotonicNow().ns);
  }
}

void DropCounters::Count(std::string_view kind, std::string_view detail) {
  Count(Register(kind), detail);
}

void DropCounters::MaybeLog(Slot& s, std::int64_t now_ns) {
  const std::uint64_t count = s.count.load(std::memory_order_relaxed);
  if (count == s.logged) return;
  if (s.logged != 0 && now_ns - s.last_log_ns < 10'000'000'000) return;
  std::string detail;
  if (!s.detail_busy.exchange(true, std::memory_order_acquire)) {
    detail = s.detail;
    s.detail_busy.store(false, std::memory_order_release);
  }
  spdlog::warn("dropped: {}{}{} ({} since the last report of this kind)", s.name,
               detail.empty() ? "" : ": ", base::Quote(detail, 120), count - s.logged);
  s.logged = count;
  s.last_log_ns = now_ns;
}

void DropCounters::Report() {
  std::lock_guard<std::mutex> lock(report_mu_);
  const std::int64_t now = base::MonotonicNow().ns;
  const int n = used_.load(std::memory_order_acquire);
  for (int i = 0; i < n; ++i) MaybeLog(slots_[i], now);
}

std::map<std::string, std::uint64_t> DropCounters::Snapshot() const {
  std::map<std::string, std::uint64_t> out;
  const int n = used_.load(std::memory_order_acquire);
  for (int i = 0; i < n; ++i) {
    const std::uint64_t c = slots_[i].count.load(std::memory_order_relaxed);
    if (c > 0) out[slots_[i].name] = c;
  }
  if (const std::uint64_t o = overflow_.load(std::memory_order_relaxed); o > 0) {
    out["drops of unregistered kinds"] = o;
  }
  return out;
}

std::uint64_t DropCounters::Total() const {
  std::uint64_t total = overflow_.load(std::memory_order_relaxed);
  const int n = used_.load(std::memory_order_acquire);
  for (int i = 0; i < n; ++i) total += slots_[i].count.load(std::memory_order_relaxed);
  return total;
}

std::uint64_t DropCounters::Of(std::string_view kind) const {
  const int i = Find(kind);
  return i < 0 ? 0 : slots_[i].count.load(std::memory_order_relaxed);
}

}  // namespace vdyn::transport
