// Small 3D math for the viewer: double-precision vectors, rotations and 4x4 transforms on the CPU
// (positions come from the state in metres, world frame W: X east, Y north, Z up), converted to
// float only when handed to OpenGL. Matrices are column-major, as OpenGL reads them, and act on
// column vectors: p_A = M_AB * p_B.
#pragma once

#include <array>
#include <cmath>

namespace vdyn::viewer {

struct Vec3 {
  double x = 0, y = 0, z = 0;
  constexpr Vec3 operator+(const Vec3& o) const { return {x + o.x, y + o.y, z + o.z}; }
  constexpr Vec3 operator-(const Vec3& o) const { return {x - o.x, y - o.y, z - o.z}; }
  constexpr Vec3 operator-() const { return {-x, -y, -z}; }
  constexpr Vec3 operator*(double s) const { return {x * s, y * s, z * s}; }
  constexpr Vec3 operator/(double s) const { return {x / s, y / s, z / s}; }
  Vec3& operator+=(const Vec3& o) { return *this = *this + o; }
  Vec3& operator-=(const Vec3& o) { return *this = *this - o; }
};
constexpr Vec3 operator*(double s, const Vec3& v) {
  return v * s;
}
constexpr double Dot(const Vec3& a, const Vec3& b) {
  return a.x * b.x + a.y * b.y + a.z * b.z;
}
constexpr Vec3 Cross(const Vec3& a, const Vec3& b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
inline double Norm(const Vec3& v) {
  return std::sqrt(Dot(v, v));
}
// v / |v|, or `fallback` for a (near) zero vector.
inline Vec3 Normalized(const Vec3& v, const Vec3& fallback = {1, 0, 0}) {
  const double n = Norm(v);
  return n > 1e-12 ? v / n : fallback;
}

// 3x3 rotation, column-major: c[0] is the image of X.
struct Mat3 {
  std::array<Vec3, 3> c{Vec3{1, 0, 0}, Vec3{0, 1, 0}, Vec3{0, 0, 1}};
  Vec3 operator*(const Vec3& v) const { return c[0] * v.x + c[1] * v.y + c[2] * v.z; }
  Mat3 operator*(const Mat3& o) const { return {{*this * o.c[0], *this * o.c[1], *this * o.c[2]}}; }
  Mat3 Transposed() const {
    return {
        {Vec3{c[0].x, c[1].x, c[2].x}, Vec3{c[0].y, c[1].y, c[2].y}, Vec3{c[0].z, c[1].z, c[2].z}}};
  }
};
// Rotation of a unit quaternion (w, x, y, z); a non-unit one is normalised first.
Mat3 RotationFromQuat(double w, double x, double y, double z);
Mat3 RotationZ(double yaw);
Mat3 RotationAxisAngle(const Vec3& axis, double angle);

// Rigid transform p_A = R * p_B + t.
struct Pose {
  Mat3 R;
  Vec3 t;
  Vec3 operator*(const Vec3& p) const { return R * p + t; }
  Pose operator*(const Pose& o) const { return {R * o.R, R * o.t + t}; }
  Pose Inverse() const {
    const Mat3 Rt = R.Transposed();
    return {Rt, -(Rt * t)};
  }
};

struct Mat4 {
  std::array<double, 16> m{1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
  double& operator()(int row, int col) { return m[static_cast<std::size_t>(col * 4 + row)]; }
  double operator()(int row, int col) const { return m[static_cast<std::size_t>(col * 4 + row)]; }
  Mat4 operator*(const Mat4& o) const;
  // Homogeneous transform of a point; w is returned through `w_out` when given.
  Vec3 TransformPoint(const Vec3& p, double* w_out = nullptr) const;
  std::array<float, 16> Floats() const;
};
Mat4 FromPose(const Pose& p);
Mat4 Inverse(const Mat4& a);  // general 4x4 inverse (identity when singular)

// View matrix of a camera at `eye` looking at `target`, `up` roughly up: the camera frame has X
// right, Y up and looks along -Z (OpenGL's eye space).
Mat4 LookAt(const Vec3& eye, const Vec3& target, const Vec3& up);
// OpenGL clip-space projections (depth -1..1).
Mat4 Perspective(double fovy_rad, double aspect, double near_m, double far_m);
// From the four half-angles of a field of view (left and down negative), as OpenXR gives them.
Mat4 PerspectiveFov(double angle_left, double angle_right, double angle_up, double angle_down,
                    double near_m, double far_m);
Mat4 Orthographic(double half_width, double half_height, double near_m, double far_m);

constexpr double kPi = 3.14159265358979323846;
constexpr double Deg(double rad) {
  return rad * 180.0 / kPi;
}
constexpr double Rad(double deg) {
  return deg * kPi / 180.0;
}
// An angle in (-pi, pi].
double WrapAngle(double a);

}  // namespace vdyn::viewer
