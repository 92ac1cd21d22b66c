#include "vdyn/viewer/math.h"

namespace vdyn::viewer {

Mat3 RotationFromQuat(double w, double x, double y, double z) {
  const double n = std::sqrt(w * w + x * x + y * y + z * z);
  if (!(n > 1e-12)) return Mat3{};
  w /= n;
  x /= n;
  y /= n;
  z /= n;
  Mat3 r;
  r.c[0] = {1 - 2 * (y * y + z * z), 2 * (x * y + w * z), 2 * (x * z - w * y)};
  r.c[1] = {2 * (x * y - w * z), 1 - 2 * (x * x + z * z), 2 * (y * z + w * x)};
  r.c[2] = {2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)};
  return r;
}

Mat3 RotationZ(double yaw) {
  const double c = std::cos(yaw), s = std::sin(yaw);
  Mat3 r;
  r.c[0] = {c, s, 0};
  r.c[1] = {-s, c, 0};
  r.c[2] = {0, 0, 1};
  return r;
}

Mat3 RotationAxisAngle(const Vec3& axis, double angle) {
  const Vec3 a = Normalized(axis);
  const double h = 0.5 * angle, s = std::sin(h);
  return RotationFromQuat(std::cos(h), a.x * s, a.y * s, a.z * s);
}

Mat4 Mat4::operator*(const Mat4& o) const {
  Mat4 r;
  for (int i = 0; i < 4; ++i) {
    for (int j = 0; j < 4; ++j) {
      double s = 0;
      for (int k = 0; k < 4; ++k) s += (*this)(i, k) * o(k, j);
      r(i, j) = s;
    }
  }
  return r;
}

Vec3 Mat4::TransformPoint(const Vec3& p, double* w_out) const {
  const Mat4& a = *this;
  const double x = a(0, 0) * p.x + a(0, 1) * p.y + a(0, 2) * p.z + a(0, 3);
  const double y = a(1, 0) * p.x + a(1, 1) * p.y + a(1, 2) * p.z + a(1, 3);
  const double z = a(2, 0) * p.x + a(2, 1) * p.y + a(2, 2) * p.z + a(2, 3);
  const double w = a(3, 0) * p.x + a(3, 1) * p.y + a(3, 2) * p.z + a(3, 3);
  if (w_out != nullptr) {
    *w_out = w;
    return {x, y, z};
  }
  return w != 0.0 ? Vec3{x / w, y / w, z / w} : Vec3{x, y, z};
}

std::array<float, 16> Mat4::Floats() const {
  std::array<float, 16> f{};
  for (std::size_t i = 0; i < 16; ++i) f[i] = static_cast<float>(m[i]);
  return f;
}

Mat4 FromPose(const Pose& p) {
  Mat4 r;
  for (int col = 0; col < 3; ++col) {
    const Vec3& c = p.R.c[static_cast<std::size_t>(col)];
    r(0, col) = c.x;
    r(1, col) = c.y;
    r(2, col) = c.z;
    r(3, col) = 0;
  }
  r(0, 3) = p.t.x;
  r(1, 3) = p.t.y;
  r(2, 3) = p.t.z;
  r(3, 3) = 1;
  return r;
}

Mat4 Inverse(const Mat4& a) {
  // Gauss-Jordan with partial pivoting on [a | I].
  double m[4][8];
  for (int i = 0; i < 4; ++i) {
    for (int j = 0; j < 4; ++j) {
      m[i][j] = a(i, j);
      m[i][j + 4] = i == j ? 1.0 : 0.0;
    }
  }
  for (int col = 0; col < 4; ++col) {
    int pivot = col;
    for (int r = col + 1; r < 4; ++r) {
      if (std::abs(m[r][col]) > std::abs(m[pivot][col])) pivot = r;
    }
    if (std::abs(m[pivot][col]) < 1e-300) return Mat4{};
    if (pivot != col) {
      for (int j = 0; j < 8; ++j) std::swap(m[col][j], m[pivot][j]);
    }
    const double inv = 1.0 / m[col][col];
    for (int j = 0; j < 8; ++j) m[col][j] *= inv;
    for (int r = 0; r < 4; ++r) {
      if (r == col) continue;
      const double f = m[r][col];
      if (f == 0.0) continue;
      for (int j = 0; j < 8; ++j) m[r][j] -= f * m[col][j];
    }
  }
  Mat4 r;
  for (int i = 0; i < 4; ++i) {
    for (int j = 0; j < 4; ++j) r(i, j) = m[i][j + 4];
  }
  return r;
}

Mat4 LookAt(const Vec3& eye, const Vec3& target, const Vec3& up) {
  const Vec3 f = Normalized(target - eye);
  Vec3 s = Cross(f, up);
  if (Norm(s) < 1e-9) s = Cross(f, Vec3{0, 1, 0});  // looking along `up`
  if (Norm(s) < 1e-9) s = Cross(f, Vec3{1, 0, 0});
  s = Normalized(s);
  const Vec3 u = Cross(s, f);
  Mat4 r;
  r(0, 0) = s.x;
  r(0, 1) = s.y;
  r(0, 2) = s.z;
  r(1, 0) = u.x;
  r(1, 1) = u.y;
  r(1, 2) = u.z;
  r(2, 0) = -f.x;
  r(2, 1) = -f.y;
  r(2, 2) = -f.z;
  r(0, 3) = -Dot(s, eye);
  r(1, 3) = -Dot(u, eye);
  r(2, 3) = Dot(f, eye);
  return r;
}

Mat4 Perspective(double fovy_rad, double aspect, double near_m, double far_m) {
  const double t = std::tan(0.5 * fovy_rad);
  return PerspectiveFov(-std::atan(t * aspect), std::atan(t * aspect), std::atan(t), -std::atan(t),
                        near_m, far_m);
}

Mat4 PerspectiveFov(double angle_left, double angle_right, double angle_up, double angle_down,
                    double near_m, double far_m) {
  const double l = std::tan(angle_left), r = std::tan(angle_right);
  const double u = std::tan(angle_up), d = std::tan(angle_down);
  Mat4 p;
  p.m.fill(0.0);
  p(0, 0) = 2.0 / (r - l);
  p(0, 2) = (r + l) / (r - l);
  p(1, 1) = 2.0 / (u - d);
  p(1, 2) = (u + d) / (u - d);
  p(2, 2) = -(far_m + near_m) / (far_m - near_m);
  p(2, 3) = -2.0 * far_m * near_m / (far_m - near_m);
  p(3, 2) = -1.0;
  return p;
}

Mat4 Orthographic(double half_width, double half_height, double near_m, double far_m) {
  Mat4 p;
  p(0, 0) = 1.0 / half_width;
  p(1, 1) = 1.0 / half_height;
  p(2, 2) = -2.0 / (far_m - near_m);
  p(2, 3) = -(far_m + near_m) / (far_m - near_m);
  return p;
}

double WrapAngle(double a) {
  a = std::fmod(a, 2 * kPi);
  if (a <= -kPi) a += 2 * kPi;
  if (a > kPi) a -= 2 * kPi;
  return a;
}

}  // namespace vdyn::viewer
