#include "vdyn/base/time.h"

#include <sys/resource.h>
#include <time.h>

#include <cerrno>

namespace vdyn::base {
namespace {
std::int64_t Read(clockid_t id) {
  timespec ts;
  clock_gettime(id, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}
}  // namespace

MonoTime MonotonicNow() { return {Read(CLOCK_MONOTONIC)}; }
WallTime WallNow() { return {Read(CLOCK_REALTIME)}; }

void SleepUntil(MonoTime t) {
  if (t.ns <= 0) return;
  timespec ts;
  ts.tv_sec = t.ns / 1'000'000'000;
  ts.tv_nsec = t.ns % 1'000'000'000;
  while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
  }
}

Nanos ProcessCpuTime() {
  rusage ru{};
  getrusage(RUSAGE_SELF, &ru);
  const auto ns = [](const timeval& tv) {
    return static_cast<std::int64_t>(tv.tv_sec) * 1'000'000'000 + tv.tv_usec * 1000;
  };
  return {ns(ru.ru_utime) + ns(ru.ru_stime)};
}

}  // namespace vdyn::base
