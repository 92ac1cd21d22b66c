#include "vdyn/telemetry/convert.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numbers>

namespace vdyn::telemetry {
namespace {

struct V3 {
  double x, y, z;
};

V3 Cross(const V3& a, const V3& b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}

// R_WB v for the unit quaternion q_WB (w first): v + 2w (u x v) + 2 u x (u x v), u = (x, y, z).
V3 Rotate(const pb::Quat& q, const V3& v) {
  const V3 u{q.x(), q.y(), q.z()};
  const V3 c = Cross(u, v);
  const V3 t{2.0 * c.x, 2.0 * c.y, 2.0 * c.z};
  const V3 d = Cross(u, t);
  return {v.x + q.w() * t.x + d.x, v.y + q.w() * t.y + d.y, v.z + q.w() * t.z + d.z};
}

float F(double v) {
  // A non-finite number never reaches a dashboard (the server contains non-finite states; this
  // is the bridge's own guard).
  if (!std::isfinite(v)) return 0.0f;
  return static_cast<float>(v);
}

float Unit(double v) {
  return F(std::clamp(std::isfinite(v) ? v : 0.0, 0.0, 1.0));
}

}  // namespace

double HeadingFromYaw(double yaw_rad) {
  constexpr double kPi = std::numbers::pi;
  // LFS's heading 0 points along +Y, vdyn's yaw 0 along +X; both grow anticlockwise from above.
  double h = std::fmod(yaw_rad - kPi / 2.0 + kPi, 2.0 * kPi);
  if (h < 0.0) h += 2.0 * kPi;
  h -= kPi;
  return h >= kPi ? h - 2.0 * kPi : h;
}

std::int32_t PositionUnits(double m) {
  if (!std::isfinite(m)) return 0;
  const double u = std::round(m * 65536.0);
  constexpr double kLo = static_cast<double>(std::numeric_limits<std::int32_t>::min());
  constexpr double kHi = static_cast<double>(std::numeric_limits<std::int32_t>::max());
  return static_cast<std::int32_t>(std::clamp(u, kLo, kHi));
}

std::uint32_t TimeMs(std::int64_t sim_time_ns) {
  const std::int64_t ms = sim_time_ns / 1'000'000;
  return static_cast<std::uint32_t>(static_cast<std::uint64_t>(ms) & 0xffffffffu);
}

OutSimPack MakeOutSim(const pb::VehicleState& s, std::int32_t id) {
  OutSimPack p;
  p.time_ms = TimeMs(s.sim_time_ns());
  const V3 w_W = Rotate(s.q_wb(), {s.w_wb_b().x(), s.w_wb_b().y(), s.w_wb_b().z()});
  p.ang_vel_x = F(w_W.x);
  p.ang_vel_y = F(w_W.y);
  p.ang_vel_z = F(w_W.z);
  p.heading = F(HeadingFromYaw(s.rpy().z()));
  p.pitch = F(-s.rpy().y());  // vdyn: nose down positive; LFS: nose up positive
  p.roll = F(s.rpy().x());    // both: right side down positive
  p.accel_x = F(s.a_wt_w().x());
  p.accel_y = F(s.a_wt_w().y());
  p.accel_z = F(s.a_wt_w().z());
  p.vel_x = F(s.v_wt_w().x());
  p.vel_y = F(s.v_wt_w().y());
  p.vel_z = F(s.v_wt_w().z());
  p.pos_x = PositionUnits(s.p_wt_w().x());
  p.pos_y = PositionUnits(s.p_wt_w().y());
  p.pos_z = PositionUnits(s.p_wt_w().z());
  p.id = id;
  return p;
}

std::uint8_t GaugeGear(const pb::VehicleState& s) {
  if (s.model() == pb::VEHICLE_MODEL_PAPER) {
    return s.control().throttle() < 0.0 ? kGaugeGearReverse : kGaugeGearFirst;
  }
  const std::int32_t g = s.drivetrain().gear();
  if (g < 0) return kGaugeGearReverse;
  return static_cast<std::uint8_t>(std::min<std::int32_t>(g + 1, 255));
}

OutGaugePack MakeOutGauge(const pb::VehicleState& s, const pb::VehicleParams* params,
                          const GaugeOptions& o) {
  OutGaugePack p;
  p.time_ms = TimeMs(s.sim_time_ns());
  SetText(p.car, sizeof(p.car), o.car.c_str(), false);
  p.flags = kOgKm | kOgBar;  // SI: km/h and bar
  p.gear = GaugeGear(s);
  p.plid = s.vehicle_id() <= 255 ? static_cast<std::uint8_t>(s.vehicle_id()) : 0;
  const auto& v = s.v_wt_w();
  p.speed = F(std::sqrt(v.x() * v.x() + v.y() * v.y() + v.z() * v.z()));
  const bool full = s.model() != pb::VEHICLE_MODEL_PAPER;
  const auto& dt = s.drivetrain();
  p.rpm = full ? F(dt.engine_rpm()) : 0.0f;  // the paper's model has no engine
  // Not modelled: no turbo, temperatures or oil pressure (0); no fuel use, so the tank stays full.
  p.fuel = 1.0f;

  std::uint32_t has = 0, on = 0;
  if (full) {
    has |= Bit(kDlHandbrake) | Bit(kDlNeutral);
    if (s.input().handbrake() > 0.0) on |= Bit(kDlHandbrake);
    if (dt.gear() == 0) on |= Bit(kDlNeutral);
    if (params != nullptr) {
      // ABS and TC lights as LFS means them: on while active, or always when switched off.
      if (params->has_abs()) {
        has |= Bit(kDlAbs);
        bool abs_active = false;
        for (const auto& w : s.wheels()) abs_active = abs_active || w.abs_factor() < 1.0;
        if (!params->abs() || abs_active) on |= Bit(kDlAbs);
      }
      if (params->has_traction_control()) {
        has |= Bit(kDlTc);
        if (!params->traction_control() || dt.tc_factor() < 1.0) on |= Bit(kDlTc);
      }
      if (params->has_shift_up_rpm() && params->shift_up_rpm() > 0.0) {
        has |= Bit(kDlShift);
        if (dt.engine_rpm() >= params->shift_up_rpm()) on |= Bit(kDlShift);
      }
    }
  }
  p.dash_lights = has;
  p.show_lights = on & has;

  // Pedals as applied (the speed control and the watchdog's safe state included); a negative
  // throttle (the paper's model driving backwards) is shown as its magnitude.
  p.throttle = Unit(std::fabs(s.control().throttle()));
  p.brake = Unit(s.control().brake());
  p.clutch = full ? Unit(s.input().clutch()) : 0.0f;

  char text[32];
  if (full) {
    std::snprintf(text, sizeof text, "full %s", dt.automatic() ? "auto" : "manual");
  } else {
    std::snprintf(text, sizeof text, "paper");
  }
  SetText(p.display1, sizeof(p.display1), text, true);
  text[0] = '\0';
  if (s.control().watchdog_safe_state()) {
    std::snprintf(text, sizeof text, "safe state");
  } else if (s.control().cruise_active()) {
    std::snprintf(text, sizeof text, "cruise %.0f km/h",
                  std::clamp(s.input().cruise_set_kmh(), 0.0, 400.0));
  }
  SetText(p.display2, sizeof(p.display2), text, true);
  p.id = o.id;
  return p;
}

}  // namespace vdyn::telemetry
