// Session rules without the network: requests, input latching, the watchdog, events and the
// bit-exact re-simulation of a session from its events.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <limits>
#include <map>
#include <numeric>
#include <set>
#include <span>
#include <stdexcept>
#include <thread>

#include <functional>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "test_support.h"
#include "vdyn/base/hash.h"
#include "vdyn/bridge/convert.h"
#include "vdyn/replay/resim.h"
#include "vdyn/physics/mesh.h"
#include "vdyn/runtime/claim.h"
#include "vdyn/runtime/placement.h"
#include "vdyn/runtime/request_planner.h"
#include "vdyn/runtime/session.h"
#include "vdyn/runtime/step_pool.h"

namespace vdyn {
namespace {

using ::testing::HasSubstr;

struct Recorder {
  std::vector<pb::SessionEvent> events;
  std::map<std::uint32_t, std::map<std::uint64_t, std::uint64_t>> hashes;  // vehicle -> step -> hash
};

// The session's event records as the server publishes them (messages).
Session::EventSink Into(Recorder& rec, const std::shared_ptr<const World>& world,
                        std::int64_t step_ns = 1'000'000) {
  const std::uint64_t terrain = TerrainHash(world->terrain);
  return [&rec, terrain, step_ns](SessionEventRecord&& r) {
    rec.events.push_back(ToMessage(r, "test", terrain, step_ns));
  };
}

SessionConfig Config() {
  SessionConfig c;
  c.server_id = "test";
  c.default_params = DefaultVehicleParams();
  c.checkpoint_every_steps = 500;
  return c;
}

pb::ControlRequest Request(std::uint32_t vehicle) {
  pb::ControlRequest r;
  r.set_vehicle_id(vehicle);
  r.set_request_id(1);
  r.set_client_id("t");
  return r;
}

pb::DriverInput Input(std::uint32_t vehicle, double throttle, double steer = 0.0) {
  pb::DriverInput in;
  in.set_vehicle_id(vehicle);
  in.set_source_id("test");
  in.set_throttle(throttle);
  in.set_steer(steer);
  return in;
}

void StepAndRecord(Session& s, Recorder& rec, int n) {
  for (int i = 0; i < n; ++i) {
    s.Step([&rec](std::uint32_t id, const pb::VehicleState& st) {
      rec.hashes[id][st.step()] = st.state_hash();
    });
  }
}

TEST(Session, SpawnEmitsTheExactStateAndCompleteParams) {
  Recorder rec;
  Session s(testing::SharedWorld("flat"), Config(), Into(rec, testing::SharedWorld("flat")));
  s.Spawn(7, {1.0, 2.0, 0.5}, 3.0, pb::VehicleParams());
  ASSERT_EQ(rec.events.size(), 1u);
  const pb::SessionEvent& e = rec.events[0];
  ASSERT_TRUE(e.has_spawned());
  EXPECT_EQ(e.vehicle_id(), 7u);
  EXPECT_EQ(e.step(), 0u);
  const State st = FromExactState(e.spawned().state());
  EXPECT_EQ(st.x, s.simulator(7).state().x);
  EXPECT_TRUE(ValidateVehicleParams(e.spawned().params()).empty());
  EXPECT_EQ(e.spawned().terrain_hash(), TerrainHash(testing::SharedWorld("flat")->terrain));
  EXPECT_THROW(s.Spawn(7, {0, 0, 0}, 0.0, pb::VehicleParams()), std::invalid_argument);
}

// ExactState carries either model's state bit for bit (13 numbers for the paper's model, 37 and
// the discrete state for the full model) and refuses anything else.
TEST(Session, ExactStateCarriesEitherModelBitForBitAndRefusesMalformedStates) {
  Simulator full(testing::SharedWorld("flat"), testing::DefaultParams());
  full.Spawn({0, 0, 0}, 12.0);
  DriverInput in;
  in.brake = 1.0;
  full.SetInput(in);
  for (int i = 0; i < 300; ++i) {  // ABS, gear and shift clock all away from defaults
    ASSERT_EQ(full.Step(), StepStatus::kOk);
  }
  const State s = full.state();
  const pb::ExactState m = ToExactState(s);
  EXPECT_EQ(m.x_size(), kStateSize);
  const State back = FromExactState(m);
  EXPECT_EQ(back.model, VehicleModel::kFull);
  EXPECT_EQ(StateHash(back), StateHash(s));
  // The full state hash as docs/hash.md writes it: x, the integral, gear, shift time, ABS, TC, step.
  base::WordHash h;
  for (double v : m.x()) h.Double(v);
  h.Double(m.cruise_integral());
  h.Int(m.gear());
  h.Double(m.shift_time());
  for (double a : m.abs()) h.Double(a);
  h.Double(m.tc());
  h.Int(static_cast<std::int64_t>(m.step()));
  EXPECT_EQ(h.Final(), StateHash(s));
  EXPECT_NE(s.discrete.abs[kLR], 1.0);  // the discrete state is not at its defaults
  EXPECT_GT(s.discrete.gear, 0);
  Simulator paper(testing::SharedWorld("flat"), testing::PaperParams());
  paper.Spawn({0, 0, 0}, 12.0);
  for (int i = 0; i < 30; ++i) ASSERT_EQ(paper.Step(), StepStatus::kOk);
  const pb::ExactState mp = ToExactState(paper.state());
  EXPECT_EQ(mp.x_size(), kPaperStateSize);
  EXPECT_EQ(StateHash(FromExactState(mp)), StateHash(paper.state()));

  pb::ExactState bad = m;
  bad.mutable_x()->RemoveLast();
  EXPECT_THROW(FromExactState(bad), std::invalid_argument);
  bad = m;
  bad.mutable_abs()->RemoveLast();
  EXPECT_THROW(FromExactState(bad), std::invalid_argument);
  bad = m;
  bad.set_gear(12);
  EXPECT_THROW(FromExactState(bad), std::invalid_argument);
  bad = m;
  bad.set_tc(std::numeric_limits<double>::quiet_NaN());
  EXPECT_THROW(FromExactState(bad), std::invalid_argument);
}

// The watchdog's safe state in the full model: the last steering (angle and mode) and gear are
// kept, throttle, clutch and handbrake dropped, the brake at safe_brake.
TEST(Session, WatchdogSafeStateKeepsTheRigsSteeringAndGear) {
  Session s(testing::SharedWorld("flat"), Config(), {});
  s.Spawn(1, {0, 0, 0}, 10.0, pb::VehicleParams());
  pb::DriverInput rig = Input(1, 0.4, 0.7);
  rig.set_steer_mode(pb::STEER_HAND_WHEEL);
  rig.set_gear(3);
  rig.set_clutch(0.2);
  rig.set_handbrake(0.5);
  std::string why;
  ASSERT_TRUE(s.OfferInput(rig, &why)) << why;
  for (int i = 0; i < 150; ++i) s.Step();
  ASSERT_TRUE(s.in_safe_state(1));
  const DriverInput& in = s.simulator(1).input();
  EXPECT_EQ(in.steer_mode, SteerMode::kHandWheel);
  EXPECT_EQ(in.steer, 0.7);
  EXPECT_EQ(in.gear, 3);
  EXPECT_EQ(in.throttle, 0.0);
  EXPECT_EQ(in.clutch, 0.0);
  EXPECT_EQ(in.handbrake, 0.0);
  EXPECT_EQ(in.brake, Config().safe_brake);
}

TEST(Session, WatchdogBrakesWhenLiveInputStops) {
  Session s(testing::SharedWorld("flat"), Config(), {});
  s.Spawn(1, {0, 0, 0}, 0.0, pb::VehicleParams());
  // No input yet: the safe state from the first step.
  s.Step();
  EXPECT_TRUE(s.in_safe_state(1));
  EXPECT_DOUBLE_EQ(s.simulator(1).input().brake, Config().safe_brake);
  std::string why;
  ASSERT_TRUE(s.OfferInput(Input(1, 1.0), &why)) << why;
  // Latched at the boundary it arrived at (age 0) and for 100 ms after it (ages 1..100 ms).
  for (int i = 0; i <= 100; ++i) {
    s.Step();
    EXPECT_FALSE(s.in_safe_state(1)) << "input age " << i << " ms";
  }
  EXPECT_DOUBLE_EQ(s.simulator(1).input().throttle, 1.0);
  s.Step();  // 101 ms without new input
  EXPECT_TRUE(s.in_safe_state(1));
  EXPECT_DOUBLE_EQ(s.simulator(1).input().throttle, 0.0);
  EXPECT_DOUBLE_EQ(s.simulator(1).input().brake, Config().safe_brake);
}

TEST(Session, InputsOutOfRangeOrForUnknownVehiclesAreRefused) {
  Session s(testing::SharedWorld("flat"), Config(), {});
  s.Spawn(1, {0, 0, 0}, 0.0, pb::VehicleParams());
  std::string why;
  EXPECT_FALSE(s.OfferInput(Input(2, 0.5), &why));
  EXPECT_THAT(why, HasSubstr("no vehicle 2"));
  EXPECT_FALSE(s.OfferInput(Input(1, 1.5), &why));
  EXPECT_THAT(why, HasSubstr("throttle must be in [-1, 1]"));
  pb::DriverInput steer = Input(1, 0.0, 3.0);
  EXPECT_FALSE(s.OfferInput(steer, &why));
  EXPECT_THAT(why, HasSubstr("steer"));
}

TEST(Session, RequestsAreValidatedAndAnswered) {
  Recorder rec;
  Session s(testing::SharedWorld("flat"), Config(), Into(rec, testing::SharedWorld("flat")));
  s.Spawn(1, {0, 0, 0}, 0.0, pb::VehicleParams());

  pb::ControlRequest bad_params = Request(1);
  bad_params.mutable_set_params()->mutable_params()->set_mass(-3.0);
  pb::ControlReply r = s.Apply(bad_params);
  EXPECT_FALSE(r.accepted());
  EXPECT_THAT(r.reason(), HasSubstr("mass: vehicle mass, kg must be in (0, 100000], got -3"));

  pb::ControlRequest good_params = Request(1);
  good_params.mutable_set_params()->mutable_params()->set_mass(1600.0);
  EXPECT_TRUE(s.Apply(good_params).accepted());
  EXPECT_EQ(s.params(1).mass(), 1600.0);
  EXPECT_EQ(s.simulator(1).params().mass, 1600.0);
  EXPECT_TRUE(rec.events.back().has_params_changed());

  pb::ControlRequest teleport = Request(1);
  teleport.mutable_teleport()->mutable_pose()->set_x(50.0);
  teleport.mutable_teleport()->set_speed(-1.0);
  r = s.Apply(teleport);
  EXPECT_FALSE(r.accepted());
  EXPECT_THAT(r.reason(), HasSubstr("speed"));
  teleport.mutable_teleport()->set_speed(10.0);
  EXPECT_TRUE(s.Apply(teleport).accepted());
  EXPECT_NEAR(Position(s.simulator(1).state().x).x(), 50.0, 1e-12);
  EXPECT_TRUE(rec.events.back().has_spawned());

  pb::ControlRequest spawn = Request(1);
  spawn.mutable_spawn();
  EXPECT_THAT(s.Apply(spawn).reason(), HasSubstr("exists already"));
  spawn.set_vehicle_id(2);
  EXPECT_THAT(s.Apply(spawn).reason(), HasSubstr("spawn needs server_id"));
  spawn.set_server_id("test");
  spawn.mutable_spawn()->mutable_params()->mutable_lf()->set_radius(0.0);
  EXPECT_THAT(s.Apply(spawn).reason(), HasSubstr("lf.radius"));
  spawn.mutable_spawn()->clear_params();
  // 0 names no vehicle in a message: a spawn or restore of it is refused with the range.
  spawn.set_vehicle_id(0);
  EXPECT_THAT(s.Apply(spawn).reason(), HasSubstr("vehicle id must be in [1, 4294967295], got 0"));
  pb::ControlRequest restore = spawn;
  *restore.mutable_restore()->mutable_state() = ToExactState(s.simulator(1).state());
  EXPECT_THAT(s.Apply(restore).reason(),
              HasSubstr("restore: vehicle id must be in [1, 4294967295], got 0"));
  EXPECT_THROW(s.Spawn(0, {0, 20, 0}, 0.0, pb::VehicleParams()), std::invalid_argument);
  EXPECT_FALSE(s.HasVehicle(0));
  spawn.set_vehicle_id(2);
  EXPECT_TRUE(s.Apply(spawn).accepted());
  EXPECT_EQ(s.vehicle_count(), 2u);

  pb::ControlRequest remove = Request(2);
  remove.mutable_remove();
  EXPECT_TRUE(s.Apply(remove).accepted());
  EXPECT_FALSE(s.HasVehicle(2));
  EXPECT_THAT(s.Apply(remove).reason(), HasSubstr("no vehicle 2"));

  pb::ControlRequest none = Request(1);
  EXPECT_THAT(s.Apply(none).reason(), HasSubstr("no command"));

  // A hello changes nothing and is accepted, for a vehicle or none (as the server answers it).
  const std::size_t events_before = rec.events.size();
  pb::ControlRequest hello = Request(1);
  hello.mutable_hello();
  r = s.Apply(hello);
  EXPECT_TRUE(r.accepted()) << r.reason();
  EXPECT_EQ(r.request_id(), hello.request_id());
  hello.set_vehicle_id(0);
  EXPECT_TRUE(s.Apply(hello).accepted());
  EXPECT_EQ(rec.events.size(), events_before);

  pb::ControlRequest step = Request(1);
  step.mutable_step()->set_steps(0);
  EXPECT_FALSE(s.Apply(step).accepted());
  step.mutable_step()->set_steps(5);
  EXPECT_TRUE(s.Apply(step).accepted());
  EXPECT_TRUE(s.paused());
  EXPECT_EQ(s.pending_steps(), 5u);
}

// restore took any finite state, where spawn and teleport check the pose: a car 1e9 m out (no
// terrain: it fell for ever), 1000 km up, with a zero quaternion or at 1e5 m/s was accepted.
TEST(Session, ARestoredStateMustBeOneAServerCouldHaveSaved) {
  Session s(testing::SharedWorld("flat"), Config(), {});
  s.Spawn(1, {0, 0, 0}, 0.0, pb::VehicleParams());
  for (int i = 0; i < 10; ++i) s.Step();
  const State saved = s.simulator(1).state();
  struct Bad {
    std::function<void(State&)> edit;
    const char* says;
  };
  const Bad bad[] = {
      {[](State& t) { t.x[sx::kP] = 1e9; }, "pose position, m must be in [-1e7, 1e7], got 1e9"},
      {[](State& t) { t.x[sx::kP] = 5e6; }, "no terrain under its position (5000000, "},
      {[](State& t) { t.x[sx::kP + 2] += 1e6; }, "m above the ground under it (at most 100 m"},
      {[](State& t) { t.x[sx::kP + 2] -= 150.0; }, "m below the ground under it"},
      {[](State& t) { t.x.segment<4>(sx::kQ).setZero(); }, "orientation quaternion has norm 0"},
      {[](State& t) { t.x[sx::kV] = 1e5; }, "moves faster than 1000 m/s"},
  };
  for (const Bad& b : bad) {
    State t = saved;
    b.edit(t);
    pb::ControlRequest restore = Request(5);
    restore.set_server_id("test");
    *restore.mutable_restore()->mutable_state() = ToExactState(t);
    const pb::ControlReply r = s.Apply(restore);
    EXPECT_FALSE(r.accepted()) << b.says;
    EXPECT_THAT(r.reason(), HasSubstr("restore: ")) << r.reason();
    EXPECT_THAT(r.reason(), HasSubstr(b.says)) << r.reason();
    EXPECT_FALSE(s.HasVehicle(5));
  }
  pb::ControlRequest restore = Request(5);
  restore.set_server_id("test");
  *restore.mutable_restore()->mutable_state() = ToExactState(saved);
  const pb::ControlReply r = s.Apply(restore);
  EXPECT_TRUE(r.accepted()) << r.reason();
}

// A request is planned off the stepping thread and applied later: when the session changed in
// between in a way the plan could not know, applying it refuses it with the reason, leaves the
// vehicle as it is, and tells the planner (its view of the vehicles stays right).
TEST(Session, APlanTheSessionNoLongerFitsIsRefusedWithTheReason) {
  const auto world = testing::SharedWorld("flat");
  Session s(world, Config(), nullptr);
  s.Spawn(1, {0, 0, 0}, 0.0, pb::VehicleParams());
  RequestPlanner planner(world, Config());
  planner.Sync(s);
  // New parameters planned for vehicle 1; meanwhile it is given others.
  pb::ControlRequest heavy = Request(1);
  heavy.mutable_set_params()->mutable_params()->set_mass(1700.0);
  RequestPlanner::Plan plan = planner.Prepare(std::make_shared<const pb::ControlRequest>(heavy));
  ASSERT_TRUE(plan.prepared) << plan.refusal;
  pb::ControlRequest light = Request(1);
  light.mutable_set_params()->mutable_params()->set_mass(1600.0);
  ASSERT_TRUE(s.Apply(light).accepted());
  RequestOutcome o = s.Commit(*plan.prepared);
  EXPECT_FALSE(o.accepted);
  EXPECT_THAT(OutcomeReason(o, "test"),
              HasSubstr("vehicle 1 on server 'test' changed while this request waited"));
  EXPECT_EQ(s.params(1).mass(), 1600.0);
  planner.Settle(std::move(plan.prepared));
  // A restore planned at the vehicle's step, applied after the vehicle stepped past it.
  planner.Sync(s);
  pb::ControlRequest restore = Request(1);
  *restore.mutable_restore()->mutable_state() = ToExactState(s.simulator(1).state());
  plan = planner.Prepare(std::make_shared<const pb::ControlRequest>(restore));
  ASSERT_TRUE(plan.prepared) << plan.refusal;
  EXPECT_TRUE(planner.waiting());  // nothing more is planned until it is settled
  for (int i = 0; i < 10; ++i) s.Step();
  o = s.Commit(*plan.prepared);
  EXPECT_FALSE(o.accepted);
  EXPECT_THAT(OutcomeReason(o, "test"),
              HasSubstr("restore: vehicle 1 is at step 10 and a vehicle's steps only go forward; "
                        "restore step 0"));
  planner.Settle(std::move(plan.prepared));
  EXPECT_FALSE(planner.waiting());
  EXPECT_TRUE(planner.Knows(1));
  // The session is full when a spawn planned while it was not is applied.
  SessionConfig small = Config();
  small.max_vehicles = 2;
  Session t(world, small, nullptr);
  t.Spawn(1, {0, 0, 0}, 0.0, pb::VehicleParams());
  RequestPlanner p2(world, small);
  p2.Sync(t);
  pb::ControlRequest spawn = Request(2);
  spawn.set_server_id("test");
  spawn.mutable_spawn()->mutable_pose()->set_x(10.0);
  plan = p2.Prepare(std::make_shared<const pb::ControlRequest>(spawn));
  ASSERT_TRUE(plan.prepared) << plan.refusal;
  spawn.set_vehicle_id(3);
  ASSERT_TRUE(t.Apply(spawn).accepted());
  spawn.set_vehicle_id(2);
  o = t.Commit(*plan.prepared);
  EXPECT_THAT(OutcomeReason(o, "test"), HasSubstr("this server runs its maximum of 2 vehicles"));
  EXPECT_FALSE(t.HasVehicle(2));
}

// A session with changing input, a parameter change, a teleport and a second vehicle, recorded
// as events; re-simulated from the events alone it gives every step's hash exactly.
TEST(Session, ResimulationFromEventsReproducesEveryHash) {
  Recorder rec;
  const auto world = testing::SharedWorld("facility");
  Session s(world, Config(), Into(rec, world));
  s.Spawn(1, world->spawn, 0.0, pb::VehicleParams());
  std::string why;
  for (int k = 0; k < 30; ++k) {
    ASSERT_TRUE(s.OfferInput(Input(1, 0.8, 0.002 * k), &why)) << why;
    StepAndRecord(s, rec, 37);
  }
  pb::ControlRequest p = Request(1);
  p.mutable_set_params()->mutable_params()->set_mu(0.7);
  ASSERT_TRUE(s.Apply(p).accepted());
  pb::ControlRequest spawn = Request(2);
  spawn.set_server_id("test");
  spawn.mutable_spawn()->mutable_pose()->set_x(0.0);
  spawn.mutable_spawn()->mutable_pose()->set_y(50.0);
  spawn.mutable_spawn()->set_speed(5.0);
  ASSERT_TRUE(s.Apply(spawn).accepted());
  StepAndRecord(s, rec, 300);  // input stops: the watchdog's safe state is an event too
  pb::ControlRequest tp = Request(1);
  tp.mutable_teleport()->mutable_pose()->set_x(100.0);
  tp.mutable_teleport()->mutable_pose()->set_y(-150.0);
  tp.mutable_teleport()->set_speed(12.0);
  ASSERT_TRUE(s.Apply(tp).accepted());
  ASSERT_TRUE(s.OfferInput(Input(1, 0.3, -0.05), &why));
  StepAndRecord(s, rec, 700);

  std::map<std::uint32_t, std::uint64_t> end;
  for (const auto& [id, h] : rec.hashes) end[id] = h.rbegin()->first + 1;
  const ResimResult res = Resimulate(world, rec.events, end);
  ASSERT_TRUE(res.ok) << res.error;
  for (const auto& [id, hashes] : rec.hashes) {
    ASSERT_EQ(res.hashes.at(id).size(), hashes.size()) << "vehicle " << id;
    for (const auto& [step, hash] : hashes) {
      ASSERT_EQ(res.hashes.at(id).at(step), hash) << "vehicle " << id << " step " << step;
    }
  }
  // It really re-simulated: a changed event changes the hashes.
  std::vector<pb::SessionEvent> edited = rec.events;
  for (auto& e : edited) {
    if (e.has_params_changed()) e.mutable_params_changed()->mutable_params()->set_mass(1501.0);
  }
  const ResimResult other = Resimulate(world, edited, end);
  ASSERT_TRUE(other.ok);
  int differing = 0;
  for (const auto& [step, hash] : rec.hashes.at(1)) differing += other.hashes.at(1).at(step) != hash;
  EXPECT_GT(differing, 100);  // from the parameter change until the teleport re-sets the state
}

// Absurd parameters are refused at the edge, with the mode they cannot resolve: a 1 kg car on
// 1e8 N/m springs (h * omega = 20 at 1 ms) or a 1 g car.
TEST(Session, ParametersTheStepCannotResolveAreRefused) {
  Session s(testing::SharedWorld("flat"), Config(), {});
  pb::VehicleParams stiff;
  stiff.set_mass(1.0);
  stiff.set_ixx(0.1);
  stiff.set_iyy(0.1);
  stiff.set_izz(0.1);
  for (auto* w : {stiff.mutable_lf(), stiff.mutable_rf(), stiff.mutable_lr(), stiff.mutable_rr()}) {
    w->set_spring_stiffness(1e8);
  }
  try {
    s.Spawn(1, {0, 0, 0}, 0.0, stiff);
    ADD_FAILURE() << "a 1 kg car on 1e8 N/m springs was accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_THAT(e.what(), HasSubstr("too long for these parameters"));
  }
  s.Spawn(1, {0, 0, 0}, 0.0, pb::VehicleParams());
  pb::ControlRequest light = Request(1);
  light.mutable_set_params()->mutable_params()->set_mass(0.001);
  const pb::ControlReply r = s.Apply(light);
  EXPECT_FALSE(r.accepted());
  EXPECT_THAT(r.reason(), HasSubstr("needs h <="));
  pb::ControlRequest soft = Request(1);
  soft.mutable_set_params()->mutable_params()->mutable_lf()->set_spring_stiffness(1e-300);
  EXPECT_THAT(s.Apply(soft).reason(), HasSubstr("lf.spring_stiffness: the static load"));
  EXPECT_EQ(s.params(1).mass(), DefaultVehicleParams().mass());
}

// A state that blows up (injected: validated parameters give none) is contained: the step is
// discarded, the vehicle is put back at rest where it was, the session goes on, and the
// re-simulation follows it through.
TEST(Session, ADivergingVehicleIsContainedAndTheSessionGoesOn) {
  Recorder rec;
  const auto world = testing::SharedWorld("flat");
  Session s(world, Config(), Into(rec, world));
  s.Spawn(1, {0, 0, 0}, 0.0, pb::VehicleParams());
  StepAndRecord(s, rec, 100);
  State wild = s.simulator(1).state();
  SetVelocity(wild.x, Eigen::Vector3d(1e300, 0.0, 0.0));  // drag ~ v^2 overflows at once
  s.SetStateForTesting(1, wild);
  StepAndRecord(s, rec, 300);
  EXPECT_GE(s.simulator(1).nonfinite_steps(), 1u);
  EXPECT_TRUE(s.simulator(1).state().x.allFinite());
  EXPECT_LT(Velocity(s.simulator(1).state().x).norm(), 1.0);  // at rest again
  EXPECT_EQ(s.simulator(1).state().step, 400);
  int respawns = 0;
  for (const auto& e : rec.events) respawns += e.has_spawned() && e.step() > 100;
  EXPECT_GE(respawns, 1);
  const ResimResult res = Resimulate(world, rec.events, {{1, 400}});
  ASSERT_TRUE(res.ok) << res.error;
  for (const auto& [step, hash] : rec.hashes.at(1)) EXPECT_EQ(res.hashes.at(1).at(step), hash);
}

// A recorder that joins late starts from a checkpoint, also at a step other than 1 ms; a
// vehicle removed and spawned again under its id goes on counting its steps, and its second
// life is re-simulated too.
TEST(Session, ResimulationFromACheckpointAndAcrossARemoveAndRespawn) {
  Recorder rec;
  const auto world = testing::SharedWorld("flat");
  SessionConfig cfg = Config();
  cfg.step_ns = 2'000'000;
  cfg.checkpoint_every_steps = 100;
  Session s(world, cfg, Into(rec, world, cfg.step_ns));
  s.Spawn(1, {0, 0, 0}, 8.0, pb::VehicleParams());
  std::string why;
  for (int k = 0; k < 6; ++k) {
    ASSERT_TRUE(s.OfferInput(Input(1, 0.4, 0.01 * k), &why)) << why;
    StepAndRecord(s, rec, 40);
  }
  pb::ControlRequest remove = Request(1);
  remove.mutable_remove();
  ASSERT_TRUE(s.Apply(remove).accepted());
  pb::ControlRequest spawn = Request(1);
  spawn.set_server_id("test");
  spawn.mutable_spawn()->mutable_pose()->set_x(30.0);
  spawn.mutable_spawn()->set_speed(4.0);
  ASSERT_TRUE(s.Apply(spawn).accepted());
  EXPECT_EQ(s.simulator(1).state().step, 240);  // the id's steps go on
  ASSERT_TRUE(s.OfferInput(Input(1, 0.7, -0.02), &why));
  StepAndRecord(s, rec, 150);

  // Late joiner: every event from the first checkpoint on.
  std::vector<pb::SessionEvent> late;
  bool from_checkpoint = false;
  for (const auto& e : rec.events) {
    from_checkpoint = from_checkpoint || e.has_checkpoint();
    if (from_checkpoint) late.push_back(e);
  }
  ASSERT_TRUE(late.front().has_checkpoint());
  const ResimResult res = Resimulate(world, late, {{1, 390}});
  ASSERT_TRUE(res.ok) << res.error;
  const auto& got = res.hashes.at(1);
  int compared = 0;
  for (const auto& [step, hash] : rec.hashes.at(1)) {
    if (step < late.front().step()) continue;  // before the checkpoint
    ASSERT_TRUE(got.count(step)) << "step " << step;
    EXPECT_EQ(got.at(step), hash) << "step " << step;
    ++compared;
  }
  EXPECT_EQ(compared, 390 - 100);  // both lives, from the checkpoint at step 100
}

// A server's vehicles start on the world's free ground (issue 31: 256 on facility were refused,
// "the body would start inside 'glass_barrier'"): the first at the spawn, every other one resting
// where its body meets nothing, none nearer another than the grid's 5 m, the same poses every
// time; a world too small for them says how many fit.
TEST(Placement, AsManyVehiclesAsTheServerRunsStartOnFreeGroundOrItSaysHowManyFit) {
  const auto facility = testing::SharedWorld("facility");
  const Params p = ParamsFromProto(DefaultVehicleParams()).get();
  const std::vector<Pose2> poses = StartPoses(*facility, p, 256);
  ASSERT_EQ(poses.size(), 256u);
  EXPECT_EQ(poses[0].x, facility->spawn.x);
  EXPECT_EQ(poses[0].y, facility->spawn.y);
  double nearest = 1e300;
  for (std::size_t i = 0; i < poses.size(); ++i) {
    double misfit = 0;
    const State s = RestingState(p, facility->terrain, poses[i], 0.0, &misfit);
    EXPECT_EQ(SpawnObstruction(p, facility->terrain, s, misfit), "") << "vehicle " << i + 1;
    EXPECT_EQ(poses[i].yaw, facility->spawn.yaw);
    for (std::size_t j = 0; j < i; ++j) {
      nearest = std::min(nearest, std::hypot(poses[i].x - poses[j].x, poses[i].y - poses[j].y));
    }
  }
  EXPECT_NEAR(nearest, 5.0, 1e-9);
  const std::vector<Pose2> again = StartPoses(*facility, p, 256);
  for (std::size_t i = 0; i < poses.size(); ++i) {
    EXPECT_EQ(again[i].x, poses[i].x);
    EXPECT_EQ(again[i].y, poses[i].y);
  }
  // A 12 m square: the spawn and one on each side (5 m apart); a row ahead or behind is 8 m off.
  TriangleMesh square;
  square.name = "square";
  square.AddQuad({-6, -6, 0}, {6, -6, 0}, {6, 6, 0}, {-6, 6, 0});
  const std::shared_ptr<const World> small = WorldFromMesh(std::move(square), {0, 0, 0});
  EXPECT_EQ(StartPoses(*small, p, 3).size(), 3u);
  try {
    (void)StartPoses(*small, p, 5);
    ADD_FAILURE() << "5 vehicles placed on a 12 m square";
  } catch (const WorldError& e) {
    EXPECT_THAT(e.what(), HasSubstr("only 3 of the 5 vehicles fit on the free ground of world "
                                    "'square'"));
  }
  // The first vehicle goes where the world says (or --spawn), or not at all: the reason is the
  // spawn's, not a place found elsewhere.
  TriangleMesh off;
  off.name = "off";
  off.AddQuad({-6, -6, 0}, {6, -6, 0}, {6, 6, 0}, {-6, 6, 0});
  const std::shared_ptr<const World> away = WorldFromMesh(std::move(off), {100, 100, 0});
  EXPECT_THROW((void)StartPoses(*away, p, 1), WorldError);
}

// What the pool's user sees of one job: every item stepped exactly once per job, and Run returns
// only when every part is done (checked right after each of many jobs).
TEST(StepPool, EveryItemOnceAJobAndRunWaitsForEveryPart) {
  for (const int threads : {1, 2, 3, 5}) {
    StepPool pool(threads);
    for (const std::size_t n : {0u, 1u, 2u, 3u, 7u, 256u}) {
      SCOPED_TRACE(std::to_string(threads) + " threads, " + std::to_string(n) + " items");
      std::vector<int> visits(n, 0);
      for (int job = 1; job <= 300; ++job) {
        auto part = [&](std::size_t begin, std::size_t end) {
          for (std::size_t i = begin; i < end; ++i) ++visits[i];
        };
        pool.Run(n, part);
        for (std::size_t i = 0; i < n; ++i) ASSERT_EQ(visits[i], job) << "item " << i;
      }
    }
  }
}

// Who steps what, as seen from the items: each thread one contiguous run of items, a different
// thread for each run; the calling thread the first run (it also runs the session's serial
// phases, so it gets the smallest share, but a real one: at least half a worker's, less one
// item); the workers' shares within one item of each other (a worker that got nothing counts as
// an empty share). One item alone is stepped on the calling thread (no worker is woken for it).
TEST(StepPool, TheWorkIsSharedInContiguousRunsTheCallersTheSmallest) {
  for (const int threads : {1, 2, 3, 5}) {
    StepPool pool(threads);
    for (const std::size_t n : {1u, 2u, 3u, 7u, 10u, 256u, 1001u}) {
      SCOPED_TRACE(std::to_string(threads) + " threads, " + std::to_string(n) + " items");
      std::vector<std::thread::id> by(n);
      auto part = [&](std::size_t begin, std::size_t end) {
        for (std::size_t i = begin; i < end; ++i) by[i] = std::this_thread::get_id();
      };
      pool.Run(n, part);
      // The runs of equal thread ids, in item order.
      std::vector<std::pair<std::thread::id, std::size_t>> runs;
      for (std::size_t i = 0; i < n; ++i) {
        if (runs.empty() || runs.back().first != by[i]) runs.push_back({by[i], 0});
        ++runs.back().second;
      }
      std::set<std::thread::id> threads_seen;
      for (const auto& [id, size] : runs) {
        EXPECT_TRUE(threads_seen.insert(id).second) << "a thread stepped two runs";
      }
      EXPECT_LE(runs.size(), static_cast<std::size_t>(threads));
      const std::thread::id here = std::this_thread::get_id();
      const std::size_t caller = runs.front().first == here ? runs.front().second : 0;
      for (std::size_t r = 1; r < runs.size(); ++r) EXPECT_NE(runs[r].first, here);
      if (n == 1) {
        EXPECT_EQ(caller, 1u);
        continue;
      }
      std::vector<std::size_t> workers;
      for (const auto& [id, size] : runs) {
        if (id != here) workers.push_back(size);
      }
      workers.resize(static_cast<std::size_t>(threads - 1), 0);  // the workers that got nothing
      if (workers.empty()) {
        EXPECT_EQ(caller, n);
        continue;
      }
      const auto [least, most] = std::minmax_element(workers.begin(), workers.end());
      EXPECT_LE(*most - *least, 1u);
      EXPECT_LE(caller, *least);
      if (n >= 10 * static_cast<std::size_t>(threads)) {
        EXPECT_LT(caller, *least);  // the serial phases are the caller's: a smaller share
      }
      EXPECT_GE(2 * caller + 2, *least);
    }
  }
}

// A session's vehicles stepped by the pool, as a server's client sees them: each vehicle's state
// advances by exactly one step per session step and is published once, and every published state
// is the same, bit for bit, with 1, 2 and 4 stepping threads (seven vehicles, each steered its own
// way, cut unevenly among the threads).
TEST(StepPool, EveryVehicleOnceAStepAndTheSameStatesWith1And2And4Threads) {
  const std::shared_ptr<const World> world = testing::SharedWorld("flat");
  constexpr std::uint32_t kVehicles = 7;
  constexpr std::uint64_t kSteps = 400;
  // The states' hashes with one thread, by (vehicle, step).
  std::map<std::pair<std::uint32_t, std::uint64_t>, std::uint64_t> one_thread;
  for (const int threads : {1, 2, 4}) {
    SCOPED_TRACE(std::to_string(threads) + " stepping thread(s)");
    SessionConfig c = Config();
    c.step_threads = threads;
    Session s(world, c, nullptr);
    for (std::uint32_t id = 1; id <= kVehicles; ++id) {
      s.Spawn(id, {0.0, 12.0 * id, 0.0}, 10.0, pb::VehicleParams());
    }
    std::map<std::pair<std::uint32_t, std::uint64_t>, std::uint64_t> seen;
    for (std::uint64_t step = 0; step < kSteps; ++step) {  // the step a state reports
      for (std::uint32_t id = 1; id <= kVehicles; ++id) {
        pb::DriverInput in;
        in.set_vehicle_id(id);
        in.set_source_id("t");
        in.set_steer(0.002 * id * std::sin(0.01 * static_cast<double>(step + 1)));
        in.set_throttle(0.1 * (id % 3));
        std::string why;
        ASSERT_TRUE(s.OfferInput(in, &why)) << why;
      }
      std::map<std::uint32_t, int> published;
      s.Step([&](std::uint32_t id, const pb::VehicleState& st) {
        ++published[id];
        EXPECT_EQ(st.step(), step) << "vehicle " << id;
        seen[{id, st.step()}] = st.state_hash();
      });
      ASSERT_EQ(published.size(), kVehicles) << "step " << step;
      for (const auto& [id, count] : published) ASSERT_EQ(count, 1) << "vehicle " << id;
    }
    for (std::uint32_t id = 1; id <= kVehicles; ++id) {
      EXPECT_EQ(s.simulator(id).state().step, static_cast<std::int64_t>(kSteps));
    }
    if (threads == 1) {
      one_thread = seen;
    } else {
      EXPECT_TRUE(seen == one_thread) << "the states differ from one thread's";
    }
  }
}

TEST(StepPool, AThreadCountOutsideItsRangeIsRefusedWithTheReason) {
  for (const int threads : {0, -1, 17}) {
    try {
      StepPool pool(threads);
      ADD_FAILURE() << threads << " threads accepted";
    } catch (const std::invalid_argument& e) {
      EXPECT_THAT(e.what(), HasSubstr("stepping threads must be in [1, 16]"));
    }
  }
  SessionConfig c = Config();
  c.step_threads = 0;
  EXPECT_THROW(Session(testing::SharedWorld("flat"), c, nullptr), std::invalid_argument);
}

// State frames in memory (the outbox's part): the states of each step, in frame order, as
// "id:bytes" when the step's frames are closed; opened and closed on the caller's thread (else
// counted).
class CollectedFrames final : public StateFrames {
 public:
  CollectedFrames(std::vector<std::string>& states, int& elsewhere)
      : states_(states), elsewhere_(elsewhere) {}
  std::size_t Open(std::size_t n) override {
    elsewhere_ += std::this_thread::get_id() != caller;
    frames_.resize(n);
    return n;
  }
  std::span<std::uint8_t> Buffer(std::size_t i) override { return frames_[i].bytes; }
  void Fill(std::size_t i, std::uint32_t key, std::size_t size, bool too_large) override {
    frames_[i].key = key;
    frames_[i].size = size;
    frames_[i].too_large = too_large;
  }
  void Close(std::size_t n) override {
    elsewhere_ += std::this_thread::get_id() != caller;
    EXPECT_EQ(n, frames_.size());
    for (const Frame& f : frames_) {
      EXPECT_FALSE(f.too_large);
      if (f.size == 0) continue;  // a contained step: no state
      states_.push_back(std::to_string(f.key) + ":" +
                        std::string(f.bytes.begin(), f.bytes.begin() + f.size));
    }
  }
  std::thread::id caller;

 private:
  struct Frame {
    std::uint32_t key = 0;
    std::size_t size = 0;
    bool too_large = false;
    std::array<std::uint8_t, 8192> bytes{};
  };
  std::vector<Frame> frames_;
  std::vector<std::string>& states_;
  int& elsewhere_;
};

// What a session says - its events and every published state, byte for byte and in order - is
// the same stepped by 1 or 3 threads (and encoded on the pool or serialised by the caller), over a
// drive of several vehicles whose input changes every step, with spawns, a removal, a teleport, a
// contained divergence and a respawn in the middle.
TEST(Session, EventsAndStatesAreTheSameByteForByteForOneAndThreeSteppingThreads) {
  const auto world = testing::SharedWorld("facility");
  struct Output {
    std::vector<std::string> events, states;
    std::uint64_t nonfinite = 0;
    int elsewhere = 0;  // events and states handed out on another thread than the caller's
  };
  auto run = [&world](int threads, bool encoded) {
    Output out;
    CollectedFrames frames(out.states, out.elsewhere);
    SessionConfig c = Config();
    c.step_threads = threads;
    const std::uint64_t terrain = TerrainHash(world->terrain);
    const std::thread::id caller = std::this_thread::get_id();
    Session s(world, c, [&out, terrain, caller](SessionEventRecord&& r) {
      out.elsewhere += std::this_thread::get_id() != caller;
      out.events.push_back(ToMessage(r, "test", terrain, 1'000'000).SerializeAsString());
    });
    const auto pose = [&world](double lateral) {
      Pose2 p = world->spawn;
      p.y += lateral;
      return p;
    };
    for (std::uint32_t id = 1; id <= 7; ++id) {
      s.Spawn(id, pose(4.0 * id), 5.0 + id, pb::VehicleParams());
    }
    const auto apply = [&s](pb::ControlRequest r) {
      const pb::ControlReply reply = s.Apply(r);
      EXPECT_TRUE(reply.accepted()) << reply.reason();
    };
    for (int step = 0; step < 2500; ++step) {
      s.ForEachVehicle([&](std::uint32_t id) {
        // Vehicles 1..3 change their input every step, the others now and then.
        const double k = id <= 3 ? step : step / 300;
        std::string why;
        EXPECT_TRUE(s.OfferInput(
            Input(id, 0.3 + 0.05 * std::sin(0.01 * k + id), 0.02 * std::sin(0.003 * k * id)), &why))
            << why;
      });
      if (step == 600) {
        for (std::uint32_t id : {20u, 21u}) {
          pb::ControlRequest spawn = Request(id);
          spawn.set_server_id("test");
          spawn.mutable_spawn()->mutable_pose()->set_x(world->spawn.x + 10.0);
          spawn.mutable_spawn()->mutable_pose()->set_y(world->spawn.y + 3.0 * id);
          apply(spawn);
        }
      }
      if (step == 900) {
        pb::ControlRequest remove = Request(3);
        remove.mutable_remove();
        apply(remove);
        pb::ControlRequest teleport = Request(5);
        teleport.mutable_teleport()->mutable_pose()->set_x(world->spawn.x + 30.0);
        teleport.mutable_teleport()->mutable_pose()->set_y(world->spawn.y + 20.0);
        teleport.mutable_teleport()->set_speed(12.0);
        apply(teleport);
      }
      if (step == 1300) {  // drag ~ v^2 overflows at once: contained in the serial phase
        State wild = s.simulator(6).state();
        SetVelocity(wild.x, Eigen::Vector3d(1e300, 0.0, 0.0));
        s.SetStateForTesting(6, wild);
      }
      if (step == 1700) {
        pb::ControlRequest spawn = Request(3);
        spawn.set_server_id("test");
        spawn.mutable_spawn()->mutable_pose()->set_x(world->spawn.x + 50.0);
        spawn.mutable_spawn()->mutable_pose()->set_y(world->spawn.y + 12.0);
        apply(spawn);
      }
      if (encoded) {  // as the server publishes them: encoded on the pool into frames
        frames.caller = caller;
        s.StepInto(frames);
      } else {
        s.Step([&out, caller](std::uint32_t id, const pb::VehicleState& st) {
          out.elsewhere += std::this_thread::get_id() != caller;
          out.states.push_back(std::to_string(id) + ":" + st.SerializeAsString());
        });
      }
    }
    s.FlushEvents();
    s.ForEachVehicle([&](std::uint32_t id) { out.nonfinite += s.simulator(id).nonfinite_steps(); });
    return out;
  };
  // One thread with the messages serialised here; three with the states encoded on the pool into
  // frames, as the server sends them: the same bytes.
  const Output one = run(1, false), three = run(3, true);
  // The drive did what it says: every kind of event, and the divergence was contained.
  int spawned = 0, removed = 0, checkpoints = 0, batches = 0;
  for (const std::string& bytes : one.events) {
    pb::SessionEvent e;
    ASSERT_TRUE(e.ParseFromString(bytes));
    spawned += e.has_spawned();
    removed += e.has_removed();
    checkpoints += e.has_checkpoint();
    batches += e.has_input_batch();
  }
  // At the start, two spawns, the teleport, the wild state set, its containment, the respawn.
  EXPECT_EQ(spawned, 7 + 2 + 1 + 1 + 1 + 1);
  EXPECT_EQ(removed, 1);
  EXPECT_GT(checkpoints, 30);
  EXPECT_GT(batches, 200);
  EXPECT_GE(one.nonfinite, 1u);
  EXPECT_EQ(one.states.size(), 7u * 600 + 9u * 300 + 8u * 800 + 9u * 800 - 1u);
  ASSERT_EQ(one.events.size(), three.events.size());
  for (std::size_t i = 0; i < one.events.size(); ++i) {
    ASSERT_TRUE(one.events[i] == three.events[i]) << "event " << i << " differs";
  }
  ASSERT_EQ(one.states.size(), three.states.size());
  for (std::size_t i = 0; i < one.states.size(); ++i) {
    // "id:bytes": the vehicle is named when they differ, not the bytes.
    const std::string& a = one.states[i];
    const std::string& b = three.states[i];
    ASSERT_TRUE(a == b) << "state " << i << ": vehicle " << a.substr(0, a.find(':')) << " vs "
                        << b.substr(0, b.find(':'));
  }
  EXPECT_EQ(one.nonfinite, three.nonfinite);
  // Handed out in the serial phase, on the caller's thread (the server's loop), never a worker's.
  EXPECT_EQ(three.elsewhere, 0);
}

// An analog wheel changes the input every step. Ten minutes of it at 1 kHz (one under the
// sanitizers): the events stay under 50 messages a second for the vehicle (the changes travel in
// batches), and the session re-simulates from those events alone, bit for bit, at every step.
TEST(Session, MinutesOfA1kHzVaryingInputCostFewEventsAndResimulateBitExactly) {
  Recorder rec;
  const auto world = testing::SharedWorld("flat");
  Session s(world, Config(), Into(rec, world));
  s.Spawn(1, {0, 0, 0}, 0.0, pb::VehicleParams());
  pb::DriverInput in = Input(1, 0.0);
  in.set_cruise_on(true);
  in.set_cruise_set_kmh(60.0);
  constexpr int kSteps = testing::kSanitized ? 60'000 : 600'000;
  std::string why;
  for (int i = 0; i < kSteps; ++i) {
    // A driver weaving on a wheel: a new steering angle every millisecond, the pedal now and then.
    in.set_steer(0.05 * std::sin(2.0 * M_PI * 0.2 * i * 1e-3) + 1e-4 * (i % 7));
    in.set_throttle(i % 20'000 < 10'000 ? 0.0 : 0.3);
    ASSERT_TRUE(s.OfferInput(in, &why)) << why;
    s.Step([&rec](std::uint32_t id, const pb::VehicleState& st) {
      rec.hashes[id][st.step()] = st.state_hash();
    });
  }
  s.FlushEvents();
  const double minutes = kSteps * 1e-3 / 60.0;
  std::size_t changes = 0;
  for (const auto& e : rec.events) {
    if (e.has_input_batch()) changes += static_cast<std::size_t>(e.input_batch().samples_size());
  }
  const double events_per_s = static_cast<double>(rec.events.size()) / (minutes * 60.0);
  std::printf("  %zu events in %.0f simulated minutes (%.1f per second) carried %zu input changes\n",
              rec.events.size(), minutes, events_per_s, changes);
  EXPECT_LE(events_per_s, 50.0);
  EXPECT_GE(changes, static_cast<std::size_t>(kSteps - 10));  // every step changed the input
  const ResimResult res = Resimulate(world, rec.events, {{1, kSteps}});
  ASSERT_TRUE(res.ok) << res.error;
  const auto& live = rec.hashes.at(1);
  const auto& again = res.hashes.at(1);
  ASSERT_EQ(again.size(), live.size());
  std::size_t mismatches = 0;
  for (const auto& [step, hash] : live) mismatches += again.at(step) != hash;
  EXPECT_EQ(mismatches, 0u);
}

TEST(Session, ResimulationRefusesAnotherTerrainAndGaps) {
  Recorder rec;
  Session s(testing::SharedWorld("flat"), Config(), Into(rec, testing::SharedWorld("flat")));
  s.Spawn(1, {0, 0, 0}, 0.0, pb::VehicleParams());
  StepAndRecord(s, rec, 10);
  const ResimResult wrong = Resimulate(testing::SharedWorld("facility"), rec.events, {{1, 10}});
  EXPECT_FALSE(wrong.ok);
  EXPECT_THAT(wrong.error, HasSubstr("another terrain"));
  std::vector<pb::SessionEvent> gap = rec.events;
  pb::SessionEvent extra = gap.back();
  extra.set_sequence(extra.sequence() + 5);
  gap.push_back(extra);
  EXPECT_THAT(Resimulate(testing::SharedWorld("flat"), gap, {{1, 10}}).error, HasSubstr("gap"));
}

}  // namespace
}  // namespace vdyn

#include "vdyn/runtime/input_arbiter.h"

namespace vdyn {
namespace {

pb::DriverInput From(const std::string& source) {
  pb::DriverInput in;
  in.set_vehicle_id(1);
  in.set_source_id(source);
  return in;
}

// A server's claim (claim.h) reads back as written; what is not a claim is not one; two claims
// clash on the id or a vehicle in common.
TEST(ServerClaim, ReadsBackAndClashesOnTheIdOrAVehicle) {
  const ServerClaim a{"lab a", {1, 2, 4294967295u}, false};
  const std::string text = a.Encode();
  EXPECT_EQ(text, "vdyn-server/1 claiming vehicles=1,2,4294967295 id=lab a");
  const std::optional<ServerClaim> back = ServerClaim::Decode(text);
  ASSERT_TRUE(back.has_value());
  EXPECT_EQ(back->server_id, "lab a");
  EXPECT_EQ(back->vehicle_ids, a.vehicle_ids);
  EXPECT_FALSE(back->running);
  EXPECT_TRUE(ServerClaim::Decode(ServerClaim{"b", {}, true}.Encode())->running);
  for (const char* other :
       {"", "vdyn-server/1 ", "vdyn-server/2 running vehicles=1 id=x",
        "vdyn-server/1 running vehicles=1,x id=y", "vdyn-server/1 running vehicles=4294967296 id=y",
        "vdyn-server/1 waiting vehicles=1 id=y", "some other program"}) {
    EXPECT_FALSE(ServerClaim::Decode(other).has_value()) << other;
  }
  EXPECT_TRUE(a.Clashes({"lab b", {7, 2}, true}));
  EXPECT_TRUE(a.Clashes({"lab a", {7}, true}));
  EXPECT_FALSE(a.Clashes({"lab b", {7, 8}, false}));
  EXPECT_FALSE(a.Clashes({"lab b", {}, false}));
}

// Servers started at the same moment settle their claims alike in every GUID order: no two
// chosen clash, and every vehicle claimed is run by one of them (issue 33: A={1}, B={2},
// C={1,2} left a vehicle unserved in 6 of 12 trials: B gave way to C, which gave way to A).
// Every order of three and of four claims, with and without a running server.
TEST(ServerClaim, ClaimsSettleSoThatEveryVehicleIsRunAndNoneTwice) {
  const std::vector<ServerClaim> sets[] = {
      {{"a", {1}, false}, {"b", {2}, false}, {"c", {1, 2}, false}},
      {{"a", {1}, false}, {"b", {2}, false}, {"c", {1, 2}, false}, {"d", {2, 3}, false}},
      {{"a", {1}, false}, {"a", {2}, false}, {"c", {2, 3}, false}, {"d", {3}, false}},
      {{"a", {1}, true}, {"b", {2}, false}, {"c", {1, 2}, false}, {"d", {2, 4}, false}},
  };
  for (const auto& set : sets) {
    std::vector<std::size_t> order(set.size());
    std::iota(order.begin(), order.end(), 0);
    do {
      std::vector<const ServerClaim*> by_guid;
      for (std::size_t i : order) by_guid.push_back(&set[i]);
      const std::vector<bool> runs = ChooseRunners(by_guid);
      std::set<std::uint32_t> claimed, served;
      std::string trace;
      for (std::size_t i = 0; i < by_guid.size(); ++i) {
        trace += by_guid[i]->server_id + (runs[i] ? "+ " : "- ");
        for (std::uint32_t v : by_guid[i]->vehicle_ids) claimed.insert(v);
        if (!runs[i]) continue;
        for (std::uint32_t v : by_guid[i]->vehicle_ids) {
          EXPECT_TRUE(served.insert(v).second) << "vehicle " << v << " run twice: " << trace;
        }
        for (std::size_t j = 0; j < i; ++j) {
          EXPECT_FALSE(runs[j] && by_guid[i]->Clashes(*by_guid[j])) << trace;
        }
      }
      // A running server always runs; every claim that gives way clashes with one that runs.
      for (std::size_t i = 0; i < by_guid.size(); ++i) {
        if (by_guid[i]->running) {
          EXPECT_TRUE(runs[i]) << trace;
        }
        if (runs[i]) continue;
        bool beaten = false;
        for (std::size_t j = 0; j < by_guid.size(); ++j) {
          beaten = beaten || (runs[j] && by_guid[i]->Clashes(*by_guid[j]));
        }
        EXPECT_TRUE(beaten) << by_guid[i]->server_id << " gave way to no runner: " << trace;
      }
      // The case: vehicles 1 and 2 are both run, whatever the order.
      if (set.size() == 3) {
        EXPECT_EQ(served, claimed) << trace;
      }
    } while (std::next_permutation(order.begin(), order.end()));
  }
}

// The strongest live valid source drives; refused input never counts as live.
TEST(InputArbiter, TheStrongestLiveValidSourceDrives) {
  InputArbiter a(base::Milliseconds(200));
  base::MonoTime t{1'000'000'000};
  const std::uint64_t primary = 11, backup = 12, wild = 13;
  EXPECT_TRUE(a.Offer(From("backup"), backup, 5, t));      // alone: it drives
  EXPECT_TRUE(a.Offer(From("primary"), primary, 20, t));   // stronger: takes over at once
  EXPECT_FALSE(a.Offer(From("backup"), backup, 5, t));
  // The primary's samples are refused from now on; within the lease it still owns the vehicle.
  for (int ms = 10; ms <= 200; ms += 10) {
    a.Refuse(primary, 1, "primary", "non-finite value on vdyn/input: steer",
             t + base::Milliseconds(ms));
    EXPECT_FALSE(a.Offer(From("backup"), backup, 5, t + base::Milliseconds(ms))) << ms << " ms";
  }
  // Past the lease without a valid sample: the backup drives.
  EXPECT_TRUE(a.Offer(From("backup"), backup, 5, t + base::Milliseconds(201)));
  // A stronger source whose every sample is refused never drives.
  for (int ms = 210; ms < 600; ms += 10) {
    a.Refuse(wild, 1, "rig30", "out of range: throttle must be in [-1, 1], got 5",
             t + base::Milliseconds(ms));
    EXPECT_TRUE(a.Offer(From("backup"), backup, 5, t + base::Milliseconds(ms)));
  }
  const auto snapshot = a.Snapshot(t + base::Milliseconds(600));
  int checked = 0;
  for (const auto& s : snapshot) {
    if (s.handle == primary) {
      EXPECT_EQ(s.last_refusal, "non-finite value on vdyn/input: steer");
      EXPECT_FALSE(s.driving);
      ++checked;
    }
    if (s.handle == wild) {
      EXPECT_EQ(s.source_id, "rig30");
      EXPECT_EQ(s.accepted, 0u);
      EXPECT_GT(s.refused, 30u);
      ++checked;
    }
    if (s.handle == backup) {
      EXPECT_TRUE(s.driving);
      ++checked;
    }
  }
  EXPECT_EQ(checked, 3);
  // When the primary sends valid input again it takes the vehicle back.
  EXPECT_TRUE(a.Offer(From("primary"), primary, 20, t + base::Milliseconds(700)));
  // A writer that is gone is forgotten.
  a.Forget({primary});
  EXPECT_FALSE(a.Knows(backup));
  EXPECT_TRUE(a.Knows(primary));
}

// The lease is DDS's liveliness lease (200 ms) unless the watchdog would brake first: then three
// quarters of the watchdog, so a live backup drives before the safe state.
TEST(InputArbiter, TheLeaseEndsBeforeTheWatchdogBrakes) {
  EXPECT_EQ(OwnershipLease(base::Milliseconds(100)).ns, base::Milliseconds(75).ns);
  EXPECT_EQ(OwnershipLease(base::Milliseconds(200)).ns, base::Milliseconds(150).ns);
  EXPECT_EQ(OwnershipLease(base::Milliseconds(1000)).ns, base::Milliseconds(200).ns);
  EXPECT_EQ(OwnershipLease(base::Milliseconds(20)).ns, base::Milliseconds(15).ns);
  EXPECT_EQ(OwnershipLease(base::Milliseconds(4)).ns, base::Milliseconds(10).ns);  // the floor
  // With the default watchdog: the primary's last sample at t = 0, the backup sending every ms;
  // at 75 ms the backup drives, 25 ms before the watchdog.
  InputArbiter a(OwnershipLease(base::Milliseconds(100)));
  pb::DriverInput in;
  in.set_vehicle_id(1);
  in.set_source_id("primary");
  const base::MonoTime t0{1'000'000'000};
  ASSERT_TRUE(a.Offer(in, 1, 20, t0));
  in.set_source_id("backup");
  std::int64_t took_over_ms = -1;
  for (int ms = 1; ms <= 100 && took_over_ms < 0; ++ms) {
    if (a.Offer(in, 2, 5, t0 + base::Milliseconds(ms))) took_over_ms = ms;
  }
  EXPECT_EQ(took_over_ms, 76);  // the first sample after the lease of 75 ms
}

TEST(InputArbiter, EqualStrengthsKeepTheCurrentOwner) {
  InputArbiter a(base::Milliseconds(200));
  const base::MonoTime t{5'000'000'000};
  EXPECT_TRUE(a.Offer(From("a"), 2, 10, t));
  EXPECT_FALSE(a.Offer(From("b"), 1, 10, t));  // no flapping between equals
  EXPECT_TRUE(a.Offer(From("a"), 2, 10, t + base::Milliseconds(1)));
}

}  // namespace
}  // namespace vdyn
