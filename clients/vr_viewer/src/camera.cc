#include "vdyn/viewer/camera.h"

#include <algorithm>
#include <cmath>

namespace vdyn::viewer {

std::string_view CameraName(CameraMode m) {
  switch (m) {
    case CameraMode::kChase:
      return "chase";
    case CameraMode::kDriver:
      return "driver";
    case CameraMode::kOrbit:
      return "orbit";
    case CameraMode::kMap:
      return "map";
    case CameraMode::kNorth:
      return "north";
  }
  return "?";
}

std::optional<CameraMode> CameraFromName(std::string_view name) {
  for (int i = 0; i < kCameraModes; ++i) {
    const auto m = static_cast<CameraMode>(i);
    if (CameraName(m) == name) return m;
  }
  return std::nullopt;
}

CameraView ComputeCamera(const CameraState& c, const CameraScene& s, int width_px, int height_px) {
  const double aspect = static_cast<double>(std::max(width_px, 1)) / std::max(height_px, 1);
  const Vec3 target = s.followed != nullptr ? s.followed->pose_WB.t : s.fallback_target_W;
  const double vehicle_yaw = s.followed != nullptr ? s.followed->yaw : 0.0;
  const double geo = s.north_yaw + c.geo_turn;
  const Vec3 up{0, 0, 1};
  CameraView v;
  v.fovy = c.fovy;
  const double near_m = c.mode == CameraMode::kDriver ? 0.05 : 0.2;
  auto ground_dir = [](double yaw) { return Vec3{std::cos(yaw), std::sin(yaw), 0}; };
  switch (c.mode) {
    case CameraMode::kChase: {
      const Vec3 f = ground_dir(vehicle_yaw);
      v.eye_W = target - f * c.chase_distance + up * c.chase_height;
      v.view = LookAt(v.eye_W, target + up * 0.8, up);
      v.heading = vehicle_yaw;
      break;
    }
    case CameraMode::kDriver: {
      if (s.followed != nullptr) {
        const Pose& p = s.followed->pose_WB;
        v.eye_W = p * c.seat_B;
        v.view = LookAt(v.eye_W, v.eye_W + p.R.c[0], p.R.c[2]);
      } else {
        v.eye_W = target + up * 1.2;
        v.view = LookAt(v.eye_W, v.eye_W + ground_dir(0), up);
      }
      v.heading = vehicle_yaw;
      break;
    }
    case CameraMode::kOrbit: {
      const double cp = std::cos(c.orbit_pitch);
      const Vec3 d{cp * std::cos(c.orbit_yaw), cp * std::sin(c.orbit_yaw), std::sin(c.orbit_pitch)};
      v.eye_W = target + d * c.orbit_distance;
      v.view = LookAt(v.eye_W, target, up);
      v.heading = std::atan2(-d.y, -d.x);
      break;
    }
    case CameraMode::kMap: {
      const double height = std::max(s.top_z + 10.0, target.z + 50.0);
      v.eye_W = {target.x, target.y, height};
      v.view = LookAt(v.eye_W, {target.x, target.y, target.z - 1.0}, ground_dir(geo));
      v.heading = geo;
      v.orthographic = true;
      const double hh = std::max(c.map_half_height, 0.5);
      v.proj = Orthographic(hh * aspect, hh, 0.1, height - std::min(s.top_z, target.z) + s.far_m);
      v.metres_per_pixel = 2 * hh / std::max(height_px, 1);
      return v;
    }
    case CameraMode::kNorth: {
      const Vec3 f = ground_dir(geo);
      v.eye_W = target - f * c.north_distance + up * c.north_height;
      v.view = LookAt(v.eye_W, target + up * 0.5, up);
      v.heading = geo;
      break;
    }
  }
  v.proj = Perspective(c.fovy, aspect, near_m, s.far_m);
  return v;
}

double CompassNorthAngle(double north_yaw, double view_heading) {
  return WrapAngle(north_yaw - view_heading);
}

bool InFrustum(const Mat4& m, const Vec3& c, double radius) {
  // The clip planes are sums and differences of the matrix's rows (Gribb and Hartmann).
  for (int axis = 0; axis < 3; ++axis) {
    for (double sign : {1.0, -1.0}) {
      const double a = m(3, 0) + sign * m(axis, 0), b = m(3, 1) + sign * m(axis, 1);
      const double cc = m(3, 2) + sign * m(axis, 2), d = m(3, 3) + sign * m(axis, 3);
      const double n = std::sqrt(a * a + b * b + cc * cc);
      if (n > 0 && (a * c.x + b * c.y + cc * c.z + d) / n < -radius) return false;
    }
  }
  return true;
}

void TurnGeographic(CameraState& c, int steps_counter_clockwise) {
  c.geo_turn = WrapAngle(c.geo_turn + steps_counter_clockwise * c.paddle_step);
}

}  // namespace vdyn::viewer
