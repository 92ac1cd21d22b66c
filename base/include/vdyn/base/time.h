// Typed clocks: monotonic time and wall-clock time are different types (Cyclone DDS's habit), each
// an int64 count of nanoseconds, so a wall-clock stamp cannot be subtracted from a monotonic one.
//
//   MonoTime   CLOCK_MONOTONIC: pacing, timeouts, latencies inside one machine
//   WallTime   CLOCK_REALTIME since the Unix epoch: DDS source timestamps, recordings' log times
//   Nanos      a duration
#pragma once

#include <cmath>
#include <compare>
#include <cstdint>

namespace vdyn::base {

struct Nanos {
  std::int64_t ns = 0;
  constexpr auto operator<=>(const Nanos&) const = default;
  constexpr Nanos operator+(Nanos o) const { return {ns + o.ns}; }
  constexpr Nanos operator-(Nanos o) const { return {ns - o.ns}; }
  constexpr double seconds() const { return static_cast<double>(ns) * 1e-9; }
  constexpr double millis() const { return static_cast<double>(ns) * 1e-6; }
  constexpr double micros() const { return static_cast<double>(ns) * 1e-3; }
};
constexpr Nanos Milliseconds(std::int64_t ms) { return {ms * 1'000'000}; }
constexpr Nanos Seconds(std::int64_t s) { return {s * 1'000'000'000}; }
// A time given in seconds (a command line's), to the nearest nanosecond: 0.541000567 s is
// 541000567 ns, where a cast would truncate the double's 541000566.99... to 541000566.
inline Nanos FromSeconds(double s) { return {std::llround(s * 1e9)}; }

struct MonoTime {
  std::int64_t ns = 0;
  constexpr auto operator<=>(const MonoTime&) const = default;
  constexpr MonoTime operator+(Nanos d) const { return {ns + d.ns}; }
  constexpr MonoTime operator-(Nanos d) const { return {ns - d.ns}; }
  constexpr Nanos operator-(MonoTime o) const { return {ns - o.ns}; }
};

struct WallTime {
  std::int64_t ns = 0;
  constexpr auto operator<=>(const WallTime&) const = default;
  constexpr WallTime operator+(Nanos d) const { return {ns + d.ns}; }
  constexpr Nanos operator-(WallTime o) const { return {ns - o.ns}; }
};

MonoTime MonotonicNow();
WallTime WallNow();
// Sleeps until the absolute monotonic time t (returns at once when it has passed); resumes after
// signals.
void SleepUntil(MonoTime t);
// CPU time of this process (user + system).
Nanos ProcessCpuTime();

}  // namespace vdyn::base
