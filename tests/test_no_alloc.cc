// A step allocates nothing: every heap allocation made while the simulator steps is counted,
// through operator new and (outside the sanitizer build, which owns malloc) malloc itself.
#include <atomic>
#include <cstdlib>
#include <new>

#include <gtest/gtest.h>

#include "maneuver.h"
#include "params_io.h"
#include "simulator.h"
#include "world.h"

namespace {
std::atomic<bool> g_counting{false};
std::atomic<long> g_allocations{0};
void Count() {
  if (g_counting.load(std::memory_order_relaxed)) g_allocations.fetch_add(1);
}
}  // namespace

void* operator new(std::size_t n) {
  Count();
  if (void* p = std::malloc(n == 0 ? 1 : n)) return p;
  throw std::bad_alloc();
}
void* operator new[](std::size_t n) {
  Count();
  if (void* p = std::malloc(n == 0 ? 1 : n)) return p;
  throw std::bad_alloc();
}
void* operator new(std::size_t n, std::align_val_t a) {
  Count();
  const std::size_t al = static_cast<std::size_t>(a);
  if (void* p = std::aligned_alloc(al, (n + al - 1) / al * al)) return p;
  throw std::bad_alloc();
}
void operator delete(void* p) noexcept { std::free(p); }
void operator delete[](void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t) noexcept { std::free(p); }
void operator delete(void* p, std::align_val_t) noexcept { std::free(p); }
void operator delete(void* p, std::size_t, std::align_val_t) noexcept { std::free(p); }

#if !defined(__SANITIZE_ADDRESS__)
extern "C" {
void* __libc_malloc(std::size_t);
void* __libc_calloc(std::size_t, std::size_t);
void* __libc_realloc(void*, std::size_t);
void* __libc_memalign(std::size_t, std::size_t);
void* malloc(std::size_t n) {
  Count();
  return __libc_malloc(n);
}
void* calloc(std::size_t a, std::size_t b) {
  Count();
  return __libc_calloc(a, b);
}
void* realloc(void* p, std::size_t n) {
  Count();
  return __libc_realloc(p, n);
}
void* aligned_alloc(std::size_t al, std::size_t n) {
  Count();
  return __libc_memalign(al, n);
}
int posix_memalign(void** out, std::size_t al, std::size_t n) {
  Count();
  *out = __libc_memalign(al, n);
  return *out != nullptr ? 0 : 12;  // ENOMEM
}
}
#endif

namespace vdyn {
namespace {

TEST(NoAllocation, StepsOnFacilityAllocateNothing) {
  std::shared_ptr<const World> world = BuildBuiltinWorld("facility");
  Simulator sim(world, ParamsFromProto(DefaultVehicleParams()));
  const Maneuver m = Maneuver::Parse(DemoManeuverCsv(), "demo");
  const Eigen::Vector3d ramp = world->LandmarkAt("jump_ramp_a");
  sim.Spawn({ramp.x() - 30.0, ramp.y(), 0.0}, 50.0 / 3.6);
  // Warm up, then count over a stretch with a jump, wall traces and the speed control.
  for (int i = 0; i < 10; ++i) sim.Step();
  long counted_calls = 0;
  g_allocations = 0;
  g_counting = true;
  for (int i = 0; i < 5000; ++i) {
    DriverInput in = m.At(20.0);
    in.steer = (i % 1000 < 500) ? 0.05 : -0.05;
    sim.SetInput(in);
    sim.Step();
    ++counted_calls;
  }
  g_counting = false;
  EXPECT_EQ(g_allocations.load(), 0) << "allocations in " << counted_calls << " steps";
  // The counter works: an allocation while counting is seen.
  g_counting = true;
  auto* probe = new std::vector<int>(100);
  g_counting = false;
  delete probe;
  EXPECT_GE(g_allocations.load(), 1);
}

}  // namespace
}  // namespace vdyn
