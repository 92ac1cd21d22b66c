// The Restore request (vdyn-recorder takeover): a vehicle brought back to a recorded moment
// continues bit for bit - its state hash after every step equals the recording's - when it gets
// the recorded inputs; the events it emits re-simulate; its steps never go back.
#include <cmath>
#include <map>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "vdyn/bridge/convert.h"
#include "vdyn/replay/resim.h"
#include "vdyn/runtime/session.h"
#include "test_support.h"

namespace vdyn {
namespace {

using ::testing::HasSubstr;

SessionConfig Config() {
  SessionConfig c;
  c.server_id = "test";
  c.default_params = DefaultVehicleParams();
  c.checkpoint_every_steps = 500;
  return c;
}

// A driver who keeps changing everything: steering, throttle and brake as functions of the step.
pb::DriverInput InputAt(std::uint32_t vehicle, std::int64_t step) {
  const double t = static_cast<double>(step) * 1e-3;
  pb::DriverInput in;
  in.set_vehicle_id(vehicle);
  in.set_source_id("rig");
  in.set_steer(0.2 * std::sin(1.3 * t));
  in.set_throttle(t < 2.0 ? 0.6 : 0.3 + 0.2 * std::sin(0.7 * t));
  in.set_brake(std::fmod(t, 1.5) > 1.2 ? 0.2 : 0.0);
  return in;
}

struct Drive {
  std::vector<pb::SessionEvent> events;
  std::map<std::uint64_t, std::uint64_t> hashes;  // step -> state hash after it
};

Session::EventSink Into(Drive& run, const World& world) {
  const std::uint64_t terrain = TerrainHash(world.terrain);
  return [&run, terrain](SessionEventRecord&& r) {
    run.events.push_back(ToMessage(r, "test", terrain, 1'000'000));
  };
}

// Steps `s` with the driver's input for each of the vehicle's steps until step `end`.
void DriveTo(Session& s, Drive& run, std::uint32_t vehicle, std::int64_t end) {
  while (s.simulator(vehicle).state().step < end) {
    std::string why;
    ASSERT_TRUE(s.OfferInput(InputAt(vehicle, s.simulator(vehicle).state().step), &why)) << why;
    s.Step([&](std::uint32_t id, const pb::VehicleState& st) {
      if (id == vehicle) run.hashes[st.step()] = st.state_hash();
    });
  }
}

// The checkpoint of `vehicle` at `step` as a Restore request.
pb::ControlRequest RestoreFrom(const Drive& run, std::uint32_t vehicle, std::uint64_t step) {
  for (const pb::SessionEvent& e : run.events) {
    if (e.vehicle_id() != vehicle || !e.has_checkpoint() || e.step() != step) continue;
    pb::ControlRequest r;
    r.set_request_id(9);
    r.set_client_id("takeover");
    r.set_server_id("test");
    r.set_vehicle_id(vehicle);
    auto* rs = r.mutable_restore();
    *rs->mutable_state() = e.checkpoint().state();
    *rs->mutable_params() = e.checkpoint().params();
    *rs->mutable_input() = e.checkpoint().input();
    rs->set_branched_from("a.mcap@1.5s");
    return r;
  }
  ADD_FAILURE() << "no checkpoint at step " << step;
  return {};
}

class RestoreRequest : public ::testing::Test {
 protected:
  void SetUp() override {
    world_ = testing::SharedWorld("facility");
    Session a(world_, Config(), Into(original_, *world_));
    a.Spawn(1, world_->spawn, 0.0, pb::VehicleParams());
    DriveTo(a, original_, 1, 3000);
  }
  std::shared_ptr<const World> world_;
  Drive original_;
};

TEST_F(RestoreRequest, AFreshServerContinuesBitExactlyFromTheBranchPoint) {
  Drive branch;
  Session b(world_, Config(), Into(branch, *world_));
  const pb::ControlReply reply = b.Apply(RestoreFrom(original_, 1, 1500));
  ASSERT_TRUE(reply.accepted()) << reply.reason();
  EXPECT_EQ(reply.applied_step(), 1500u);
  DriveTo(b, branch, 1, 3000);
  ASSERT_EQ(branch.hashes.size(), 1500u);
  EXPECT_EQ(branch.hashes.begin()->first, 1500u);
  for (const auto& [step, hash] : branch.hashes) {
    ASSERT_EQ(hash, original_.hashes.at(step)) << "step " << step;
  }
  // The events say where it came from and carry the exact state.
  const auto spawned = std::find_if(branch.events.begin(), branch.events.end(),
                                    [](const auto& e) { return e.has_spawned(); });
  ASSERT_NE(spawned, branch.events.end());
  EXPECT_EQ(spawned->step(), 1500u);
  EXPECT_EQ(spawned->spawned().branched_from(), "a.mcap@1.5s");
}

TEST_F(RestoreRequest, ADifferentInputAfterTheBranchPointDiverges) {
  // The comparison above can fail: one changed input sample changes every hash after it.
  Drive branch;
  Session b(world_, Config(), Into(branch, *world_));
  ASSERT_TRUE(b.Apply(RestoreFrom(original_, 1, 1500)).accepted());
  pb::DriverInput other = InputAt(1, 1500);
  other.set_throttle(other.throttle() + 1e-9);
  ASSERT_TRUE(b.OfferInput(other, nullptr));
  b.Step([&](std::uint32_t, const pb::VehicleState& st) { branch.hashes[st.step()] = st.state_hash(); });
  DriveTo(b, branch, 1, 1600);
  for (const auto& [step, hash] : branch.hashes) EXPECT_NE(hash, original_.hashes.at(step));
}

TEST_F(RestoreRequest, TheRestoredInputDrivesUntilALiveOneArrivesThenTheWatchdogCounts) {
  Session b(world_, Config(), {});
  ASSERT_TRUE(b.Apply(RestoreFrom(original_, 1, 1500)).accepted());
  const pb::ControlRequest request = RestoreFrom(original_, 1, 1500);
  const pb::InputSample& recorded = request.restore().input();
  b.Step();
  EXPECT_FALSE(b.in_safe_state(1));
  EXPECT_EQ(b.simulator(1).input().steer, recorded.steer());
  EXPECT_EQ(b.simulator(1).input().throttle, recorded.throttle());
  for (int i = 0; i < 100; ++i) b.Step();
  EXPECT_FALSE(b.in_safe_state(1));  // 100 ms after the restore: still the restored input
  b.Step();
  EXPECT_TRUE(b.in_safe_state(1));  // nobody took over within the watchdog time
}

TEST_F(RestoreRequest, AnExistingVehicleMovesForwardAndTheBranchedSessionResimulates) {
  Drive branch;
  Session b(world_, Config(), Into(branch, *world_));
  b.Spawn(1, world_->spawn, 0.0, pb::VehicleParams());
  DriveTo(b, branch, 1, 100);
  ASSERT_TRUE(b.Apply(RestoreFrom(original_, 1, 1500)).accepted());
  DriveTo(b, branch, 1, 2500);
  // The old life ended with a Removed event, the new one starts with a Spawned event.
  bool removed = false;
  for (const auto& e : branch.events) removed = removed || (e.has_removed() && e.step() == 100);
  EXPECT_TRUE(removed);
  const ResimResult res = Resimulate(world_, branch.events, {{1, 2500}});
  ASSERT_TRUE(res.ok) << res.error;
  std::size_t compared = 0;
  for (const auto& [step, hash] : res.hashes.at(1)) {
    ASSERT_EQ(hash, branch.hashes.at(step)) << "step " << step;
    if (step >= 1500) {
      ASSERT_EQ(hash, original_.hashes.at(step));
      ++compared;
    }
  }
  EXPECT_EQ(compared, 1000u);
}

TEST_F(RestoreRequest, StepsNeverGoBackAndBadRequestsAreRefused) {
  Session b(world_, Config(), {});
  b.Spawn(1, world_->spawn, 0.0, pb::VehicleParams());
  for (int i = 0; i < 1600; ++i) b.Step();
  pb::ControlReply r = b.Apply(RestoreFrom(original_, 1, 1500));
  EXPECT_FALSE(r.accepted());
  EXPECT_THAT(r.reason(), HasSubstr("only go forward"));
  EXPECT_EQ(b.simulator(1).state().step, 1600);  // untouched

  pb::ControlRequest other = RestoreFrom(original_, 1, 1500);
  other.set_vehicle_id(2);
  other.clear_server_id();
  r = b.Apply(other);
  EXPECT_FALSE(r.accepted());
  EXPECT_THAT(r.reason(), HasSubstr("needs server_id"));
  EXPECT_FALSE(b.HasVehicle(2));

  pb::ControlRequest short_state = RestoreFrom(original_, 1, 1500);
  short_state.set_vehicle_id(2);
  short_state.mutable_restore()->mutable_state()->mutable_x()->RemoveLast();
  r = b.Apply(short_state);
  EXPECT_FALSE(r.accepted());
  EXPECT_THAT(r.reason(), HasSubstr("or 37 (the full model), got 36"));

  pb::ControlRequest bad_params = RestoreFrom(original_, 1, 1500);
  bad_params.set_vehicle_id(2);
  bad_params.mutable_restore()->mutable_params()->set_mass(-1.0);
  r = b.Apply(bad_params);
  EXPECT_FALSE(r.accepted());
  EXPECT_THAT(r.reason(), HasSubstr("mass"));

  pb::ControlRequest playback;
  playback.set_vehicle_id(1);
  playback.mutable_playback()->set_loop(true);
  r = b.Apply(playback);
  EXPECT_FALSE(r.accepted());
  EXPECT_THAT(r.reason(), HasSubstr("for a player"));
}

}  // namespace
}  // namespace vdyn
