// The 1 kHz thread allocates nothing: every heap allocation made by the stepping thread is
// counted, through operator new and (outside the sanitizer build, which owns malloc) malloc
// itself. Two paths: the simulator's step, and the server's whole loop body - Session::Step with
// an input that changes every step (an analog wheel), the state message filled and handed to the
// state outbox that writes it over DDS to a subscriber in another process (Cyclone allocates in
// dds_write: the outbox's own thread does that), the input events gathered and handed on.
#include <atomic>
#include <chrono>
#include <cstdlib>
#include <new>
#include <thread>

#include <gtest/gtest.h>

#include "process.h"
#include "test_support.h"
#include "vdyn/bridge/convert.h"
#include "vdyn/base/spsc_queue.h"
#include "vdyn/bridge/params.h"
#include "vdyn/io/maneuver.h"
#include "vdyn/physics/simulator.h"
#include "vdyn/physics/world.h"
#include "vdyn/runtime/session.h"
#include "vdyn/runtime/state_outbox.h"
#include "vdyn/transport/dds.h"

namespace {
// Counting is per thread: DDS's own threads allocate as they please.
thread_local bool t_counting = false;
std::atomic<long> g_allocations{0};
void Count() {
  if (t_counting) g_allocations.fetch_add(1);
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

// GCC names AddressSanitizer with a macro, clang with a feature.
#if defined(__SANITIZE_ADDRESS__)
#define VDYN_ASAN 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define VDYN_ASAN 1
#endif
#endif

#if !defined(VDYN_ASAN)
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

// The counter works: an allocation while counting is seen (else every test here passes vacuously).
void ExpectCounterWorks() {
  const long before = g_allocations.load();
  t_counting = true;
  auto* probe = new std::vector<int>(100);
  t_counting = false;
  delete probe;
  EXPECT_GE(g_allocations.load() - before, 1);
}

TEST(NoAllocation, StepsOnFacilityAllocateNothing) {
  std::shared_ptr<const World> world = BuildBuiltinWorld("facility");
  Simulator sim(world, ParamsFromProto(DefaultVehicleParams()));
  const Maneuver m = Maneuver::Parse(DemoManeuverCsv(), "demo");
  const Eigen::Vector3d ramp = world->LandmarkAt("jump_ramp_a");
  sim.Spawn({ramp.x() - 30.0, ramp.y(), 0.0}, 50.0 / 3.6);
  // Warm up, then count over a stretch with a jump, wall traces and the speed control.
  for (int i = 0; i < 10; ++i) sim.Step();
  const std::uint64_t traced_before = sim.wall_traced_steps();
  int airborne_steps = 0;
  g_allocations = 0;
  t_counting = true;
  for (int i = 0; i < 5000; ++i) {
    DriverInput in = FromManeuver(m.At(20.0));
    in.steer = (i % 1000 < 500) ? 0.05 : -0.05;
    sim.SetInput(in);
    sim.Step();
    bool airborne = true;
    for (const WheelOutputs& w : sim.last_step().derived.wheel) airborne = airborne && !w.contact;
    airborne_steps += airborne;
  }
  t_counting = false;
  EXPECT_EQ(g_allocations.load(), 0) << "allocations in 5000 steps";
  // The stretch did what it promises: a jump (all four wheels in the air) and wall traces (the
  // ramp's steep faces are near).
  EXPECT_GT(airborne_steps, 100);
  EXPECT_GT(sim.wall_traced_steps() - traced_before, 100u);
  ExpectCounterWorks();
}

TEST(NoAllocation, TheServerLoopBodyAllocatesNothingWithAnInputChangingEveryStep) {
  testing::UseLoopbackDds();
  const std::uint32_t domain = testing::FreshDomain();
  // A subscriber in another process: the state writes take the network path.
  testing::TempDir dir;
  testing::Process subscriber({testing::StateSubscriberBinary(), std::to_string(domain), "100000",
                               "120"},
                              dir / "subscriber.log");
  std::shared_ptr<const World> world = BuildBuiltinWorld("facility");
  transport::Participant participant(domain);
  transport::DropCounters drops(/*deferred=*/true);
  StateOutbox outbox(participant, drops);
  // A probe writer on the same topic tells when the subscriber has matched.
  transport::Writer<pb::VehicleState> probe(participant, transport::TopicId::kState);
  long events = 0, input_changes = 0;
  SessionConfig config;
  config.server_id = "no-alloc";
  config.default_params = DefaultVehicleParams();
  // The events go into a lock-free queue, as the server's do, and a consumer thread (the
  // server's publisher) takes them out.
  base::SpscQueue<SessionEventRecord> queue(4096);
  std::atomic<bool> done{false};
  std::atomic<long> consumed{0};
  std::thread consumer([&] {
    SessionEventRecord r;
    while (!done.load() || !queue.empty()) {
      if (queue.TryPop(r)) {
        ++consumed;
        r.message.reset();
        r.params.reset();
      } else {
        std::this_thread::sleep_for(std::chrono::microseconds(200));
      }
    }
  });
  Session session(world, config, [&](SessionEventRecord&& r) {
    ++events;
    if (r.kind == SessionEventRecord::Kind::kInputBatch) input_changes += r.n_changes;
    EXPECT_TRUE(queue.TryPush(std::move(r)));
  });
  const Eigen::Vector3d ramp = world->LandmarkAt("jump_ramp_a");
  session.Spawn(1, {ramp.x() - 30.0, ramp.y(), 0.0}, 50.0 / 3.6, pb::VehicleParams());
  long pushed = 0;
  const Session::StateSink sink = [&](std::uint32_t id, const pb::VehicleState& s) {
    pushed += outbox.Push(id, s);
  };
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
  while (probe.MatchedReaders() == 0 && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  ASSERT_GE(probe.MatchedReaders(), 1u) << "the subscriber never matched\n" << subscriber.Log();
  pb::DriverInput in;
  in.set_vehicle_id(1);
  in.set_source_id("an-analog-wheel-with-a-long-source-id-0123456789");
  in.set_cruise_on(true);
  in.set_cruise_set_kmh(50.0);
  int step = 0;
  auto drive = [&](int n) {
    for (int i = 0; i < n; ++i, ++step) {
      in.set_steer(0.02 * std::sin(0.01 * step));  // new every step
      in.set_sequence(static_cast<std::uint64_t>(step));
      session.OfferInput(in, nullptr);
      session.Step(sink);
      outbox.Send();
    }
  };
  // Paced like the server (a step a millisecond on average), so the outbox never fills up.
  auto paced = [&](int n) {
    for (int k = 0; k < n; k += 10) {
      drive(10);
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
  };
  paced(2000);  // warm-up: every buffer reaches its size
  const long events_before = events, changes_before = input_changes;
  g_allocations = 0;
  t_counting = true;
  // 3 s with a jump, wall traces and checkpoints at steps 3000 and 4000. (The pacing sleep is
  // not the loop's: the server sleeps with clock_nanosleep, which allocates nothing either.)
  for (int k = 0; k < 3000; k += 10) {
    drive(10);
    t_counting = false;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
    t_counting = true;
  }
  t_counting = false;
  EXPECT_EQ(g_allocations.load(), 0) << "allocations in 3000 steps of the loop body";
  ASSERT_TRUE(outbox.Drain(base::Seconds(10)));
  EXPECT_EQ(pushed, 5000);
  EXPECT_EQ(outbox.written(), 5000u);
  EXPECT_EQ(outbox.write_failures(), 0u);
  // The path was exercised: inputs changed every step and went out batched.
  EXPECT_GE(input_changes - changes_before, 2900);
  EXPECT_GT(events - events_before, 100);
  EXPECT_GT(session.simulator(1).wall_traced_steps(), 100u);
  done = true;
  consumer.join();
  EXPECT_EQ(consumed.load(), events);
  ExpectCounterWorks();
}

}  // namespace
}  // namespace vdyn
