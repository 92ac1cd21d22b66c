// The 1 kHz thread allocates nothing: every heap allocation made by the stepping thread is
// counted, through operator new and (outside the sanitizer build, which owns malloc) malloc
// itself. Two paths: the simulator's step, and the server's real loop - a ServerNode running in
// this process, its loop on a thread of this test and its vehicles stepped by the loop and two
// workers (StepPool, also counted), while driver input changes every millisecond (an analog
// wheel), a subscriber in another process takes the states, and control requests of every kind
// arrive: the request thread makes them ready, the loop only swaps them in.
#include <sys/prctl.h>

#include <atomic>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <new>
#include <thread>

#include <gtest/gtest.h>

#include "dds_wait.h"
#include "process.h"
#include "test_support.h"
#include "vdyn/bridge/convert.h"
#include "vdyn/bridge/params.h"
#include "vdyn/io/maneuver.h"
#include "vdyn/io/tire_file.h"
#include "vdyn/physics/simulator.h"
#include "vdyn/physics/world.h"
#include "vdyn/runtime/server_node.h"
#include "vdyn/runtime/step_pool.h"
#include "vdyn/transport/control_client.h"
#include "vdyn/transport/dds.h"

namespace {
// Counting is per thread: DDS's own threads, the server's other threads, allocate as they please.
// t_counting: this thread, now; t_loop and g_count_loop: the server's loop thread and its
// stepping workers (threads named vdyn-step-K, runtime/step_pool.h), while set.
thread_local bool t_counting = false;
thread_local bool t_loop = false;
thread_local int t_step_worker = -1;  // unknown yet; then 0 or 1 (a worker names itself first)
std::atomic<bool> g_count_loop{false};
std::atomic<long> g_allocations{0};
bool IsStepWorker() {
  if (t_step_worker < 0) {
    char name[16] = {};
    prctl(PR_GET_NAME, name, 0, 0, 0);
    t_step_worker = std::strncmp(name, "vdyn-step-", 10) == 0 ? 1 : 0;
  }
  return t_step_worker == 1;
}
void Count() {
  if (t_counting || (g_count_loop.load(std::memory_order_relaxed) && (t_loop || IsStepWorker()))) {
    g_allocations.fetch_add(1);
  }
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

#if !defined(VDYN_TEST_ASAN)  // (test_support.h)
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
  for (int i = 0; i < 10; ++i) ASSERT_EQ(sim.Step(), StepStatus::kOk);
  const std::uint64_t traced_before = sim.wall_traced_steps();
  int airborne_steps = 0, nonfinite = 0;
  g_allocations = 0;
  t_counting = true;
  for (int i = 0; i < 5000; ++i) {
    DriverInput in = FromManeuver(m.At(20.0));
    in.steer = (i % 1000 < 500) ? 0.05 : -0.05;
    sim.SetInput(in);
    nonfinite += sim.Step() != StepStatus::kOk;
    bool airborne = true;
    for (const WheelOutputs& w : sim.last_step().derived.wheel) airborne = airborne && !w.contact;
    airborne_steps += airborne;
  }
  t_counting = false;
  EXPECT_EQ(g_allocations.load(), 0) << "allocations in 5000 steps";
  EXPECT_EQ(nonfinite, 0);
  // The stretch did what it promises: a jump (all four wheels in the air) and wall traces (the
  // ramp's steep faces are near).
  EXPECT_GT(airborne_steps, 100);
  EXPECT_GT(sim.wall_traced_steps() - traced_before, 100u);
  ExpectCounterWorks();
}

// The same stretch on Magic Formula tyres (issue 34): the law, its relaxation and its low-speed
// handling allocate nothing either.
TEST(NoAllocation, StepsOnMagicFormulaTyresAllocateNothing) {
  std::shared_ptr<const World> world = BuildBuiltinWorld("facility");
  pb::VehicleParams params = DefaultVehicleParams();
  const pb::MagicFormulaTire tire = ReadTireFile(std::filesystem::path(VDYN_SOURCE_DIR) / "tires" /
                                                 "vdyn_synthetic_205_55R16_mf61.tir");
  for (pb::WheelParams* w :
       {params.mutable_lf(), params.mutable_rf(), params.mutable_lr(), params.mutable_rr()}) {
    *w->mutable_magic_formula() = tire;
  }
  Simulator sim(world, ParamsFromProto(params));
  const Maneuver m = Maneuver::Parse(DemoManeuverCsv(), "demo");
  const Eigen::Vector3d ramp = world->LandmarkAt("jump_ramp_a");
  sim.Spawn({ramp.x() - 30.0, ramp.y(), 0.0}, 50.0 / 3.6);
  for (int i = 0; i < 10; ++i) ASSERT_EQ(sim.Step(), StepStatus::kOk);
  int airborne_steps = 0, nonfinite = 0;
  double largest_fy = 0.0;
  g_allocations = 0;
  t_counting = true;
  for (int i = 0; i < 7000; ++i) {
    DriverInput in = FromManeuver(m.At(20.0));
    in.steer = (i % 1000 < 500) ? 0.05 : -0.05;
    if (i > 3000) {  // after the jump, a stop: the low-speed handling, then at rest
      in.throttle = 0.0;
      in.brake = 1.0;
      in.cruise_on = false;
    }
    sim.SetInput(in);
    nonfinite += sim.Step() != StepStatus::kOk;
    bool airborne = true;
    for (const WheelOutputs& w : sim.last_step().derived.wheel) {
      airborne = airborne && !w.contact;
      largest_fy = std::max(largest_fy, std::abs(w.Fy));
    }
    airborne_steps += airborne;
  }
  t_counting = false;
  EXPECT_EQ(g_allocations.load(), 0) << "allocations in 7000 steps";
  EXPECT_EQ(nonfinite, 0);
  EXPECT_GT(airborne_steps, 100);
  EXPECT_GT(largest_fy, 1000.0);                    // the tyres did corner
  EXPECT_LT(Velocity(sim.state().x).norm(), 0.05);  // and the car stopped
  EXPECT_TRUE(sim.params().wheel[kLF].mf.enabled);
  ExpectCounterWorks();
}

// The server test below counts its stepping workers by their name: a worker's allocations are
// seen (a vector and its elements for each item of the worker's part of the job, each counted in
// operator new and again in malloc where malloc is counted; part 0 runs here, on a thread that is
// neither the loop nor a worker, and is not counted).
TEST(NoAllocation, AnAllocationOnAStepWorkerIsCounted) {
  StepPool pool(2);
  std::vector<int>* made[5] = {};
  auto part = [&made](std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i < end; ++i) made[i] = new std::vector<int>(10);
  };
  g_allocations = 0;
  g_count_loop = true;
  pool.Run(5, part);
  g_count_loop = false;
  const auto on_worker = static_cast<long>(5 - StepPool::Begin(5, 2, 1));
  ASSERT_GE(on_worker, 1);
#if defined(VDYN_TEST_ASAN)
  EXPECT_EQ(g_allocations.load(), 2 * on_worker);
#else
  EXPECT_EQ(g_allocations.load(), 4 * on_worker);
#endif
  for (std::vector<int>* v : made) delete v;
}

// Requests of every kind, each answered: spawns (one where a removed vehicle lived), teleports,
// a reset, new parameters, a restore of a new vehicle, a pause, steps while paused, a resume, a
// removal. `round` keeps ids and poses apart between calls.
void SendRequests(transport::ControlClient& control, int round, int* accepted, int* answered) {
  auto call = [&](pb::ControlRequest r) {
    const auto reply = control.Call(std::move(r), std::chrono::seconds(20));
    *answered += reply.has_value();
    *accepted += reply.has_value() && reply->accepted();
    EXPECT_TRUE(reply.has_value()) << control.last_error();
    if (reply) {
      EXPECT_TRUE(reply->accepted()) << reply->reason();
    }
  };
  // The spawned ids are the same every round: a vehicle comes back where a removed one lived.
  const auto id = [&](int k) { return static_cast<std::uint32_t>(100 + k); };
  const auto restored_id = static_cast<std::uint32_t>(105 + round);
  for (int k = 0; k < 4; ++k) {
    pb::ControlRequest spawn;
    spawn.set_vehicle_id(id(k));
    spawn.set_server_id("no-alloc");
    spawn.mutable_spawn()->mutable_pose()->set_x(-200.0 + 8.0 * k);
    spawn.mutable_spawn()->mutable_pose()->set_y(0.0);
    spawn.mutable_spawn()->mutable_params()->set_mass(1500.0 + 10.0 * k);
    call(spawn);
  }
  pb::ControlRequest teleport;
  teleport.set_vehicle_id(1);
  teleport.mutable_teleport()->mutable_pose()->set_x(-230.0);
  teleport.mutable_teleport()->mutable_pose()->set_y(5.0 * round);
  teleport.mutable_teleport()->set_speed(10.0);
  call(teleport);
  pb::ControlRequest reset;
  reset.set_vehicle_id(id(0));
  reset.mutable_reset();
  call(reset);
  pb::ControlRequest params;
  params.set_vehicle_id(1);
  params.mutable_set_params()->mutable_params()->set_mass(1600.0 + round);
  call(params);
  // A new vehicle from an exact state (as a takeover brings one back).
  Simulator sim(testing::SharedWorld("facility"), ParamsFromProto(DefaultVehicleParams()));
  sim.Spawn({-150.0, 0.0, 0.0}, 5.0);
  pb::ControlRequest restore;
  restore.set_vehicle_id(restored_id);
  restore.set_server_id("no-alloc");
  *restore.mutable_restore()->mutable_state() = ToExactState(sim.state());
  restore.mutable_restore()->set_branched_from("test@" + std::to_string(round));
  call(restore);
  pb::ControlRequest pause;
  pause.set_vehicle_id(1);
  pause.mutable_pause();
  call(pause);
  pb::ControlRequest step;
  step.set_vehicle_id(1);
  step.mutable_step()->set_steps(20);
  call(step);
  call(step);
  pb::ControlRequest resume;
  resume.set_vehicle_id(1);
  resume.mutable_resume();
  call(resume);
  for (int k = 0; k < 4; ++k) {
    pb::ControlRequest remove;
    remove.set_vehicle_id(id(k));
    remove.mutable_remove();
    call(remove);
  }
  pb::ControlRequest remove;
  remove.set_vehicle_id(restored_id);
  remove.mutable_remove();
  call(remove);
}

TEST(NoAllocation, TheServerLoopAllocatesNothingWhileRequestsArriveAndInputChangesEveryStep) {
  testing::UseLoopbackDds();
  const std::uint32_t domain = testing::FreshDomain();
  // A subscriber in another process: the state writes take the network path.
  testing::TempDir dir;
  testing::Process subscriber({testing::StateSubscriberBinary(), std::to_string(domain), "100000",
                               "120"},
                              dir / "subscriber.log");
  std::shared_ptr<const World> world = testing::SharedWorld("facility");
  ServerOptions options;
  options.domain_id = domain;
  options.vehicle_ids = {1, 2};
  options.session.server_id = "no-alloc";
  options.session.default_params = DefaultVehicleParams();
  options.session.watchdog_s = 0.5;
  // Three stepping threads: the loop and two workers, the vehicles (2 to 7) cut unevenly.
  options.session.step_threads = 3;
  ServerNode node(world, options);
  std::atomic<bool> stop{false};
  int code = -1;
  std::thread loop([&] {
    t_loop = true;  // the thread that runs ServerNode::Run is the loop
    code = node.Run(stop);
  });

  // A rig on vehicle 1 whose steering changes every millisecond, and one on vehicle 2.
  transport::Participant p(domain);
  std::atomic<bool> rig_stop{false};
  std::thread rig([&] {
    transport::Writer<pb::DriverInput> input(p, transport::TopicId::kInput, 10);
    pb::DriverInput in;
    in.set_source_id("an-analog-wheel-with-a-long-source-id-0123456789");
    in.set_cruise_on(true);
    in.set_cruise_set_kmh(30.0);
    for (std::uint64_t k = 0; !rig_stop.load(); ++k) {
      for (std::uint32_t v : {1u, 2u}) {
        in.set_vehicle_id(v);
        in.set_steer(0.02 * std::sin(0.01 * static_cast<double>(k)));
        in.set_sequence(k);
        EXPECT_TRUE(input.Write(v, in)) << input.last_error();
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
  });
  transport::ControlClient control(p, "no-alloc-test");
  ASSERT_TRUE(control.WaitForServer(std::chrono::seconds(30))) << control.last_error();
  transport::DropCounters drops;
  transport::Reader<pb::Diagnostics> diag(p, transport::TopicId::kDiagnostics, &drops);

  // Warm-up: every kind of request once, and a second of steps, so every buffer has its size.
  int accepted = 0, answered = 0;
  SendRequests(control, 0, &accepted, &answered);
  std::this_thread::sleep_for(std::chrono::seconds(1));

  // Counted: the loop thread, from here, while the same kinds of requests arrive twice more.
  g_allocations = 0;
  g_count_loop = true;
  const int answered_before = answered;
  SendRequests(control, 1, &accepted, &answered);
  SendRequests(control, 2, &accepted, &answered);
  std::this_thread::sleep_for(std::chrono::milliseconds(500));  // steps with all vehicles
  g_count_loop = false;
  const long loop_allocations = g_allocations.load();

  // The loop ran and stepped meanwhile (the diagnostics say so), and every request was answered.
  std::uint64_t steps = 0;
  ASSERT_TRUE(testing::ReadUntil<pb::Diagnostics>(
      diag, std::chrono::seconds(10), [&](const pb::Diagnostics& d) { steps = d.steps(); },
      [&] { return steps > 2000; }));
  rig_stop = true;
  rig.join();
  stop = true;
  loop.join();
  EXPECT_EQ(code, 0);
  EXPECT_EQ(answered - answered_before, 2 * 17);
  EXPECT_EQ(accepted, 3 * 17);
  EXPECT_EQ(loop_allocations, 0) << "allocations on the server's loop thread or stepping workers";
  ExpectCounterWorks();
}

}  // namespace
}  // namespace vdyn
