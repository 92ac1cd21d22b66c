// The built-in table of wheels. Where each value comes from:
//  - USB ids: SDL's own wheel list (SDL_joystick.c, SDL_IsJoystickProductWheel), the Linux drivers'
//    id tables (hid-ids.h, hid-universal-pidff, hid-tmff2, hid-fanatecff) as collected by the
//    oversteer project and the linux-steering-wheels compatibility table.
//  - Axes in SDL's order on Linux, which is the order of the evdev ABS codes the driver reports
//    (ABS_X, ABS_Y, ABS_Z, ABS_RX, ABS_RY, ABS_RZ, ...): Logitech's lg4ff wheels and the T300 RS
//    report steering ABS_X, clutch ABS_Y, throttle ABS_Z, brake ABS_RZ (their HID descriptors; the
//    oversteer project remaps the same way); the other drivers throttle ABS_Y, brake ABS_Z, clutch
//    ABS_RZ. Logitech pedals rest at full scale (SDL reads +32767 released).
//  - Rotation ranges: the drivers' default ranges; peak torques: the makers' published figures,
//    rounded up (a peak set too high gives less torque than asked, never more).
//  - Buttons (paddles and the rest) are vdyn's defaults where the layout is widely documented and
//    absent where rims differ; `vdyn-input calibrate` assigns them on any wheel.
#include <algorithm>
#include <initializer_list>
#include <string>
#include <vector>

#include "vdyn/wheel_input/mapping.h"

namespace vdyn::wheel_input {
namespace {

constexpr int kLo = -32768;
constexpr int kHi = 32767;

struct Pedal {
  int axis = -1;
  int rest = kLo;
  int full = kHi;
};

void SetPedal(pb::PedalAxis* out, const Pedal& p) {
  if (p.axis < 0) return;
  out->set_axis(p.axis);
  out->set_rest(p.rest);
  out->set_full(p.full);
  out->set_dead_zone(0.02);
  out->set_gamma(1.0);
}

struct Buttons {
  int paddle_left = -1, paddle_right = -1, cruise_toggle = -1, cruise_up = -1, cruise_down = -1,
      reset = -1, camera = -1, estop = -1, horn = -1;
};

pb::WheelMapping Make(const std::string& name, std::uint16_t vid,
                      std::initializer_list<std::uint16_t> pids, double range_deg, double peak_nm,
                      const Pedal& throttle, const Pedal& brake, const Pedal& clutch,
                      const Buttons& b, const char* source) {
  pb::WheelMapping m;
  m.set_name(name);
  m.set_vendor_id(vid);
  for (auto pid : pids) m.add_product_ids(pid);
  auto* s = m.mutable_steer();
  s->set_axis(0);
  s->set_left(kLo);
  s->set_right(kHi);
  s->set_range_deg(range_deg);
  s->set_dead_zone(0.0);
  SetPedal(m.mutable_throttle(), throttle);
  SetPedal(m.mutable_brake(), brake);
  SetPedal(m.mutable_clutch(), clutch);
  auto* bm = m.mutable_buttons();
  auto set = [](int v, auto setter) {
    if (v >= 0) setter(v);
  };
  set(b.paddle_left, [&](int v) { bm->set_paddle_left(v); });
  set(b.paddle_right, [&](int v) { bm->set_paddle_right(v); });
  set(b.cruise_toggle, [&](int v) { bm->set_cruise_toggle(v); });
  set(b.cruise_up, [&](int v) { bm->set_cruise_up(v); });
  set(b.cruise_down, [&](int v) { bm->set_cruise_down(v); });
  set(b.reset, [&](int v) { bm->set_reset(v); });
  set(b.camera, [&](int v) { bm->set_camera(v); });
  set(b.estop, [&](int v) { bm->set_estop(v); });
  set(b.horn, [&](int v) { bm->set_horn(v); });
  m.mutable_ffb()->set_peak_torque_nm(peak_nm);
  m.mutable_ffb()->set_invert(false);
  m.set_source(source);
  return m;
}

std::vector<pb::WheelMapping> BuildTable() {
  // Logitech lg4ff wheels: clutch 1, throttle 2, brake 3, resting at full scale.
  const Pedal lg_throttle{2, kHi, kLo}, lg_brake{3, kHi, kLo}, lg_clutch{1, kHi, kLo};
  // Logitech HID++ wheels (G920, G923 Xbox): throttle 1, brake 2, clutch 3, resting at full scale.
  const Pedal hpp_throttle{1, kHi, kLo}, hpp_brake{2, kHi, kLo}, hpp_clutch{3, kHi, kLo};
  // The generic layout (hid-pidff, hid-tmff2 except the T300, hid-fanatecff): throttle 1,
  // brake 2, clutch 3, resting at the low end.
  const Pedal std_throttle{1}, std_brake{2}, std_clutch{3};
  const Pedal none{};
  // The G29's buttons (lg4ff, PS3 mode): 4/5 the right/left paddles, 8 Share, 9 Options,
  // 11 L3, 19/20 plus/minus, 23 Enter (the red dial's press), 24 the PS button.
  const Buttons g29{5, 4, 23, 19, 20, 9, 8, 24, 11};
  const Buttons logitech_paddles{.paddle_left = 5, .paddle_right = 4};
  const Buttons tm_paddles{.paddle_left = 1, .paddle_right = 0};
  const Buttons none_b{};
  const char* lg4ff =
      "ids: SDL wheel list, hid-lg4ff; axes: lg4ff HID descriptor (clutch ABS_Y, throttle ABS_Z, "
      "brake ABS_RZ), pedals rest at full scale";
  const char* hidpp =
      "ids: SDL wheel list, hid-logitech-hidpp; axes: throttle ABS_Y, brake ABS_Z, "
      "clutch ABS_RZ, pedals rest at full scale";
  const char* tmff2 =
      "ids: SDL wheel list, hid-tmff2; axes: throttle ABS_Y, brake ABS_Z, clutch "
      "ABS_RZ; paddles buttons 0 (right) and 1 (left)";
  const char* fanatec =
      "ids: hid-fanatecff, oversteer; axes: throttle ABS_Y, brake ABS_Z, clutch "
      "ABS_RZ; rim buttons differ: calibrate";
  const char* pidff =
      "ids: hid-universal-pidff; pedals connected to the base: throttle ABS_Y, "
      "brake ABS_Z, clutch ABS_RZ; rim buttons differ: calibrate";
  const char* simucube =
      "ids: Simucube developer docs, linux-steering-wheels; the base has no "
      "pedal inputs: calibrate with --pedals for a USB pedal set";
  std::vector<pb::WheelMapping> t;
  t.push_back(Make("Logitech G25", 0x046d, {0xc299}, 900, 2.5, lg_throttle, lg_brake, lg_clutch,
                   logitech_paddles, lg4ff));
  t.push_back(Make("Logitech G27", 0x046d, {0xc29b}, 900, 2.5, lg_throttle, lg_brake, lg_clutch,
                   logitech_paddles, lg4ff));
  t.push_back(Make("Logitech G29", 0x046d, {0xc24f, 0xc260}, 900, 2.5, lg_throttle, lg_brake,
                   lg_clutch, g29, lg4ff));
  t.push_back(Make("Logitech G923 (PlayStation/PC)", 0x046d, {0xc266, 0xc267}, 900, 2.5,
                   lg_throttle, lg_brake, lg_clutch, g29, lg4ff));
  t.push_back(Make("Logitech G920", 0x046d, {0xc261, 0xc262}, 900, 2.5, hpp_throttle, hpp_brake,
                   hpp_clutch, logitech_paddles, hidpp));
  t.push_back(Make("Logitech G923 (Xbox/PC)", 0x046d, {0xc26d, 0xc26e}, 900, 2.5, hpp_throttle,
                   hpp_brake, hpp_clutch, logitech_paddles, hidpp));
  t.push_back(Make("Thrustmaster T150", 0x044f, {0xb677}, 1080, 2.5, std_throttle, std_brake,
                   std_clutch, tm_paddles, tmff2));
  t.push_back(Make("Thrustmaster TMX", 0x044f, {0xb67f}, 900, 2.5, std_throttle, std_brake,
                   std_clutch, tm_paddles, tmff2));
  // The T300 RS reports its pedals in the Logitech order; the T-GT II enumerates with its ids.
  t.push_back(Make("Thrustmaster T300 RS / T-GT II", 0x044f, {0xb66e, 0xb66f, 0xb66d}, 1080, 6.0,
                   Pedal{2}, Pedal{3}, Pedal{1}, tm_paddles,
                   "ids: SDL wheel list, hid-tmff2 (the T-GT II reuses the T300 RS ids); axes: "
                   "clutch ABS_Y, throttle ABS_Z, brake ABS_RZ"));
  t.push_back(Make("Thrustmaster T248", 0x044f, {0xb696}, 900, 4.0, std_throttle, std_brake,
                   std_clutch, tm_paddles, tmff2));
  t.push_back(Make("Fanatec CSL DD / GT DD Pro / ClubSport DD", 0x0eb7, {0x0020}, 1080, 8.0,
                   std_throttle, std_brake, std_clutch, none_b, fanatec));
  t.push_back(Make("Fanatec ClubSport Wheel Base V2", 0x0eb7, {0x0001}, 900, 8.0, std_throttle,
                   std_brake, std_clutch, none_b, fanatec));
  t.push_back(Make("Fanatec ClubSport Wheel Base V2.5", 0x0eb7, {0x0004}, 900, 8.0, std_throttle,
                   std_brake, std_clutch, none_b, fanatec));
  t.push_back(Make("Fanatec CSL Elite", 0x0eb7, {0x0e03, 0x0005}, 1080, 6.0, std_throttle,
                   std_brake, std_clutch, none_b, fanatec));
  t.push_back(Make("Moza R5", 0x346e, {0x0004, 0x0014}, 900, 5.5, std_throttle, std_brake,
                   std_clutch, none_b, pidff));
  t.push_back(Make("Moza R9", 0x346e, {0x0002, 0x0012}, 900, 9.0, std_throttle, std_brake,
                   std_clutch, none_b, pidff));
  t.push_back(Make("Moza R12", 0x346e, {0x0006, 0x0016}, 900, 12.0, std_throttle, std_brake,
                   std_clutch, none_b, pidff));
  t.push_back(
      Make("Simucube 2 Sport", 0x16d0, {0x0d61}, 900, 17.0, none, none, none, none_b, simucube));
  t.push_back(
      Make("Simucube 2 Pro", 0x16d0, {0x0d60}, 900, 25.0, none, none, none, none_b, simucube));
  t.push_back(
      Make("Simucube 2 Ultimate", 0x16d0, {0x0d5f}, 900, 32.0, none, none, none, none_b, simucube));
  // The paper's wheel: an Xbox 360 wheel without force feedback (xpad): steering on the left
  // stick's X, brake and throttle on the left and right triggers, paddles on the shoulder buttons.
  t.push_back(Make("Thrustmaster Ferrari 458 Italia", 0x24c6, {0x5b00}, 240, 0.0, Pedal{5},
                   Pedal{2}, none, Buttons{.paddle_left = 4, .paddle_right = 5},
                   "ids: SDL controller list, oversteer; axes: xpad (steer ABS_X, brake ABS_Z, "
                   "throttle ABS_RZ); no force feedback"));
  return t;
}

}  // namespace

std::span<const pb::WheelMapping> BuiltinWheels() {
  static const std::vector<pb::WheelMapping> table = BuildTable();
  return table;
}

const pb::WheelMapping* FindBuiltinWheel(std::uint16_t vendor_id, std::uint16_t product_id) {
  for (const auto& m : BuiltinWheels()) {
    if (m.vendor_id() != vendor_id) continue;
    const auto& ids = m.product_ids();
    if (std::find(ids.begin(), ids.end(), product_id) != ids.end()) return &m;
  }
  return nullptr;
}

pb::WheelMapping GenericWheel(std::uint16_t vendor_id, std::uint16_t product_id, int axes) {
  // No peak torque is known: force feedback stays off until a mapping file or --ffb-peak-nm
  // gives one.
  return Make("unknown wheel " + VidPid(vendor_id, product_id), vendor_id, {product_id}, 900, 0.0,
              axes > 1 ? Pedal{1} : Pedal{}, axes > 2 ? Pedal{2} : Pedal{}, Pedal{}, Buttons{},
              "generic: not in the table; run vdyn-input calibrate");
}

}  // namespace vdyn::wheel_input
