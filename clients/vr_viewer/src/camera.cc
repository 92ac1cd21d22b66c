#include "vdyn/viewer/camera.h"

#include <algorithm>
#include <cmath>

#include "vdyn/viewer/car_model.h"

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
    case CameraMode::kBeside:
      return "beside";
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

namespace {

Vec3 GroundDir(double yaw) {
  return {std::cos(yaw), std::sin(yaw), 0};
}

// A perspective camera's eye, the point it looks at and its up direction.
struct Rig {
  Vec3 eye, target, up{0, 0, 1};
  double heading = 0;      // of the view, on the ground (the compass)
  bool with_body = false;  // the view's frame is the body's (driver) or turns with it (unlocked)
};

Rig RigFor(const CameraState& c, const CameraScene& s) {
  const Vec3 target = s.followed != nullptr ? s.followed->pose_WB.t : s.fallback_target_W;
  const double vehicle_yaw = s.followed != nullptr ? s.followed->yaw : 0.0;
  const double geo = s.north_yaw + c.geo_turn;
  const Vec3 up{0, 0, 1};
  Rig r;
  switch (c.mode) {
    case CameraMode::kChase: {
      const Vec3 f = GroundDir(vehicle_yaw);
      r.eye = target - f * c.chase_distance + up * c.chase_height;
      r.target = target + up * 0.8;
      r.heading = vehicle_yaw;
      break;
    }
    case CameraMode::kDriver: {
      if (s.followed != nullptr) {
        const Pose& p = s.followed->pose_WB;
        r.eye = p * CabinFor(s.followed->geometry).eyes_B;
        r.target =
            r.eye + p.R.c[0] * std::cos(c.driver_pitch) + p.R.c[2] * std::sin(c.driver_pitch);
        r.up = p.R.c[2];
        r.with_body = true;
      } else {
        r.eye = target + up * 1.2;
        r.target = r.eye + GroundDir(0);
      }
      r.heading = vehicle_yaw;
      break;
    }
    case CameraMode::kOrbit:
    case CameraMode::kMap: {  // (the map's perspective stand-in: a headset's place above)
      const double cp = std::cos(c.orbit_pitch);
      const Vec3 d{cp * std::cos(c.orbit_yaw), cp * std::sin(c.orbit_yaw), std::sin(c.orbit_pitch)};
      r.eye = target + d * c.orbit_distance;
      r.target = target;
      r.heading = std::atan2(-d.y, -d.x);
      if (c.mode == CameraMode::kMap) {
        r.eye = target + up * std::clamp(c.map_half_height, 2.0, 60.0);
        r.target = r.eye + GroundDir(geo);
        r.heading = geo;
      }
      break;
    }
    case CameraMode::kNorth: {
      const Vec3 f = GroundDir(geo);
      r.eye = target - f * c.north_distance + up * c.north_height;
      r.target = target + up * 0.5;
      r.heading = geo;
      break;
    }
    case CameraMode::kBeside: {
      const Vec3 left = GroundDir(vehicle_yaw + kPi / 2);
      const double ground = s.followed != nullptr ? s.followed->ground_z : target.z;
      r.eye = target + left * c.beside_distance;
      r.eye.z = ground + c.eye_height;
      r.target = target;
      r.heading = vehicle_yaw - kPi / 2;
      break;
    }
  }
  // Unlocked, chase and orbit roll and pitch with the body about the vehicle.
  const bool tilts = c.mode == CameraMode::kChase || c.mode == CameraMode::kOrbit;
  if (tilts && !c.horizon_locked && s.followed != nullptr) {
    const Mat3 tilt = Tilt(s.followed->pose_WB, vehicle_yaw);
    r.eye = target + tilt * (r.eye - target);
    r.target = target + tilt * (r.target - target);
    r.up = tilt * r.up;
    r.with_body = true;
  }
  return r;
}

}  // namespace

Mat3 Tilt(const Pose& pose_WB, double yaw) {
  return pose_WB.R * RotationZ(-yaw);
}

CameraView ComputeCamera(const CameraState& c, const CameraScene& s, int width_px, int height_px) {
  const double aspect = static_cast<double>(std::max(width_px, 1)) / std::max(height_px, 1);
  CameraView v;
  v.fovy = c.fovy;
  if (c.mode == CameraMode::kMap) {
    const Vec3 target = s.followed != nullptr ? s.followed->pose_WB.t : s.fallback_target_W;
    const double geo = s.north_yaw + c.geo_turn;
    const double height = std::max(s.top_z + 10.0, target.z + 50.0);
    v.eye_W = {target.x, target.y, height};
    v.view = LookAt(v.eye_W, {target.x, target.y, target.z - 1.0}, GroundDir(geo));
    v.heading = geo;
    v.orthographic = true;
    const double hh = std::max(c.map_half_height, 0.5);
    v.proj = Orthographic(hh * aspect, hh, 0.1, height - std::min(s.top_z, target.z) + s.far_m);
    v.metres_per_pixel = 2 * hh / std::max(height_px, 1);
    return v;
  }
  const Rig r = RigFor(c, s);
  v.eye_W = r.eye;
  v.view = LookAt(r.eye, r.target, r.up);
  v.heading = r.heading;
  const double near_m = c.mode == CameraMode::kDriver ? 0.05 : 0.2;
  v.proj = Perspective(c.fovy, aspect, near_m, s.far_m);
  return v;
}

Pose XrPlace(const CameraState& c, const CameraScene& s) {
  const Rig r = RigFor(c, s);
  Pose p;
  p.t = r.eye;
  Vec3 forward = r.target - r.eye, up = r.up;
  if (r.with_body) {
    // The body's frame (driver) or the tilted level frame (unlocked): forward along the look
    // direction within the plane normal to `up`.
    forward = forward - up * Dot(forward, up);
  } else {
    up = {0, 0, 1};
    forward.z = 0;
  }
  forward = Normalized(forward, GroundDir(r.heading));
  const Vec3 right = Normalized(Cross(forward, up), {0, -1, 0});
  up = Cross(right, forward);
  p.R.c[0] = right;
  p.R.c[1] = up;
  p.R.c[2] = -forward;
  return p;
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
