// Determinism as a stored hash (Box2D's habit): fixed reference drives must end on the state hash
// stored here. A compiler, flag or library change that moves one bit of one step fails this test.
// docs/hash.md says when the stored values may legitimately change.
#include <gtest/gtest.h>

#include "test_support.h"
#include "vdyn/bridge/convert.h"
#include "vdyn/io/maneuver.h"
#include "vdyn/runtime/batch.h"

namespace vdyn {
namespace {

std::uint64_t DemoDriveHash(const ValidParams& params) {
  const std::shared_ptr<const World> world = testing::SharedWorld("facility");
  Simulator sim(world, params);
  sim.Spawn(world->spawn);
  const Maneuver m = Maneuver::Named("demo");
  BatchOptions o;
  o.duration = m.end_time();
  const BatchSummary s = RunBatch(sim, m, o, nullptr);
  EXPECT_TRUE(s.ok) << s.error;
  EXPECT_EQ(s.steps, 40'000);
  return s.final_hash;
}

// The paper's model with the default parameters: the hash it has had since it was the only model.
TEST(Golden, PaperModelDemoDriveOnFacilityEndsOnTheStoredHash) {
  const ValidParams p = testing::ParamsWith([](pb::VehicleParams& m) {
    m.set_model(pb::VEHICLE_MODEL_PAPER);
  });
  EXPECT_EQ(DemoDriveHash(p), 0xf00662dacbdc2b22ull);
}

// The full model (the default) over the same drive.
TEST(Golden, FullModelDemoDriveOnFacilityEndsOnTheStoredHash) {
  EXPECT_EQ(DemoDriveHash(testing::DefaultParams()), 0xfa23a84c6e39e665ull);
}

TEST(Golden, PaperYawModeWithTheLinearTireEndsOnTheStoredHash) {
  const ValidParams p = testing::ParamsWith([](pb::VehicleParams& m) {
    m.set_model(pb::VEHICLE_MODEL_PAPER);
    m.set_yaw_mode(pb::YAW_MODE_PAPER);
    m.set_tire_law(pb::TIRE_LAW_LINEAR_SATURATED);
  });
  EXPECT_EQ(DemoDriveHash(p), 0xd4fa87fce29c14ddull);
}

}  // namespace
}  // namespace vdyn
