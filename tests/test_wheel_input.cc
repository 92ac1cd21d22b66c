// vdyn-input's rig logic in-process (issue: drive it with a wheel, pedals and keyboard through
// SDL2): every wheel of the table as an SDL virtual joystick (headless), mapping, inversion,
// combined pedals, calibration from a scripted session, keyboard driving from synthetic SDL key
// events under SDL's dummy video driver, the force-feedback pipeline on a recording device,
// hot-unplug, and axes that are not numbers or out of range. Times are given to the loop, never
// slept: every ramp and fade is checked against its closed form.
#include <SDL2/SDL.h>

#include <atomic>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <numbers>
#include <set>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "test_support.h"
#include "vdyn/base/limits.h"
#include "vdyn/client/driver_input.h"
#include "vdyn/io/maneuver.h"
#include "vdyn/io/vehicle_params.h"
#include "vdyn/wheel_input/calibrate.h"
#include "vdyn/wheel_input/commands.h"
#include "vdyn/wheel_input/controls.h"
#include "vdyn/wheel_input/devices.h"
#include "vdyn/wheel_input/ffb.h"
#include "vdyn/wheel_input/keyboard.h"
#include "vdyn/wheel_input/mapping.h"
#include "vdyn/wheel_input/rig.h"
#include "vdyn/wheel_input/wheel_reader.h"
#include "vdyn/wheel_input/window.h"

namespace vdyn::wheel_input {
namespace {

using base::Milliseconds;
using base::MonoTime;
using base::Nanos;
using ::testing::HasSubstr;

constexpr double kPi = std::numbers::pi;
constexpr double kDeg = kPi / 180.0;

// --- fakes of the domain ---------------------------------------------------------------------

class RecordingSink : public InputSink {
 public:
  bool Publish(pb::DriverInput& msg, MonoTime) override {
    last = msg;
    ++count;
    return true;
  }
  std::string last_error() const override { return {}; }
  pb::DriverInput last;
  int count = 0;
};

class FakeFeed : public VehicleFeed {
 public:
  FakeFeed() : vehicle(DefaultVehicleParams()) {}
  void Poll() override {}
  const pb::VehicleState* state() const override { return has_state ? &st : nullptr; }
  MonoTime state_received() const override { return received; }
  std::int64_t state_source_wall_ns() const override { return 0; }
  const pb::VehicleParams* params() const override { return &vehicle; }
  void SetSpeedKmh(double v) {
    has_state = true;
    st.mutable_v_wt_b()->set_x(v / 3.6);
  }
  pb::VehicleParams vehicle;
  pb::VehicleState st;
  bool has_state = false;
  MonoTime received{};
};

// A rig config for a wheel, no window.
RigConfig WheelRigConfig() {
  RigConfig cfg;
  cfg.source = RigConfig::Source::kWheel;
  cfg.window = false;
  return cfg;
}

// n ticks of 1 ms, a state of the server (step `first` on) arriving with each.
void TickWithStates(RigLoop& rig, FakeFeed& feed, MonoTime& t, int n, int first = 0) {
  feed.has_state = true;
  for (int i = 0; i < n; ++i) {
    t = t + Milliseconds(1);
    feed.received = t;
    feed.st.set_step(static_cast<std::uint64_t>(first + i));
    ASSERT_TRUE(rig.Tick(t));
  }
}

// Each test gets its own SDL (and no user mapping files but its own).
class SdlTest : public ::testing::Test {
 protected:
  void SetUp() override {
    setenv("VDYN_CONFIG_DIR", dir_.path().c_str(), 1);
    setenv("SDL_VIDEODRIVER", "dummy", 1);
  }
  void TearDown() override { unsetenv("VDYN_CONFIG_DIR"); }
  testing::TempDir dir_;
};

int AxesNeeded(const pb::WheelMapping& m) {
  int n = m.steer().axis() + 1;
  for (const pb::PedalAxis* p : {&m.throttle(), &m.brake(), &m.clutch(), &m.handbrake()}) {
    if (p->has_axis()) n = std::max(n, p->axis() + 1);
  }
  if (m.has_combined() && m.combined().has_axis()) n = std::max(n, m.combined().axis() + 1);
  return n;
}

int ButtonsNeeded(const pb::WheelMapping& m) {
  int n = 1;
  const auto& b = m.buttons();
  for (int v : {b.paddle_left(), b.paddle_right(), b.cruise_toggle(), b.cruise_up(),
                b.cruise_down(), b.reset(), b.camera(), b.estop(), b.horn()}) {
    n = std::max(n, v + 1);
  }
  return n;
}

// An SDL virtual joystick with a wheel's ids, as SDL would present the real device.
class VirtualWheel {
 public:
  VirtualWheel(std::uint16_t vid, std::uint16_t pid, int axes, int buttons,
               const char* name = "virtual wheel") {
    SDL_VirtualJoystickDesc d{};
    d.version = SDL_VIRTUAL_JOYSTICK_DESC_VERSION;
    d.type = SDL_JOYSTICK_TYPE_WHEEL;
    d.naxes = static_cast<Uint16>(axes);
    d.nbuttons = static_cast<Uint16>(buttons);
    d.vendor_id = vid;
    d.product_id = pid;
    d.name = name;
    index_ = SDL_JoystickAttachVirtualEx(&d);
    EXPECT_GE(index_, 0) << SDL_GetError();
    js_ = SDL_JoystickOpen(index_);
    EXPECT_NE(js_, nullptr) << SDL_GetError();
    id_ = SDL_JoystickInstanceID(js_);
  }
  ~VirtualWheel() { Detach(); }
  void Axis(int a, int raw) {
    EXPECT_EQ(SDL_JoystickSetVirtualAxis(js_, a, static_cast<Sint16>(raw)), 0);
  }
  void Button(int b, bool down) {
    EXPECT_EQ(SDL_JoystickSetVirtualButton(js_, b, down ? 1 : 0), 0);
  }
  void Detach() {
    if (js_ == nullptr) return;
    // The device index of a virtual joystick is its position now.
    for (int i = 0; i < SDL_NumJoysticks(); ++i) {
      if (SDL_JoystickGetDeviceInstanceID(i) == id_) SDL_JoystickDetachVirtual(i);
    }
    SDL_JoystickClose(js_);
    js_ = nullptr;
  }
  SDL_Joystick* joystick() const { return js_; }

 private:
  int index_ = -1;
  SDL_Joystick* js_ = nullptr;
  SDL_JoystickID id_ = -1;
};

// A G29 as SDL would present it, its pedals released.
std::unique_ptr<VirtualWheel> ReleasedG29() {
  auto w = std::make_unique<VirtualWheel>(0x046d, 0xc24f, 4, 25);
  for (int a = 1; a < 4; ++a) w->Axis(a, 32767);  // the G29's pedals rest at the top
  return w;
}

DeviceInfo Find(const std::vector<DeviceInfo>& devices, std::uint16_t vid, std::uint16_t pid) {
  for (const auto& d : devices) {
    if (d.vendor_id == vid && d.product_id == pid) return d;
  }
  ADD_FAILURE() << "no device " << VidPid(vid, pid);
  return {};
}

// --- the table -------------------------------------------------------------------------------

TEST(WheelTable, EveryEntryIsValidAndEveryIdBelongsToOneWheel) {
  std::set<std::pair<std::uint32_t, std::uint32_t>> ids;
  ASSERT_GE(BuiltinWheels().size(), 20u);
  for (const auto& m : BuiltinWheels()) {
    EXPECT_THAT(ValidateMapping(m), ::testing::IsEmpty()) << m.name();
    EXPECT_FALSE(m.source().empty()) << m.name();
    for (auto pid : m.product_ids()) {
      EXPECT_TRUE(ids.insert({m.vendor_id(), pid}).second) << m.name() << " " << pid;
      EXPECT_EQ(FindBuiltinWheel(static_cast<std::uint16_t>(m.vendor_id()),
                                 static_cast<std::uint16_t>(pid)),
                &m);
    }
  }
  // The models the issue names are all there (a model that enumerates under a second id too).
  for (const char* name :
       {"G25", "G27", "G29", "G920", "G923", "T150", "TMX", "T300", "T248", "T-GT", "CSL DD",
        "ClubSport", "Moza R5", "Moza R9", "Moza R12", "Simucube 2", "Ferrari 458"}) {
    bool found = false;
    for (const auto& m : BuiltinWheels()) found = found || m.name().find(name) != std::string::npos;
    EXPECT_TRUE(found) << name;
  }
  EXPECT_EQ(FindBuiltinWheel(0x046d, 0xc24f)->name(), "Logitech G29");
  EXPECT_EQ(FindBuiltinWheel(0x1234, 0x5678), nullptr);
}

// Every wheel of the table, as SDL presents it: recognised by its ids, the steering axis at the
// locks gives +-half the rotation range (positive left), each pedal reads 0 released and 1 fully
// pressed whichever end it rests at, the paddles set their bits.
TEST_F(SdlTest, EveryTableWheelAsAVirtualJoystick) {
  SdlContext sdl(false);
  for (const auto& model : BuiltinWheels()) {
    SCOPED_TRACE(model.name());
    const auto vid = static_cast<std::uint16_t>(model.vendor_id());
    const auto pid = static_cast<std::uint16_t>(model.product_ids(0));
    // A base without pedal inputs (Simucube) is used with a pedal set; here its steering alone.
    const bool pedals = model.throttle().has_axis();
    const int axes = std::max(AxesNeeded(model), 3);
    VirtualWheel w(vid, pid, axes, ButtonsNeeded(model));
    const auto devices = ScanDevices();
    const DeviceInfo d = Find(devices, vid, pid);
    EXPECT_EQ(d.kind, DeviceInfo::Kind::kTable);
    EXPECT_THAT(d.recognised_as, HasSubstr(model.name()));
    EXPECT_EQ(d.type, "wheel");
    if (!pedals) {
      EXPECT_THROW(FitToDevice(d.mapping, axes, ButtonsNeeded(model), 0, nullptr), MappingError);
      continue;
    }
    std::string why;
    auto dev = WheelDevice::Open(d, devices, nullptr, &why);
    ASSERT_NE(dev, nullptr) << why;
    WheelReader reader(dev->mapping());
    RawFrame f;
    // Everything at rest: the wheel centred, pedals released.
    const auto& m = model;
    auto rest = [&] {
      w.Axis(m.steer().axis(), 0);
      for (const pb::PedalAxis* p : {&m.throttle(), &m.brake(), &m.clutch()}) {
        if (p->has_axis()) w.Axis(p->axis(), p->rest());
      }
    };
    rest();
    SDL_JoystickUpdate();
    dev->Read(f);
    WheelControls c = reader.Read(f);
    const double half = 0.5 * m.steer().range_deg() * kDeg;
    EXPECT_NEAR(c.hand_angle_rad, 0.0, half * 2.0 / 65535.0);
    EXPECT_EQ(c.throttle, 0.0);
    EXPECT_EQ(c.brake, 0.0);
    // Full left lock: SDL's lowest value on the steering axis (X runs left to right).
    w.Axis(m.steer().axis(), -32768);
    // Full throttle.
    w.Axis(m.throttle().axis(), m.throttle().full());
    SDL_JoystickUpdate();
    dev->Read(f);
    c = reader.Read(f);
    EXPECT_NEAR(c.hand_angle_rad, half, 1e-9);
    EXPECT_DOUBLE_EQ(c.throttle, 1.0);
    EXPECT_EQ(c.brake, 0.0);
    // Full right lock, full brake, throttle released.
    w.Axis(m.steer().axis(), 32767);
    w.Axis(m.throttle().axis(), m.throttle().rest());
    w.Axis(m.brake().axis(), m.brake().full());
    SDL_JoystickUpdate();
    dev->Read(f);
    c = reader.Read(f);
    EXPECT_NEAR(c.hand_angle_rad, -half, 1e-9);
    EXPECT_EQ(c.throttle, 0.0);
    EXPECT_DOUBLE_EQ(c.brake, 1.0);
    // Half brake: the dead zone is rescaled away, (0.5 - dz) / (1 - dz).
    const int mid = (m.brake().rest() + m.brake().full()) / 2;
    w.Axis(m.brake().axis(), mid);
    SDL_JoystickUpdate();
    dev->Read(f);
    c = reader.Read(f);
    const double t =
        (mid - m.brake().rest()) / static_cast<double>(m.brake().full() - m.brake().rest());
    const double dz = m.brake().dead_zone();
    EXPECT_NEAR(c.brake, (t - dz) / (1 - dz), 1e-12);
    if (m.clutch().has_axis()) {
      w.Axis(m.clutch().axis(), m.clutch().full());
      SDL_JoystickUpdate();
      dev->Read(f);
      EXPECT_DOUBLE_EQ(reader.Read(f).clutch, 1.0);
    }
    if (m.buttons().has_paddle_left()) {
      w.Button(m.buttons().paddle_left(), true);
      SDL_JoystickUpdate();
      dev->Read(f);
      EXPECT_EQ(reader.Read(f).buttons, static_cast<std::uint32_t>(pb::BUTTON_PADDLE_LEFT));
      w.Button(m.buttons().paddle_left(), false);
      w.Button(m.buttons().paddle_right(), true);
      SDL_JoystickUpdate();
      dev->Read(f);
      EXPECT_EQ(reader.Read(f).buttons, static_cast<std::uint32_t>(pb::BUTTON_PADDLE_RIGHT));
    }
    EXPECT_EQ(reader.nonfinite(), 0u);
    EXPECT_EQ(reader.out_of_range(), 0u);
  }
}

// Logitech pedals rest at full scale (NOTES.md; SDL reads +32767 released): the table says so for
// the G29, whose throttle, brake and clutch are ABS_Z, ABS_RZ and ABS_Y (SDL axes 2, 3, 1).
TEST_F(SdlTest, LogitechPedalsAreInverted) {
  SdlContext sdl(false);
  VirtualWheel w(0x046d, 0xc24f, 4, 25);
  const auto devices = ScanDevices();
  std::string why;
  auto dev = WheelDevice::Open(Find(devices, 0x046d, 0xc24f), devices, nullptr, &why);
  ASSERT_NE(dev, nullptr) << why;
  WheelReader reader(dev->mapping());
  RawFrame f;
  for (int a = 1; a < 4; ++a) w.Axis(a, 32767);  // all released
  SDL_JoystickUpdate();
  dev->Read(f);
  WheelControls c = reader.Read(f);
  EXPECT_EQ(c.throttle, 0.0);
  EXPECT_EQ(c.brake, 0.0);
  EXPECT_EQ(c.clutch, 0.0);
  w.Axis(2, -32768);  // throttle to the floor
  w.Axis(1, -32768);  // clutch down
  SDL_JoystickUpdate();
  dev->Read(f);
  c = reader.Read(f);
  EXPECT_EQ(c.throttle, 1.0);
  EXPECT_EQ(c.clutch, 1.0);
  EXPECT_EQ(c.brake, 0.0);
}

// --- steering for each model --------------------------------------------------------------------

TEST(Steering, PaperModelGetsTheRoadWheelAngleFullModelTheHandWheel) {
  VehicleInfo v;
  v.steering_ratio = 15;
  v.steering_lock = 0.6;
  // 90 degrees at the hand wheel: 6 degrees at the road wheels.
  SteerCommand s = ToSteer(90 * kDeg, v);
  EXPECT_EQ(s.mode, pb::STEER_ROAD_WHEEL);
  EXPECT_NEAR(s.steer, 6 * kDeg, 1e-15);
  // 450 degrees would be 30 degrees = 0.524 rad, below the lock; 540 degrees is past it.
  EXPECT_NEAR(ToSteer(-450 * kDeg, v).steer, -30 * kDeg, 1e-15);
  EXPECT_EQ(ToSteer(540 * kDeg, v).steer, 0.6);
  // The full model's steering column takes the hand-wheel angle itself.
  pb::VehicleParams p;
  p.set_model(pb::VEHICLE_MODEL_FULL);
  ApplyParams(p, v);
  s = ToSteer(540 * kDeg, v);
  EXPECT_EQ(s.mode, pb::STEER_HAND_WHEEL);
  EXPECT_NEAR(s.steer, 540 * kDeg, 1e-15);
  // The keyboard has no hand wheel: it sends the road-wheel angle to the full model too.
  s = ToSteer(135 * kDeg, v, /*road_wheel_only=*/true);
  EXPECT_EQ(s.mode, pb::STEER_ROAD_WHEEL);
  EXPECT_NEAR(s.steer, 135 * kDeg / 15, 1e-15);
  // A message with an unspecified model is the paper's (today's servers).
  pb::VehicleParams q;
  q.set_steering_ratio(12);
  ApplyParams(q, v);
  EXPECT_EQ(ToSteer(120 * kDeg, v).mode, pb::STEER_ROAD_WHEEL);
  EXPECT_NEAR(ToSteer(120 * kDeg, v).steer, 10 * kDeg, 1e-15);
}

TEST(Steering, ClampToLimitsKnowsTheHandWheelRange) {
  pb::DriverInput in;
  in.set_steer_mode(pb::STEER_HAND_WHEEL);
  in.set_steer(10.0);  // rad: 573 degrees, a valid hand-wheel angle, not a road-wheel angle
  EXPECT_EQ(client::ClampToLimits(in), 0);
  EXPECT_EQ(in.steer(), 10.0);
  in.set_steer(100.0);
  EXPECT_EQ(client::ClampToLimits(in), 1);
  EXPECT_EQ(in.steer(), limits::kHandWheel.hi);
  in.set_steer_mode(pb::STEER_ROAD_WHEEL);
  in.set_steer(10.0);
  EXPECT_EQ(client::ClampToLimits(in), 1);
  EXPECT_EQ(in.steer(), limits::kSteer.hi);
  in.set_clutch(std::nan(""));
  in.set_gear(12);
  EXPECT_EQ(client::ClampToLimits(in), 2);
  EXPECT_EQ(in.clutch(), 0.0);
  EXPECT_EQ(in.gear(), 10);
}

// --- buttons: gear, cruise, e-stop ---------------------------------------------------------------

TEST(InputBuilder, PaddlesCountGearsCruiseFollowsButtonsAndBrake) {
  InputBuilder b(InputBuilderParams{.forward_gears = 3});
  VehicleInfo v;
  pb::DriverInput out;
  MonoTime t{};
  auto press = [&](std::uint32_t bits, double brake = 0) {
    WheelControls c;
    c.buttons = bits;
    c.brake = brake;
    b.Build(t, c, v, out);
    c.buttons = 0;
    b.Build(t, c, v, out);  // released
  };
  for (int i = 0; i < 5; ++i) press(pb::BUTTON_PADDLE_RIGHT);
  EXPECT_EQ(b.gear(), 3);
  EXPECT_EQ(out.gear(), 3);
  for (int i = 0; i < 6; ++i) press(pb::BUTTON_PADDLE_LEFT);
  EXPECT_EQ(b.gear(), -1);  // reverse is as low as it goes
  press(pb::BUTTON_PADDLE_RIGHT);
  EXPECT_EQ(out.gear(), 0);  // automatic

  // Cruise: no speed known yet: the press is ignored and counted.
  press(pb::BUTTON_CRUISE_TOGGLE);
  EXPECT_FALSE(out.cruise_on());
  EXPECT_EQ(b.cruise_ignored(), 1u);
  v.speed_known = true;
  v.speed_kmh = 47.6;
  press(pb::BUTTON_CRUISE_TOGGLE);
  EXPECT_TRUE(out.cruise_on());
  EXPECT_EQ(out.cruise_set_kmh(), 48.0);
  press(pb::BUTTON_CRUISE_UP);
  press(pb::BUTTON_CRUISE_UP);
  EXPECT_EQ(out.cruise_set_kmh(), 58.0);
  press(pb::BUTTON_CRUISE_DOWN);
  EXPECT_EQ(out.cruise_set_kmh(), 53.0);
  // A touch of the brake switches it off, as in a car; "up" resumes the set speed.
  press(0, 0.2);
  EXPECT_FALSE(out.cruise_on());
  press(pb::BUTTON_CRUISE_UP);
  EXPECT_TRUE(out.cruise_on());
  EXPECT_EQ(out.cruise_set_kmh(), 53.0);
  press(pb::BUTTON_CRUISE_TOGGLE);
  EXPECT_FALSE(out.cruise_on());
  // Holding a button does not count again.
  WheelControls held;
  held.buttons = pb::BUTTON_PADDLE_RIGHT;
  for (int i = 0; i < 10; ++i) b.Build(t, held, v, out);
  EXPECT_EQ(b.gear(), 1);
  EXPECT_EQ(out.buttons(), static_cast<std::uint32_t>(pb::BUTTON_PADDLE_RIGHT));
  // Reset: one request per press.
  press(pb::BUTTON_RESET);
  EXPECT_TRUE(b.TakeResetRequest());
  EXPECT_FALSE(b.TakeResetRequest());
}

// The paddles count to the car's gears, not to --gears (a 3-speed car: E six times read "gear 5"
// on the rig, and a down-shift did nothing until the count came back under 3).
TEST(InputBuilder, ThePaddlesCountToTheCarsGears) {
  InputBuilder b;  // --gears 6
  VehicleInfo v;
  pb::VehicleParams p = DefaultVehicleParams();
  p.set_model(pb::VEHICLE_MODEL_FULL);
  p.set_gear_count(3);
  ApplyParams(p, v);
  ASSERT_EQ(v.gear_count, 3);
  pb::DriverInput out;
  WheelControls c;
  for (int i = 0; i < 6; ++i) {
    c.buttons = pb::BUTTON_PADDLE_RIGHT;
    b.Build(MonoTime{}, c, v, out);
    c.buttons = 0;
    b.Build(MonoTime{}, c, v, out);
  }
  EXPECT_EQ(out.gear(), 3);
  c.buttons = pb::BUTTON_PADDLE_LEFT;
  b.Build(MonoTime{}, c, v, out);
  EXPECT_EQ(out.gear(), 2);
}

// A paddle shift that would turn the engine past its limit, or go into or out of reverse while
// moving, is refused with the reason; a reset returns to automatic (issue 31: E from automatic took
// 1st at 87 km/h, 8,482 rpm against 6,800; Q passed into reverse at 40-70 km/h with cruise on;
// reverse survived a reset). The engine speed from the closed form: v / r * ratio * final drive.
TEST(InputBuilder, AShiftThatWouldOverRevOrReverseWhileMovingIsRefused) {
  InputBuilder b;
  VehicleInfo v;
  pb::VehicleParams p = DefaultVehicleParams();
  p.set_model(pb::VEHICLE_MODEL_FULL);
  ApplyParams(p, v);
  ASSERT_GT(v.gear_count, 2);
  pb::DriverInput out;
  MonoTime t{};
  auto press = [&](std::uint32_t bits) {
    WheelControls c;
    c.buttons = bits;
    b.Build(t, c, v, out);
    c.buttons = 0;
    b.Build(t, c, v, out);
  };
  auto rpm_in = [&](int gear, double kmh) {
    const double step = std::pow(v.gear_ratio_top / v.gear_ratio_first, 1.0 / (v.gear_count - 1));
    const double ratio = v.gear_ratio_first * std::pow(step, gear - 1);
    return kmh / 3.6 / v.wheel_radius_m * ratio * v.final_drive_ratio * 60 / (2 * std::numbers::pi);
  };
  v.speed_known = true;
  v.speed_kmh = 87;
  ASSERT_GT(rpm_in(1, 87), v.engine_rpm_limit);  // the case
  press(pb::BUTTON_PADDLE_RIGHT);
  EXPECT_EQ(out.gear(), 0);
  EXPECT_EQ(b.shifts_refused(), 1u);
  char want[96];
  std::snprintf(want, sizeof want, "1st at 87 km/h: the engine at %.0f rpm, past its %.0f limit",
                rpm_in(1, 87), v.engine_rpm_limit);
  EXPECT_EQ(b.shift_refusal(), want);
  // At 20 km/h 1st is within the limit: taken; then down to automatic and, moving, not reverse.
  v.speed_kmh = 20;
  ASSERT_LT(rpm_in(1, 20), v.engine_rpm_limit);
  press(pb::BUTTON_PADDLE_RIGHT);
  EXPECT_EQ(out.gear(), 1);
  press(pb::BUTTON_PADDLE_LEFT);
  EXPECT_EQ(out.gear(), 0);
  v.speed_kmh = 45;
  press(pb::BUTTON_PADDLE_LEFT);
  EXPECT_EQ(out.gear(), 0);
  EXPECT_EQ(b.shift_refusal(), "reverse while moving at 45 km/h: stop first");
  // Standing: reverse; a reset brings automatic back.
  v.speed_kmh = 0.5;
  press(pb::BUTTON_PADDLE_LEFT);
  EXPECT_EQ(out.gear(), -1);
  press(pb::BUTTON_RESET);
  EXPECT_EQ(out.gear(), 0);
  EXPECT_TRUE(b.TakeResetRequest());
}

TEST(InputBuilder, EstopLatchesAndRearmsOnlyWhenHeld) {
  InputBuilder b;
  VehicleInfo v;
  pb::DriverInput out;
  WheelControls c;
  c.buttons = pb::BUTTON_ESTOP;
  b.Build(MonoTime{0}, c, v, out);
  EXPECT_TRUE(b.estop());
  c.buttons = 0;
  b.Build(MonoTime{Milliseconds(10).ns}, c, v, out);
  EXPECT_TRUE(b.estop());  // latched after release
  EXPECT_EQ(out.buttons(), static_cast<std::uint32_t>(pb::BUTTON_ESTOP));
  // A short press while latched does not re-arm; a 2 s hold does.
  c.buttons = pb::BUTTON_ESTOP;
  b.Build(MonoTime{Milliseconds(100).ns}, c, v, out);
  b.Build(MonoTime{Milliseconds(1500).ns}, c, v, out);
  EXPECT_TRUE(b.estop());
  b.Build(MonoTime{Milliseconds(2100).ns}, c, v, out);
  EXPECT_FALSE(b.estop());
  EXPECT_EQ(out.buttons() & pb::BUTTON_ESTOP, 0u);
}

// --- bad axis values
// -------------------------------------------------------------------------------

TEST(WheelReader, NanAndOutOfRangeAxesAreClampedAndCounted) {
  WheelReader r(*FindBuiltinWheel(0x046d, 0xc24f));  // G29: steer 0, clutch 1, throttle 2, brake 3
  RawFrame f;
  f.n_axes = 4;
  f.axes = {};
  f.axes[0] = -16384;  // a quarter of the travel left of centre: +225 degrees of 900
  f.axes[1] = f.axes[2] = 32767;
  f.axes[3] = 0;  // half brake
  WheelControls c = r.Read(f);
  EXPECT_NEAR(c.hand_angle_rad, 225 * kDeg, 0.05 * kDeg);
  const double brake = c.brake;
  EXPECT_GT(brake, 0.4);
  // Not numbers: steering and brake hold their last good values, the throttle drops to zero.
  f.axes[0] = std::nan("");
  f.axes[2] = -32768;  // full throttle...
  c = r.Read(f);
  EXPECT_EQ(c.throttle, 1.0);
  f.axes[2] = std::numeric_limits<double>::infinity();  // ...then garbage
  f.axes[3] = std::nan("");
  c = r.Read(f);
  EXPECT_NEAR(c.hand_angle_rad, 225 * kDeg, 0.05 * kDeg);
  EXPECT_EQ(c.throttle, 0.0);
  EXPECT_EQ(c.brake, brake);
  EXPECT_EQ(r.nonfinite(), 4u);
  EXPECT_EQ(r.out_of_range(), 0u);
  // Beyond the calibrated travel: clamped to the end, counted.
  pb::WheelMapping narrow = *FindBuiltinWheel(0x046d, 0xc24f);
  narrow.mutable_steer()->set_left(-20000);
  narrow.mutable_steer()->set_right(20000);
  WheelReader n(narrow);
  f.axes = {};
  f.axes[1] = f.axes[2] = f.axes[3] = 32767;
  f.axes[0] = -32768;
  c = n.Read(f);
  EXPECT_NEAR(c.hand_angle_rad, 450 * kDeg, 1e-12);
  EXPECT_EQ(n.out_of_range(), 1u);
  f.axes[0] = -20300;  // within 2 % of the travel: noise at the lock, clamped, not counted
  c = n.Read(f);
  EXPECT_NEAR(c.hand_angle_rad, 450 * kDeg, 1e-12);
  EXPECT_EQ(n.out_of_range(), 1u);
  // And the message sent stays inside the limits whatever the mapping says.
  InputBuilder b;
  VehicleInfo v;
  v.model = pb::VEHICLE_MODEL_FULL;
  pb::DriverInput out;
  WheelControls wild;
  wild.hand_angle_rad = 1e6;
  wild.throttle = std::nan("");
  b.Build(MonoTime{}, wild, v, out);
  EXPECT_EQ(out.steer(), limits::kHandWheel.hi);
  EXPECT_EQ(out.throttle(), 0.0);
  EXPECT_EQ(b.clamped(), 1u);  // steer clamped by ToSteer already; the NaN throttle here
}

// Out-of-range values from a device: the virtual wheel reports a value past a user calibration.
TEST_F(SdlTest, AVirtualWheelPastItsCalibrationIsClampedAndCounted) {
  pb::WheelMapping m = *FindBuiltinWheel(0x046d, 0xc24f);
  m.mutable_throttle()->set_rest(30000);
  m.mutable_throttle()->set_full(-30000);
  WriteMappingFile(DefaultMappingPath(0x046d, 0xc24f), m);
  SdlContext sdl(false);
  VirtualWheel w(0x046d, 0xc24f, 4, 25);
  const auto devices = ScanDevices();
  const DeviceInfo d = Find(devices, 0x046d, 0xc24f);
  EXPECT_EQ(d.kind, DeviceInfo::Kind::kUserFile);
  std::string why;
  auto dev = WheelDevice::Open(d, devices, nullptr, &why);
  ASSERT_NE(dev, nullptr) << why;
  WheelReader reader(dev->mapping());
  RawFrame f;
  w.Axis(1, 32767);
  w.Axis(3, 32767);
  w.Axis(2, -32768);
  SDL_JoystickUpdate();
  dev->Read(f);
  EXPECT_EQ(reader.Read(f).throttle, 1.0);
  EXPECT_EQ(reader.out_of_range(), 1u);
}

// --- mapping files -------------------------------------------------------------------------------

TEST_F(SdlTest, MappingFilesRoundTripAndBadOnesAreRefusedWithTheReason) {
  const pb::WheelMapping& g29 = *FindBuiltinWheel(0x046d, 0xc24f);
  const auto path = dir_ / "g29.txt";
  WriteMappingFile(path, g29);
  const pb::WheelMapping back = ReadMappingFile(path);
  EXPECT_EQ(back.SerializeAsString(), g29.SerializeAsString());
  EXPECT_THAT(testing::ReadFile(path), HasSubstr("range_deg: 900"));

  testing::WriteFile(dir_ / "syntax.txt", "name: \"x\"\nsteer { axis: 0 left: oops }\n");
  try {
    ReadMappingFile(dir_ / "syntax.txt");
    ADD_FAILURE() << "accepted";
  } catch (const MappingError& e) {
    EXPECT_THAT(e.what(), HasSubstr("syntax.txt: line 2, column"));
  }
  testing::WriteFile(dir_ / "values.txt",
                     "steer { axis: 0 left: 100 right: 200 range_deg: 20 }\n"
                     "throttle { axis: 1 rest: 0 full: 0 }\n");
  try {
    ReadMappingFile(dir_ / "values.txt");
    ADD_FAILURE() << "accepted";
  } catch (const MappingError& e) {
    EXPECT_THAT(e.what(),
                HasSubstr("steer: left 100 and right 200 are less than 1000 raw units apart"));
    EXPECT_THAT(
        e.what(),
        HasSubstr("steer.range_deg: wheel rotation range, degree must be in [90, 3600], got 20"));
    EXPECT_THAT(e.what(), HasSubstr("throttle: rest 0 and full 0"));
  }
  EXPECT_THROW(ReadMappingFile(dir_ / "missing.txt"), MappingError);
  EXPECT_THROW(ReadMappingFile(dir_.path()), MappingError);
  try {  // a file that never ends: refused at the bound (it filled the memory)
    ReadMappingFile("/dev/zero");
    ADD_FAILURE() << "accepted";
  } catch (const MappingError& e) {
    EXPECT_THAT(e.what(), HasSubstr("/dev/zero: more than 4194304 bytes, more than a mapping file"));
  }
  // A broken user file is reported, not silently replaced by the table.
  std::filesystem::create_directories(DefaultMappingPath(0x046d, 0xc29b).parent_path());
  testing::WriteFile(DefaultMappingPath(0x046d, 0xc29b), "steer {");
  SdlContext sdl(false);
  VirtualWheel w(0x046d, 0xc29b, 4, 22);
  const DeviceInfo d = Find(ScanDevices(), 0x046d, 0xc29b);
  EXPECT_EQ(d.kind, DeviceInfo::Kind::kBrokenFile);
  EXPECT_THAT(d.recognised_as, HasSubstr("broken mapping"));
  std::string why;
  EXPECT_EQ(WheelDevice::Open(d, {d}, nullptr, &why), nullptr);
  EXPECT_THAT(why, HasSubstr("c29b.txt"));
}

TEST_F(SdlTest, ADeviceTheTableDoesNotKnowIsAGenericWheelOrNotAWheel) {
  SdlContext sdl(false);
  VirtualWheel w(0x1234, 0x0001, 3, 8);
  const DeviceInfo d = Find(ScanDevices(), 0x1234, 0x0001);
  EXPECT_EQ(d.kind, DeviceInfo::Kind::kGeneric);
  EXPECT_EQ(d.mapping.ffb().peak_torque_nm(), 0.0);  // no force feedback until told the peak
  EXPECT_EQ(d.mapping.throttle().axis(), 1);
  EXPECT_EQ(d.mapping.brake().axis(), 2);
  // A gamepad is not a wheel.
  SDL_VirtualJoystickDesc pad{};
  pad.version = SDL_VIRTUAL_JOYSTICK_DESC_VERSION;
  pad.type = SDL_JOYSTICK_TYPE_GAMECONTROLLER;
  pad.naxes = 6;
  pad.nbuttons = 10;
  pad.vendor_id = 0x1234;
  pad.product_id = 0x0002;
  ASSERT_GE(SDL_JoystickAttachVirtualEx(&pad), 0);
  EXPECT_EQ(Find(ScanDevices(), 0x1234, 0x0002).kind, DeviceInfo::Kind::kNotAWheel);
}

// --- combined pedals and calibration ----------------------------------------------------------

TEST(WheelReader, CombinedPedalsSplitAtRest) {
  pb::WheelMapping m = GenericWheel(0x1234, 1, 2);
  m.clear_throttle();
  m.clear_brake();
  auto* c = m.mutable_combined();
  c->set_axis(1);
  c->set_rest(0);
  c->set_throttle_full(-32768);  // older wheels: throttle pulls the axis up (negative in SDL)
  c->set_brake_full(32767);
  c->set_dead_zone(0.0);
  ASSERT_THAT(ValidateMapping(m), ::testing::IsEmpty());
  WheelReader r(m);
  RawFrame f;
  f.n_axes = 2;
  f.axes[1] = -16384;
  WheelControls w = r.Read(f);
  EXPECT_DOUBLE_EQ(w.throttle, 0.5);
  EXPECT_EQ(w.brake, 0.0);
  f.axes[1] = 32767;
  w = r.Read(f);
  EXPECT_EQ(w.throttle, 0.0);
  EXPECT_DOUBLE_EQ(w.brake, 1.0);
  // Both on one side of rest is not a combined axis.
  c->set_brake_full(-1000);
  EXPECT_THAT(ValidateMapping(m), ::testing::Contains(HasSubstr("opposite sides of rest")));
}

// Two controls on one axis of one device are refused, naming both and the axis (issue 33: throttle
// and brake on one axis were accepted, and every press drove and braked at once); the same index
// on the wheel and on the pedal device are two axes.
TEST(WheelMapping, TwoControlsOnOneAxisAreRefused) {
  pb::WheelMapping m = GenericWheel(0x1234, 2, 4);  // steer 0, throttle 1, brake 2
  ASSERT_THAT(ValidateMapping(m), ::testing::IsEmpty());
  m.mutable_brake()->set_axis(1);
  EXPECT_THAT(ValidateMapping(m),
              ::testing::Contains(HasSubstr("throttle and brake are both on axis 1 of the wheel: "
                                            "each control needs an axis of its own")));
  m.mutable_brake()->set_axis(2);
  m.mutable_clutch()->set_axis(0);
  m.mutable_clutch()->set_rest(-32768);
  m.mutable_clutch()->set_full(32767);
  EXPECT_THAT(ValidateMapping(m),
              ::testing::Contains(HasSubstr("steer and clutch are both on axis 0 of the wheel")));
  // The brake on axis 1 of a pedal device, the throttle on axis 1 of the wheel: two axes.
  m.clear_clutch();
  m.set_pedal_vendor_id(0x1111);
  m.set_pedal_product_id(0x2222);
  m.mutable_brake()->set_axis(1);
  m.mutable_brake()->set_on_pedal_device(true);
  EXPECT_THAT(ValidateMapping(m), ::testing::IsEmpty());
}

// Raw values at the int32 extremes are refused by their range, and the spans between them are
// computed without overflow (issue 20: the report showed a wrapped difference). The sanitizer
// build traps a signed overflow here.
TEST(WheelMapping, Int32ExtremesAreRefusedWithoutOverflow) {
  constexpr std::int32_t lo = std::numeric_limits<std::int32_t>::min();
  constexpr std::int32_t hi = std::numeric_limits<std::int32_t>::max();
  pb::WheelMapping m = GenericWheel(0x1234, 2, 3);
  m.mutable_steer()->set_left(lo);
  m.mutable_steer()->set_right(hi);
  m.mutable_throttle()->set_rest(hi);
  m.mutable_throttle()->set_full(lo);
  m.mutable_brake()->set_rest(lo);
  m.mutable_brake()->set_full(lo + 500);  // really less than 1000 apart
  const auto why = ValidateMapping(m);
  EXPECT_THAT(why, ::testing::Contains(HasSubstr(
                       "steer.left: raw axis value must be in [-32768, 32767], got -2147483648")));
  EXPECT_THAT(why, ::testing::Contains(HasSubstr(
                       "steer.right: raw axis value must be in [-32768, 32767], got 2147483647")));
  EXPECT_THAT(why, ::testing::Contains(HasSubstr("throttle.rest: raw axis value must be in")));
  EXPECT_THAT(why, ::testing::Not(::testing::Contains(HasSubstr("steer: left"))));
  EXPECT_THAT(why, ::testing::Not(::testing::Contains(HasSubstr("throttle: rest"))));
  EXPECT_THAT(why, ::testing::Contains(HasSubstr(
                       "brake: rest -2147483648 and full -2147483148 are less than 1000 raw units "
                       "apart")));
  pb::WheelMapping c = GenericWheel(0x1234, 2, 3);
  c.clear_throttle();
  c.clear_brake();
  c.mutable_combined()->set_axis(1);
  c.mutable_combined()->set_rest(lo);
  c.mutable_combined()->set_throttle_full(hi);
  c.mutable_combined()->set_brake_full(lo);
  EXPECT_THAT(ValidateMapping(c), ::testing::Contains(HasSubstr("opposite sides of rest")));
  EXPECT_THAT(ValidateMapping(c),
              ::testing::Contains(HasSubstr("combined.rest: raw axis value must be in")));
}

// A person's session at the wheel, scripted: each step's motion on an SDL virtual joystick with
// the G29's layout (axes: steering, clutch, throttle, brake; pedals resting at full scale), the
// calibrator fed 200 frames a second. The mapping found is the script's.
class CalibrationSession {
 public:
  CalibrationSession(VirtualWheel& w, Calibrator& c) : w_(w), c_(c) {}
  // Runs `seconds` of frames at 200 Hz.
  void Run(double seconds) {
    for (int i = 0; i < static_cast<int>(seconds * 200); ++i) {
      t_ = t_ + Milliseconds(5);
      SDL_JoystickUpdate();
      ReadJoysticks(w_.joystick(), nullptr, f_);
      c_.Feed(t_, f_);
      if (on_frame) on_frame();
    }
  }
  MonoTime now() const { return t_; }
  std::function<void()> on_frame;

 private:
  VirtualWheel& w_;
  Calibrator& c_;
  MonoTime t_{1'000'000'000};
  RawFrame f_;
};

TEST_F(SdlTest, CalibrationFromAScriptedSession) {
  SdlContext sdl(false);
  VirtualWheel w(0x046d, 0xc24f, 4, 25);
  auto rest = [&] {
    w.Axis(0, 0);
    for (int a = 1; a < 4; ++a) w.Axis(a, 32767);
    for (int b = 0; b < 25; ++b) w.Button(b, false);
  };
  rest();
  Calibrator::Options opt;
  opt.vendor_id = 0x046d;
  opt.product_id = 0xc24f;
  opt.range_deg = 900;
  opt.base = *FindBuiltinWheel(0x046d, 0xc24f);
  opt.ffb = true;
  opt.optional_timeout = base::Seconds(20);
  Calibrator cal(opt);
  CalibrationSession s(w, cal);
  s.Run(0.2);
  EXPECT_EQ(cal.step(), Calibrator::Step::kRest);
  cal.Confirm(s.now());
  EXPECT_EQ(cal.step(), Calibrator::Step::kSteerLeft);
  // A hand turning the wheel: first part way, then to the lock (a little short of SDL's end), held.
  w.Axis(0, -15000);
  s.Run(0.2);
  w.Axis(0, -32000);
  s.Run(0.3);
  EXPECT_EQ(cal.step(), Calibrator::Step::kSteerLeft);  // not held long enough yet
  s.Run(0.4);
  EXPECT_EQ(cal.step(), Calibrator::Step::kSteerRight);
  w.Axis(0, 0);  // through the centre
  s.Run(0.1);
  w.Axis(0, 31800);
  s.Run(1.0);
  EXPECT_EQ(cal.step(), Calibrator::Step::kThrottle);
  w.Axis(0, 0);
  s.Run(0.1);
  w.Axis(2, -32768);  // throttle to the floor
  s.Run(1.0);
  EXPECT_EQ(cal.step(), Calibrator::Step::kBrake);
  // The next step waits until the throttle is released, so a held pedal is not taken twice.
  s.Run(1.0);
  EXPECT_EQ(cal.step(), Calibrator::Step::kBrake);
  w.Axis(2, 32767);
  s.Run(0.1);
  w.Axis(3, -30000);  // the brake's load cell stops short of the end
  s.Run(1.0);
  EXPECT_EQ(cal.step(), Calibrator::Step::kClutch);
  w.Axis(3, 32767);
  s.Run(0.1);
  w.Axis(1, -32768);
  s.Run(1.0);
  EXPECT_EQ(cal.step(), Calibrator::Step::kHandbrake);
  w.Axis(1, 32767);
  s.Run(0.1);
  cal.Confirm(s.now());  // no handbrake: Enter skips
  EXPECT_EQ(cal.step(), Calibrator::Step::kPaddleLeft);
  s.Run(0.05);
  auto press = [&](int b) {
    w.Button(b, true);
    s.Run(0.1);
    w.Button(b, false);
    s.Run(0.1);
  };
  press(5);
  press(4);
  EXPECT_EQ(cal.step(), Calibrator::Step::kCruiseToggle);
  press(23);
  press(19);
  press(20);
  press(9);
  EXPECT_EQ(cal.step(), Calibrator::Step::kCamera);
  s.Run(21);  // nothing pressed: the camera step is skipped after its quiet time
  EXPECT_EQ(cal.step(), Calibrator::Step::kEstop);
  press(24);
  cal.Skip(s.now());  // no horn
  ASSERT_EQ(cal.step(), Calibrator::Step::kFfbDirection);
  EXPECT_EQ(cal.ffb_level(), 0.0);  // nothing plays before the hands are off
  cal.Confirm(s.now());
  EXPECT_GT(cal.ffb_level(), 0.0);
  // This wheel turns RIGHT for a positive level (the axis rises): its direction is inverted.
  int frames = 0;
  s.on_frame = [&] {
    if (cal.ffb_level() > 0) w.Axis(0, std::min(++frames * 200, 30000));
  };
  s.Run(0.5);
  ASSERT_TRUE(cal.done()) << cal.Prompt();
  EXPECT_EQ(cal.ffb_level(), 0.0);

  const pb::WheelMapping m = cal.result();
  EXPECT_EQ(m.steer().axis(), 0);
  EXPECT_EQ(m.steer().left(), -32000);
  EXPECT_EQ(m.steer().right(), 31800);
  EXPECT_EQ(m.steer().range_deg(), 900);
  EXPECT_EQ(m.throttle().axis(), 2);
  EXPECT_EQ(m.throttle().rest(), 32767);
  EXPECT_EQ(m.throttle().full(), -32768);
  EXPECT_EQ(m.brake().axis(), 3);
  EXPECT_EQ(m.brake().full(), -30000);
  EXPECT_EQ(m.clutch().axis(), 1);
  EXPECT_FALSE(m.handbrake().has_axis());
  EXPECT_FALSE(m.has_combined());
  EXPECT_EQ(m.buttons().paddle_left(), 5);
  EXPECT_EQ(m.buttons().paddle_right(), 4);
  EXPECT_EQ(m.buttons().cruise_toggle(), 23);
  EXPECT_EQ(m.buttons().cruise_up(), 19);
  EXPECT_EQ(m.buttons().cruise_down(), 20);
  EXPECT_EQ(m.buttons().reset(), 9);
  EXPECT_FALSE(m.buttons().has_camera());
  EXPECT_EQ(m.buttons().estop(), 24);
  EXPECT_FALSE(m.buttons().has_horn());
  EXPECT_TRUE(m.ffb().invert());
  EXPECT_EQ(m.ffb().peak_torque_nm(), opt.base.ffb().peak_torque_nm());
  EXPECT_EQ(m.vendor_id(), 0x046du);
  EXPECT_THAT(ValidateMapping(m, 4, 25), ::testing::IsEmpty());

  // Written where drive looks for it, it takes the table's place, and the brake now reaches 1 at
  // the load cell's end.
  WriteMappingFile(DefaultMappingPath(0x046d, 0xc24f), m);
  const auto devices = ScanDevices();
  const DeviceInfo d = Find(devices, 0x046d, 0xc24f);
  EXPECT_EQ(d.kind, DeviceInfo::Kind::kUserFile);
  std::string why;
  auto dev = WheelDevice::Open(d, devices, nullptr, &why);
  ASSERT_NE(dev, nullptr) << why;
  WheelReader reader(dev->mapping());
  rest();
  w.Axis(3, -30000);
  w.Axis(0, -32000);
  SDL_JoystickUpdate();
  RawFrame f;
  dev->Read(f);
  const WheelControls c = reader.Read(f);
  EXPECT_DOUBLE_EQ(c.brake, 1.0);
  EXPECT_NEAR(c.hand_angle_rad, 450 * kDeg, 1e-12);
}

TEST_F(SdlTest, CalibrationFindsCombinedPedals) {
  SdlContext sdl(false);
  VirtualWheel w(0x1234, 0x0009, 2, 4);
  w.Axis(0, 0);
  w.Axis(1, 0);
  Calibrator::Options opt;
  opt.vendor_id = 0x1234;
  opt.product_id = 0x0009;
  opt.base = GenericWheel(0x1234, 0x0009, 2);
  Calibrator cal(opt);
  CalibrationSession s(w, cal);
  s.Run(0.1);
  cal.Confirm(s.now());
  w.Axis(0, -32768);
  s.Run(1.0);
  w.Axis(0, 0);
  s.Run(0.1);
  w.Axis(0, 32767);
  s.Run(1.0);
  w.Axis(0, 0);
  s.Run(0.1);
  w.Axis(1, -32768);  // throttle pulls the one pedal axis up...
  s.Run(1.0);
  w.Axis(1, 0);
  s.Run(0.1);
  ASSERT_EQ(cal.step(), Calibrator::Step::kBrake);
  w.Axis(1, 32767);  // ...the brake pushes it down
  s.Run(1.0);
  EXPECT_EQ(cal.step(), Calibrator::Step::kClutch);
  while (!cal.done()) cal.Skip(s.now());
  const pb::WheelMapping m = cal.result();
  EXPECT_FALSE(m.throttle().has_axis());
  EXPECT_FALSE(m.brake().has_axis());
  EXPECT_EQ(m.combined().axis(), 1);
  EXPECT_EQ(m.combined().rest(), 0);
  EXPECT_EQ(m.combined().throttle_full(), -32768);
  EXPECT_EQ(m.combined().brake_full(), 32767);
  EXPECT_THAT(ValidateMapping(m, 2, 4), ::testing::IsEmpty());
}

// A direct-drive base without pedal inputs (Simucube 2) with a pedal set on its own USB device:
// calibrated together (`calibrate --pedals N`), driven together; unplugging the pedals is an
// unplug too.
TEST_F(SdlTest, ABaseWithoutPedalsDrivesWithAUsbPedalSet) {
  SdlContext sdl(false);
  VirtualWheel base(0x16d0, 0x0d61, 1, 16, "Simucube 2 Sport");
  auto pedals = std::make_unique<VirtualWheel>(0x30b7, 0x1001, 3, 1, "pedal set");
  base.Axis(0, 0);
  for (int a = 0; a < 3; ++a) pedals->Axis(a, -32768);
  Calibrator::Options opt;
  opt.vendor_id = 0x16d0;
  opt.product_id = 0x0d61;
  opt.pedal_vendor_id = 0x30b7;
  opt.pedal_product_id = 0x1001;
  opt.base = *FindBuiltinWheel(0x16d0, 0x0d61);
  Calibrator cal(opt);
  MonoTime t{1'000'000'000};
  RawFrame f;
  auto run = [&](double seconds) {
    for (int i = 0; i < static_cast<int>(seconds * 200); ++i) {
      t = t + Milliseconds(5);
      SDL_JoystickUpdate();
      ReadJoysticks(base.joystick(), pedals->joystick(), f);
      cal.Feed(t, f);
    }
  };
  run(0.1);
  cal.Confirm(t);
  base.Axis(0, -32768);
  run(1);
  base.Axis(0, 0);
  run(0.1);
  base.Axis(0, 32767);
  run(1);
  base.Axis(0, 0);
  run(0.1);
  pedals->Axis(1, 32767);  // throttle: the pedal set's axis 1
  run(1);
  pedals->Axis(1, -32768);
  run(0.1);
  pedals->Axis(0, 32767);  // brake: its axis 0
  run(1);
  pedals->Axis(0, -32768);
  run(0.1);
  while (!cal.done()) cal.Skip(t);
  const pb::WheelMapping m = cal.result();
  EXPECT_TRUE(m.throttle().on_pedal_device());
  EXPECT_EQ(m.throttle().axis(), 1);
  EXPECT_TRUE(m.brake().on_pedal_device());
  EXPECT_EQ(m.brake().axis(), 0);
  EXPECT_EQ(m.pedal_vendor_id(), 0x30b7u);
  EXPECT_EQ(m.pedal_product_id(), 0x1001u);
  EXPECT_EQ(m.ffb().peak_torque_nm(), 17.0);
  WriteMappingFile(DefaultMappingPath(0x16d0, 0x0d61), m);

  RecordingSink sink;
  FakeFeed feed;
  RigConfig cfg;
  cfg.source = RigConfig::Source::kWheel;
  cfg.window = false;
  cfg.ffb = false;
  cfg.replug_scan = Milliseconds(50);
  RigLoop rig(cfg, sdl, sink, feed, nullptr);
  rig.Start();
  ASSERT_EQ(rig.device_name(), "Simucube 2 Sport");
  pedals->Axis(1, 32767);
  base.Axis(0, 32767);
  ASSERT_TRUE(rig.Tick(t = t + Milliseconds(1)));
  EXPECT_EQ(sink.last.throttle(), 1.0);
  EXPECT_NEAR(sink.last.steer(), -450.0 / 15.0 * kDeg, 1e-12);  // half of 900 degrees, right
  {
    testing::ExpectLogs logs;
    pedals->Detach();
    ASSERT_TRUE(rig.Tick(t = t + Milliseconds(1)));
  }
  EXPECT_EQ(sink.last.throttle(), 0.0);
  EXPECT_EQ(sink.last.brake(), 0.3);
  EXPECT_EQ(rig.unplugs(), 1u);
  pedals = std::make_unique<VirtualWheel>(0x30b7, 0x1001, 3, 1, "pedal set");
  pedals->Axis(0, 32767);
  pedals->Axis(1, -32768);
  pedals->Axis(2, -32768);
  for (int i = 0; i < 60; ++i) ASSERT_TRUE(rig.Tick(t = t + Milliseconds(1)));
  EXPECT_EQ(rig.replugs(), 1u);
  EXPECT_EQ(sink.last.brake(), 1.0);
  EXPECT_EQ(sink.last.throttle(), 0.0);
}

// A device that refuses every force-feedback update is said (the status line read "ffb ... on"
// throughout; only the summary at the end counted the errors).
TEST_F(SdlTest, ForceFeedbackTheDeviceRefusesIsSaid) {
  struct Refusing : RecordingHaptic {
    bool SetConstant(double, base::Nanos) override { return false; }
  };
  SdlContext sdl(false);
  const auto g29 = ReleasedG29();
  RecordingSink sink;
  FakeFeed feed;
  RigConfig cfg = WheelRigConfig();
  HapticFactory factory = [](const WheelDevice&, std::string*) -> std::unique_ptr<HapticDevice> {
    return std::make_unique<Refusing>();
  };
  RigLoop rig(cfg, sdl, sink, feed, nullptr, factory);
  rig.Start();
  ASSERT_TRUE(rig.using_wheel());
  MonoTime t{1'000'000'000};
  feed.st.set_steering_torque(1.25);
  testing::ExpectLogs logs;
  TickWithStates(rig, feed, t, 100);
  EXPECT_EQ(logs.count(), 1);  // once a second
  EXPECT_THAT(rig.StatusLine(), HasSubstr("DEVICE ERRORS"));
}

// --- the rig loop with a wheel: steering per model, hot-unplug ---------------------------------

TEST_F(SdlTest, RigDrivesFromAWheelAndFallsBackToNeutralWhenItIsUnplugged) {
  SdlContext sdl(false);
  auto w = std::make_unique<VirtualWheel>(0x046d, 0xc24f, 4, 25);
  for (int a = 1; a < 4; ++a) w->Axis(a, 32767);
  RecordingSink sink;
  FakeFeed feed;
  RigConfig cfg;
  cfg.source = RigConfig::Source::kWheel;
  cfg.window = false;
  cfg.replug_scan = Milliseconds(50);
  RecordingHaptic* haptic = nullptr;
  HapticFactory factory = [&](const WheelDevice&, std::string*) -> std::unique_ptr<HapticDevice> {
    auto h = std::make_unique<RecordingHaptic>();
    haptic = h.get();
    return h;
  };
  RigLoop rig(cfg, sdl, sink, feed, nullptr, factory);
  rig.Start();
  ASSERT_TRUE(rig.using_wheel());
  EXPECT_EQ(rig.device_name(), "virtual wheel");
  ASSERT_NE(haptic, nullptr);
  MonoTime t{1'000'000'000};
  auto tick = [&](int n = 1) {
    for (int i = 0; i < n; ++i) {
      t = t + Milliseconds(1);
      ASSERT_TRUE(rig.Tick(t));
    }
  };
  // 90 degrees to the left (a tenth of the 900 degree travel, 6553.5 raw units below centre),
  // half throttle: the paper's car gets 90 / 15 = 6 degrees at the road wheels.
  w->Axis(0, -6554);
  w->Axis(2, 0);
  tick();
  EXPECT_EQ(sink.last.steer_mode(), pb::STEER_ROAD_WHEEL);
  EXPECT_NEAR(sink.last.steer(), 6 * kDeg, 0.01 * kDeg);
  EXPECT_NEAR(sink.last.throttle(), (0.5 - 0.02) / 0.98, 1e-4);
  // The server now runs the full model: the same wheel sends its hand-wheel angle.
  feed.vehicle.set_model(pb::VEHICLE_MODEL_FULL);
  tick(4);  // parameters are taken at the force-feedback rate (every 2 ms)
  EXPECT_EQ(sink.last.steer_mode(), pb::STEER_HAND_WHEEL);
  EXPECT_NEAR(sink.last.steer(), 90 * kDeg, 0.01 * kDeg);
  feed.vehicle.set_model(pb::VEHICLE_MODEL_PAPER);
  tick(4);

  // Unplugged mid-drive: reported, and a safe neutral - no throttle, the neutral brake, steering
  // held where it was, cruise off.
  {
    testing::ExpectLogs logs;
    w->Detach();
    tick();
    EXPECT_GE(logs.count(), 1);
  }
  EXPECT_FALSE(rig.wheel_attached());
  EXPECT_EQ(rig.unplugs(), 1u);
  EXPECT_EQ(sink.last.throttle(), 0.0);
  EXPECT_EQ(sink.last.brake(), 0.3);
  EXPECT_NEAR(sink.last.steer(), 6 * kDeg, 0.01 * kDeg);
  EXPECT_FALSE(sink.last.cruise_on());
  const int sent = sink.count;
  tick(200);
  EXPECT_EQ(sink.count, sent + 200);  // still written every tick: the rig keeps its vehicle
  EXPECT_EQ(sink.last.brake(), 0.3);

  // Plugged back in (a new SDL device with the same ids): found by the next scan, driving again.
  w = std::make_unique<VirtualWheel>(0x046d, 0xc24f, 4, 25);
  for (int a = 1; a < 4; ++a) w->Axis(a, 32767);
  w->Axis(0, 6554);
  tick(60);
  EXPECT_TRUE(rig.wheel_attached());
  EXPECT_EQ(rig.replugs(), 1u);
  EXPECT_NEAR(sink.last.steer(), -6 * kDeg, 0.01 * kDeg);
  EXPECT_EQ(sink.last.brake(), 0.0);
  EXPECT_THAT(rig.Summary(), HasSubstr("unplugged 1 times, back 1 times"));
}

// SDL drops joystick values while no window of the program has the keyboard focus unless told
// otherwise; a rig whose window is in the background (the viewer has the focus) must still read
// its wheel.
TEST_F(SdlTest, TheWheelIsReadWhileTheWindowHasNoFocus) {
  SdlContext sdl(true);
  ASSERT_TRUE(sdl.video()) << sdl.video_error();
  VirtualWheel w(0x046d, 0xc24f, 4, 25);
  for (int a = 1; a < 4; ++a) w.Axis(a, 32767);
  RecordingSink sink;
  FakeFeed feed;
  RigConfig cfg;
  cfg.source = RigConfig::Source::kWheel;
  cfg.ffb = false;
  RigLoop rig(cfg, sdl, sink, feed, nullptr);
  rig.Start();
  ASSERT_NE(rig.window(), nullptr);
  ASSERT_EQ(SDL_GetKeyboardFocus(), nullptr);
  w.Axis(2, -32768);
  ASSERT_TRUE(rig.Tick(MonoTime{1'000'000'000}));
  EXPECT_EQ(sink.last.throttle(), 1.0);
}

// --- keyboard
// --------------------------------------------------------------------------------------

void Key(SDL_Scancode sc, bool down) {
  SDL_Event e{};
  e.type = down ? SDL_KEYDOWN : SDL_KEYUP;
  e.key.state = down ? SDL_PRESSED : SDL_RELEASED;
  e.key.keysym.scancode = sc;
  e.key.keysym.sym = SDL_GetKeyFromScancode(sc);
  ASSERT_EQ(SDL_PushEvent(&e), 1) << SDL_GetError();
}

// A wheel plugged in whose mapping is broken, or a --mapping for another device: said, and
// refused (vdyn-input drive exits 2), not set aside for the keyboard or the built-in table
// (drive went on with the keyboard, exit 0, with no word of the file).
TEST_F(SdlTest, ABrokenOrForeignMappingIsRefusedNotSetAsideForTheKeyboard) {
  SdlContext sdl(true);
  ASSERT_TRUE(sdl.video()) << sdl.video_error();
  VirtualWheel g29(0x046d, 0xc24f, 6, 25, "G29 virtual");
  RecordingSink sink;
  FakeFeed feed;
  auto start = [&](const std::filesystem::path& file) {
    RigConfig cfg;
    cfg.source = RigConfig::Source::kAuto;
    cfg.window = false;
    cfg.ffb = false;
    cfg.mapping_file = file;
    RigLoop rig(cfg, sdl, sink, feed, nullptr);
    try {
      rig.Start();
    } catch (const std::runtime_error& e) {
      return std::string(e.what());
    }
    return std::string(rig.using_wheel() ? "wheel" : "keyboard");
  };
  testing::WriteFile(dir_ / "broken.txt", "steer { axis: 0 left: \n");
  const std::string broken = start(dir_ / "broken.txt");
  EXPECT_THAT(broken, HasSubstr("cannot use G29 virtual [046d:c24f]: broken mapping: "));
  EXPECT_THAT(broken, HasSubstr("broken.txt"));
  pb::WheelMapping foreign = *FindBuiltinWheel(0x046d, 0xc24f);
  foreign.set_vendor_id(0x1234);
  foreign.clear_product_ids();
  foreign.add_product_ids(0x5678);
  WriteMappingFile(dir_ / "other.txt", foreign);
  const std::string other = start(dir_ / "other.txt");
  EXPECT_THAT(other, HasSubstr("other.txt is for another device"));
  EXPECT_THAT(other, HasSubstr("G29 virtual [046d:c24f]"));
}

// Keyboard driving from synthetic SDL key events under the dummy video driver, with the loop's
// clock given: every ramp is its rate times the time held.
TEST_F(SdlTest, KeyboardDrivesWithRampsAndSteeringReturnsToCentre) {
  SdlContext sdl(true);
  ASSERT_TRUE(sdl.video()) << sdl.video_error();
  RecordingSink sink;
  FakeFeed feed;  // the default car: lock 0.6 rad, ratio 15, wheelbase 2.7 m
  RigConfig cfg;
  cfg.source = RigConfig::Source::kAuto;  // no wheel plugged in: the keyboard
  cfg.events_hz = 1000;
  RigLoop rig(cfg, sdl, sink, feed, nullptr);
  rig.Start();
  ASSERT_FALSE(rig.using_wheel());
  ASSERT_NE(rig.window(), nullptr);
  MonoTime t{1'000'000'000};
  auto run = [&](double seconds) {
    for (int i = 0; i < static_cast<int>(std::lround(seconds * 1000)); ++i) {
      t = t + Milliseconds(1);
      feed.received = t;  // a state each tick (a silent server is said: another test)
      ASSERT_TRUE(rig.Tick(t));
    }
  };
  run(0.01);
  EXPECT_EQ(sink.last.throttle(), 0.0);
  Key(SDL_SCANCODE_UP, true);
  run(0.25);  // throttle rises at 2 per second
  EXPECT_NEAR(sink.last.throttle(), 0.5, 0.0021);
  run(0.5);
  EXPECT_EQ(sink.last.throttle(), 1.0);
  Key(SDL_SCANCODE_UP, false);
  run(0.1);  // and falls at 4 per second
  EXPECT_NEAR(sink.last.throttle(), 0.6, 0.0041);
  run(0.2);
  EXPECT_EQ(sink.last.throttle(), 0.0);

  // Standing still, a held key turns the road wheels to the lock at 1.5 locks per second.
  Key(SDL_SCANCODE_A, true);
  run(0.4);
  EXPECT_EQ(sink.last.steer_mode(), pb::STEER_ROAD_WHEEL);
  EXPECT_NEAR(sink.last.steer(), 0.6 * 0.6, 0.6 * 0.0016);
  run(0.5);
  EXPECT_DOUBLE_EQ(sink.last.steer(), 0.6);
  // Released: back to the centre at 3 locks per second.
  Key(SDL_SCANCODE_A, false);
  run(0.2);
  EXPECT_NEAR(sink.last.steer(), 0.6 * 0.4, 0.6 * 0.0031);
  run(0.2);
  EXPECT_EQ(sink.last.steer(), 0.0);

  // At 60 km/h a held key asks for at most 7 m/s^2: gamma = a L / v^2 = 7 * 2.7 / 16.67^2.
  feed.SetSpeedKmh(60);
  Key(SDL_SCANCODE_RIGHT, true);
  run(1.0);
  const double v = 60 / 3.6;
  EXPECT_NEAR(sink.last.steer(), -7.0 * 2.7 / (v * v), 1e-9);
  Key(SDL_SCANCODE_RIGHT, false);
  run(1.0);
  EXPECT_EQ(sink.last.steer(), 0.0);

  // Brake, paddles, cruise on at the current speed, e-stop key.
  Key(SDL_SCANCODE_E, true);
  run(0.01);
  EXPECT_EQ(sink.last.buttons() & pb::BUTTON_PADDLE_RIGHT,
            static_cast<std::uint32_t>(pb::BUTTON_PADDLE_RIGHT));
  Key(SDL_SCANCODE_E, false);
  run(0.01);
  // 1st at 60 km/h would over-rev the full model's engine: refused, automatic stays (issue 31).
  EXPECT_EQ(sink.last.gear(), 0);
  Key(SDL_SCANCODE_C, true);
  run(0.01);
  Key(SDL_SCANCODE_C, false);
  run(0.01);
  EXPECT_TRUE(sink.last.cruise_on());
  EXPECT_EQ(sink.last.cruise_set_kmh(), 60.0);
  Key(SDL_SCANCODE_DOWN, true);
  run(0.2);
  EXPECT_NEAR(sink.last.brake(), 0.6, 0.0031);
  EXPECT_FALSE(sink.last.cruise_on());  // braking cancels it
  Key(SDL_SCANCODE_DOWN, false);
  {
    testing::ExpectLogs logs;
    Key(SDL_SCANCODE_ESCAPE, true);
    run(0.01);
  }
  EXPECT_TRUE(rig.builder().estop());
  EXPECT_EQ(sink.last.buttons() & pb::BUTTON_ESTOP, static_cast<std::uint32_t>(pb::BUTTON_ESTOP));
  Key(SDL_SCANCODE_ESCAPE, false);
  Key(SDL_SCANCODE_F2, true);
  run(0.01);
  EXPECT_FALSE(rig.builder().estop());

  // A key held when the window loses the keyboard is released.
  Key(SDL_SCANCODE_W, true);
  run(0.5);
  EXPECT_EQ(sink.last.throttle(), 1.0);
  SDL_Event focus{};
  focus.type = SDL_WINDOWEVENT;
  focus.window.event = SDL_WINDOWEVENT_FOCUS_LOST;
  focus.window.windowID = rig.window()->window_id();
  SDL_PushEvent(&focus);
  run(0.3);
  EXPECT_EQ(sink.last.throttle(), 0.0);
}

// --- force feedback ----------------------------------------------------------------------------

class Ffb : public ::testing::Test {
 protected:
  Ffb() {
    p_.peak_torque_nm = 8.0;
    p_.cap_nm = 4.0;
    p_.gain = 1.0;
    p_.filter_hz = 40.0;
    p_.slew_nm_per_s = 200.0;
  }
  FfbInput State(double torque, MonoTime received, std::uint64_t step = 1) {
    FfbInput in;
    in.has_state = true;
    in.torque_nm = torque;
    in.received = received;
    in.step = step;
    return in;
  }
  // Updates at 500 Hz for `seconds` with a state that is always fresh.
  FfbOutput Run(ForceFeedback& f, double torque, double seconds, bool estop = false) {
    FfbOutput out;
    for (int i = 0; i < static_cast<int>(std::lround(seconds * 500)); ++i) {
      t_ = t_ + Milliseconds(2);
      out = f.Update(t_, State(torque, t_, ++step_), estop);
    }
    return out;
  }
  FfbParams p_;
  RecordingHaptic dev_;
  MonoTime t_{1'000'000'000};
  std::uint64_t step_ = 0;
};

TEST_F(Ffb, GainAndCapScaleTheTorqueToTheDevicesPeak) {
  p_.gain = 2.0;
  ForceFeedback f(p_, &dev_);
  // 1.5 N*m from the server at gain 2: 3 N*m played, 3/8 of the device's peak, positive = left.
  FfbOutput out = Run(f, 1.5, 1.0);
  EXPECT_NEAR(out.torque_nm, 3.0, 1e-9);
  EXPECT_NEAR(out.level, 3.0 / 8.0, 1e-9);
  EXPECT_FALSE(out.clipped);
  ASSERT_FALSE(dev_.calls.empty());
  EXPECT_EQ(dev_.calls.back().kind, RecordingHaptic::Call::Kind::kConstant);
  EXPECT_NEAR(dev_.calls.back().value, 3.0 / 8.0, 1e-9);
  // Every update carries the finite effect length.
  for (const auto& c : dev_.calls) EXPECT_EQ(c.length, Milliseconds(100));
  // -3 N*m asks for 6: capped at the user's 4.
  out = Run(f, -3.0, 1.0);
  EXPECT_NEAR(out.torque_nm, -4.0, 1e-9);
  EXPECT_NEAR(out.level, -0.5, 1e-9);
  EXPECT_TRUE(out.clipped);
  // A device weaker than the cap: capped at its peak, level 1.
  p_.peak_torque_nm = 2.5;
  ForceFeedback weak(p_, &dev_);
  out = Run(weak, 3.0, 1.0);
  EXPECT_NEAR(out.torque_nm, 2.5, 1e-9);
  EXPECT_EQ(out.level, 1.0);
  // A device that turns the other way gets the opposite level for the same torque.
  p_.invert = true;
  p_.peak_torque_nm = 8.0;
  p_.gain = 1.0;
  ForceFeedback inv(p_, &dev_);
  out = Run(inv, 2.0, 1.0);
  EXPECT_NEAR(out.torque_nm, 2.0, 1e-9);
  EXPECT_NEAR(out.level, -0.25, 1e-9);
}

TEST_F(Ffb, FilterAndSlewShapeAStep) {
  p_.slew_nm_per_s = 1e4;  // the filter alone first
  ForceFeedback f(p_, &dev_);
  Run(f, 0.0, 0.1);
  // One update 2 ms after a step from 0 to 2 N*m: the first-order filter moves by
  // 1 - exp(-2 pi fc dt) of the step.
  FfbOutput out = Run(f, 2.0, 0.002);
  const double alpha = 1.0 - std::exp(-2.0 * kPi * 40.0 * 0.002);
  EXPECT_NEAR(out.torque_nm, 2.0 * alpha, 1e-12);
  out = Run(f, 2.0, 0.002);
  EXPECT_NEAR(out.torque_nm, 2.0 * (1 - (1 - alpha) * (1 - alpha)), 1e-12);

  // Slow slew: the torque climbs by at most 200 N*m/s * 2 ms = 0.4 N*m per update.
  p_.slew_nm_per_s = 200.0;
  p_.filter_hz = 500.0;
  ForceFeedback s(p_, &dev_);
  Run(s, 0.0, 0.1);
  double last = 0;
  for (int i = 0; i < 20; ++i) {
    out = Run(s, 3.5, 0.002);
    EXPECT_LE(out.torque_nm - last, 0.4 + 1e-12);
    last = out.torque_nm;
  }
  EXPECT_NEAR(last, 3.5, 1e-6);
}

TEST_F(Ffb, AStaleStateFadesThenStopsAndEstopStopsAtOnce) {
  ForceFeedback f(p_, &dev_);
  Run(f, 2.0, 1.0);
  const MonoTime last_state = t_;
  FfbInput in = State(2.0, last_state, 999);
  // 20 ms old: still full. Then linear to zero over 100 ms: at 70 ms, half.
  FfbOutput out = f.Update(last_state + Milliseconds(20), in, false);
  EXPECT_NEAR(out.torque_nm, 2.0, 1e-9);
  EXPECT_EQ(out.mode, FfbOutput::Mode::kPlaying);
  out = f.Update(last_state + Milliseconds(70), in, false);
  EXPECT_NEAR(out.torque_nm, 1.0, 1e-9);
  EXPECT_EQ(out.mode, FfbOutput::Mode::kFading);
  out = f.Update(last_state + Milliseconds(120), in, false);
  EXPECT_EQ(out.torque_nm, 0.0);
  EXPECT_EQ(dev_.calls.back().value, 0.0);
  // 250 ms: every effect stopped, once.
  const std::size_t before = dev_.calls.size();
  out = f.Update(last_state + Milliseconds(250), in, false);
  EXPECT_EQ(out.mode, FfbOutput::Mode::kStopped);
  ASSERT_EQ(dev_.calls.size(), before + 1);
  EXPECT_EQ(dev_.calls.back().kind, RecordingHaptic::Call::Kind::kStop);
  f.Update(last_state + Milliseconds(300), in, false);
  EXPECT_EQ(dev_.calls.size(), before + 1);
  // Fresh states again: it plays again (from zero, through the slew limit).
  t_ = last_state + Milliseconds(400);
  out = Run(f, 2.0, 0.5);
  EXPECT_NEAR(out.torque_nm, 2.0, 1e-6);
  // The e-stop: the very update stops everything, and nothing is played while it lasts.
  const std::size_t at_estop = dev_.calls.size();
  out = Run(f, 2.0, 0.1, true);
  EXPECT_EQ(out.mode, FfbOutput::Mode::kEstop);
  ASSERT_EQ(dev_.calls.size(), at_estop + 1);
  EXPECT_EQ(dev_.calls[at_estop].kind, RecordingHaptic::Call::Kind::kStop);
  EXPECT_EQ(dev_.calls[at_estop].at, dev_.calls.back().at);
}

TEST_F(Ffb, TheClippingMeterWarnsAbove2Point5PercentOver10Seconds) {
  std::vector<std::string> warnings;
  auto run_with = [&](int clip_every) {
    warnings.clear();
    ForceFeedback f(p_, &dev_);
    f.on_warning = [&](const std::string& s) { warnings.push_back(s); };
    // 12 s at 500 Hz; one update in `clip_every` asks for 60 N*m (beyond the 4 N*m cap).
    for (int i = 0; i < 6000; ++i) {
      t_ = t_ + Milliseconds(2);
      f.Update(t_, State(i % clip_every == 0 ? 60.0 : 1.0, t_, ++step_), false);
    }
    return f.clip_fraction();
  };
  // A filter this fast (alpha = 0.998 at 2 ms) passes a one-update spike: one update in 25 (4 %)
  // clips, the rest do not.
  p_.filter_hz = 500;
  const double f1 = run_with(25);
  EXPECT_GT(f1, 0.025);
  EXPECT_EQ(warnings.size(), 1u);  // once per window, not every update
  EXPECT_THAT(warnings.front(), HasSubstr("force feedback clips"));
  const double f2 = run_with(50);  // 2 %
  EXPECT_LT(f2, 0.025);
  EXPECT_TRUE(warnings.empty());
}

TEST_F(Ffb, TheDamperActsAtLowSpeedOnly) {
  p_.damper = 0.4;
  p_.damper_below_kmh = 20;
  ForceFeedback f(p_, &dev_);
  FfbInput in = State(0.0, t_);
  in.speed_kmh = 5;  // 1 - 5/20 = 0.75 of the damper
  t_ = t_ + Milliseconds(2);
  in.received = t_;
  FfbOutput out = f.Update(t_, in, false);
  EXPECT_NEAR(out.damper, 0.3, 1e-12);
  bool damper_sent = false;
  for (const auto& c : dev_.calls) {
    if (c.kind == RecordingHaptic::Call::Kind::kDamper) {
      damper_sent = true;
      EXPECT_NEAR(c.value, 0.3, 1e-12);
    }
  }
  EXPECT_TRUE(damper_sent);
  in.speed_kmh = 50;
  t_ = t_ + Milliseconds(2);
  in.received = t_;
  EXPECT_EQ(f.Update(t_, in, false).damper, 0.0);
}

// The whole pipeline inside the rig: the states' torque reaches the wheel's device; an e-stop
// button on the wheel stops it.
TEST_F(SdlTest, RigPlaysTheServersTorqueAndTheEstopButtonStopsIt) {
  SdlContext sdl(false);
  const auto g29 = ReleasedG29();
  VirtualWheel& w = *g29;
  RecordingSink sink;
  FakeFeed feed;
  RigConfig cfg = WheelRigConfig();
  cfg.ffb_params.cap_nm = 4;
  RecordingHaptic* haptic = nullptr;
  RigLoop rig(cfg, sdl, sink, feed, nullptr,
              [&](const WheelDevice&, std::string*) -> std::unique_ptr<HapticDevice> {
                auto h = std::make_unique<RecordingHaptic>();
                haptic = h.get();
                return h;
              });
  rig.Start();
  ASSERT_NE(haptic, nullptr);
  MonoTime t{1'000'000'000};
  feed.st.set_steering_torque(1.25);
  TickWithStates(rig, feed, t, 1000);
  // 500 updates a second at 1 kHz ticks; the G29 table's peak is 2.5 N*m.
  EXPECT_NEAR(static_cast<double>(haptic->calls.size()), 500.0, 2.0);
  EXPECT_NEAR(haptic->calls.back().value, 1.25 / 2.5, 1e-6);
  {
    testing::ExpectLogs logs;
    w.Button(24, true);  // the PS button is the table's e-stop
    t = t + Milliseconds(1);
    feed.received = t;
    ASSERT_TRUE(rig.Tick(t));
    t = t + Milliseconds(1);
    feed.received = t;
    ASSERT_TRUE(rig.Tick(t));
  }
  EXPECT_TRUE(rig.builder().estop());
  EXPECT_EQ(haptic->calls.back().kind, RecordingHaptic::Call::Kind::kStop);
  EXPECT_EQ(sink.last.buttons() & pb::BUTTON_ESTOP, static_cast<std::uint32_t>(pb::BUTTON_ESTOP));
}

// --- the status window -----------------------------------------------------------------------

// Every field at its longest: the largest id, a 64-byte source and device name, a status of two
// lines, full pedals, every button, the largest speed and torque, the e-stop on.
WindowView LongestView(bool keyboard) {
  WindowView v;
  v.mode = keyboard ? "KEYBOARD" : "WHEEL: " + std::string(64, 'W');
  v.status =
      "wheel unplugged: neutral, braking at 0.3 until it is back; plug it in again or "
      "press Ctrl+C to end";
  v.status_alarm = true;
  v.vehicle_id = 4294967295u;
  v.source_id = std::string(64, 's');
  v.have_state = true;
  v.driving = false;
  v.speed_kmh = -399.9;
  v.input.set_steer_mode(pb::STEER_HAND_WHEEL);
  v.input.set_steer(-limits::kHandWheel.hi);
  v.input.set_throttle(1);
  v.input.set_brake(1);
  v.input.set_clutch(1);
  v.input.set_handbrake(1);
  v.input.set_gear(10);
  v.input.set_cruise_on(true);
  v.input.set_cruise_set_kmh(400);
  v.input.set_buttons(0xFFFFFFFFu);
  v.steer_fraction = -1;
  v.hand_angle_deg = -1080;
  v.ffb_present = true;
  v.ffb_torque_nm = -50;
  v.ffb_cap_nm = 50;
  v.ffb_mode = "fading (state late)";
  v.clip_percent = 100;
  v.estop = true;
  v.keyboard_help = keyboard;
  return v;
}

bool Overlap(const SDL_Rect& a, const SDL_Rect& b) {
  return a.x < b.x + b.w && b.x < a.x + a.w && a.y < b.y + b.h && b.y < a.y + a.h;
}

// Before: the CLUTCH and HANDBRK bars reached 24 pixels past the right edge and the e-stop banner
// was cut at "(F2 OR HOLD THE BUTTON 2 S TO RE".
TEST(Window, EverythingDrawnLiesInsideTheWindowAndNothingOverlaps) {
  for (const bool keyboard : {true, false}) {
    SCOPED_TRACE(keyboard ? "keyboard" : "wheel");
    const std::vector<WindowItem> items = LayoutWindow(LongestView(keyboard), StatusWindow::kWidth);
    int bars = 0;
    std::string banner;
    for (std::size_t i = 0; i < items.size(); ++i) {
      const SDL_Rect& b = items[i].box;
      EXPECT_GE(b.x, 0) << items[i].text;
      EXPECT_GE(b.y, 0) << items[i].text;
      EXPECT_LE(b.x + b.w, StatusWindow::kWidth) << items[i].text;
      EXPECT_LE(b.y + b.h, StatusWindow::kHeight) << items[i].text;
      if (items[i].kind == WindowItem::Kind::kBar) ++bars;
      if (items[i].kind == WindowItem::Kind::kFilledBox) {
        // The banner's text lies inside its red box.
        for (const WindowItem& t : items) {
          if (t.kind == WindowItem::Kind::kText && Overlap(t.box, b)) {
            EXPECT_TRUE(t.box.x >= b.x && t.box.x + t.box.w <= b.x + b.w && t.box.y >= b.y &&
                        t.box.y + t.box.h <= b.y + b.h)
                << t.text;
            banner += t.text + " ";
          }
        }
        continue;
      }
      for (std::size_t j = i + 1; j < items.size(); ++j) {
        if (items[j].kind == WindowItem::Kind::kFilledBox) continue;
        EXPECT_FALSE(Overlap(b, items[j].box)) << items[i].text << " | " << items[j].text;
      }
    }
    EXPECT_EQ(bars, 4);  // throttle, clutch, brake, handbrake
    EXPECT_THAT(banner, HasSubstr("EMERGENCY STOP"));
    EXPECT_THAT(banner, HasSubstr(keyboard ? "RE-ARM: F2 " : "HOLD THE E-STOP BUTTON 2 S "));
  }
}

// At rest the speed reads 0.0, not -0.0 (a parked car's speed is a tiny negative number), and no
// other reading shows a minus zero.
TEST(Window, ReadingsAtRestShowNoMinusZero) {
  WindowView v;
  v.have_state = true;
  v.speed_kmh = -0.0004;
  EXPECT_EQ(SpeedText(v), "SPEED    0.0 KM/H");
  v.speed_kmh = -0.0;
  EXPECT_EQ(SpeedText(v), "SPEED    0.0 KM/H");
  v.speed_kmh = -3.25;
  EXPECT_EQ(SpeedText(v), "SPEED   -3.2 KM/H");  // reversing is a real minus
  v.speed_kmh = 70;
  EXPECT_EQ(SpeedText(v), "SPEED   70.0 KM/H");
  v.have_state = false;
  EXPECT_EQ(SpeedText(v), "SPEED   --");

  v.have_state = true;
  v.speed_kmh = -0.0004;
  v.input.set_steer(-1e-6);
  v.hand_angle_deg = -0.2;
  v.ffb_present = true;
  v.ffb_torque_nm = -0.001;
  for (const WindowItem& item : LayoutWindow(v, StatusWindow::kWidth)) {
    EXPECT_THAT(item.text, ::testing::Not(::testing::ContainsRegex("-0(\\.0+)?( |$)")))
        << item.text;
  }
}

// A server that stopped: the window says how long no state has come, in red (it said DRIVING).
TEST(RigWindow, NoStateForTwoSecondsIsSaidInRed) {
  WindowView v;
  v.vehicle_id = 1;
  v.source_id = "rig";
  v.have_state = true;
  v.driving = true;
  auto line = [&v] {
    for (const WindowItem& item : LayoutWindow(v, StatusWindow::kWidth)) {
      if (item.text.rfind("VEHICLE 1", 0) == 0) return item;
    }
    return WindowItem{};
  };
  v.state_age_s = 0.01;
  EXPECT_EQ(line().text, "VEHICLE 1  SOURCE rig  DRIVING");
  v.state_age_s = 3.2;
  const WindowItem gone = line();
  EXPECT_EQ(gone.text, "VEHICLE 1  SOURCE rig  NO STATE FOR 3 S (SERVER GONE?)");
  EXPECT_EQ(gone.color.r, 255);
  EXPECT_EQ(gone.color.g, 90);
}

// The rig loop says once when no state has come for 2 s (the server stopped) and once when states
// come again; it said nothing and its window went on saying DRIVING.
TEST_F(SdlTest, TheRigSaysWhenNoStateHasComeForTwoSeconds) {
  SdlContext sdl(true);
  ASSERT_TRUE(sdl.video()) << sdl.video_error();
  RecordingSink sink;
  FakeFeed feed;
  feed.SetSpeedKmh(30);
  RigConfig cfg;
  cfg.source = RigConfig::Source::kAuto;
  RigLoop rig(cfg, sdl, sink, feed, nullptr);
  rig.Start();
  MonoTime t{1'000'000'000};
  feed.received = t;
  testing::ExpectLogs logs;
  for (int i = 0; i < 1900; ++i) {  // 1.9 s without a new state: nothing said yet
    t = t + Milliseconds(1);
    ASSERT_TRUE(rig.Tick(t));
  }
  EXPECT_EQ(logs.count(), 0);
  for (int i = 0; i < 200; ++i) {
    t = t + Milliseconds(1);
    ASSERT_TRUE(rig.Tick(t));
  }
  EXPECT_EQ(logs.count(), 1);  // the warning, once
  feed.received = t;
  for (int i = 0; i < 100; ++i) {
    t = t + Milliseconds(1);
    feed.received = t;
    ASSERT_TRUE(rig.Tick(t));
  }
  EXPECT_EQ(logs.count(), 1);  // "again" is information, not a warning
}

// --- the commands (commands.h), called as vdyn-input's main calls them -----------------------

// calibrate with a device SDL does not have: exit code 2 (bad input) and the reason, before any
// prompt or device is opened.
TEST_F(SdlTest, CalibrateRefusesADeviceSdlDoesNotHaveWithExitCode2) {
  CalibrateOptions o;
  o.device = 200;
  o.out = (dir_.path() / "never.txt").string();
  const std::atomic<bool> stop{false};
  ::testing::internal::CaptureStderr();
  const int code = Calibrate(o, stop);
  const std::string err = ::testing::internal::GetCapturedStderr();
  EXPECT_EQ(code, 2);
  EXPECT_THAT(err, HasSubstr("no device 200 to calibrate (vdyn-input list shows what SDL sees)"));
  EXPECT_FALSE(std::filesystem::exists(o.out));
}

// play with a maneuver file that is not there: the maneuver's error naming the file (main makes
// it exit code 2), before anything is sent.
TEST(Commands, PlayRefusesAMissingManeuverFileNamingIt) {
  testing::TempDir dir;
  PlayOptions o;
  o.maneuver = (dir.path() / "none.csv").string();
  const std::atomic<bool> stop{false};
  try {
    (void)Play(CommonOptions{}, o, stop);
    ADD_FAILURE() << "a missing maneuver was played";
  } catch (const ManeuverError& e) {
    EXPECT_THAT(e.what(), HasSubstr(o.maneuver + ": no such maneuver file"));
  }
}

// What a person is told when the vehicle to drive is not on the domain: no server, or the
// vehicles that are there and the two ways to go on.
TEST(Commands, WhyNoVehicleNamesTheVehiclesThereAndHowToDriveOne) {
  CommonOptions c;
  c.vehicle_id = 3;
  EXPECT_EQ(WhyNoVehicle(c, {}), "is vdyn-server running?");
  EXPECT_EQ(WhyNoVehicle(c, {1}),
            "vdyn-server there has vehicle 1: drive it with --vehicle-id 1, or start vdyn-server "
            "with --vehicle-ids 1,3");
  EXPECT_EQ(WhyNoVehicle(c, {1, 2}),
            "vdyn-server there has vehicles 1,2: drive one with --vehicle-id 1, or start "
            "vdyn-server with --vehicle-ids 1,2,3");
}

}  // namespace
}  // namespace vdyn::wheel_input
