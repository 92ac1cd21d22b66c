// Helpers for the viewer's tests: a private X server (Xvfb + Mesa's llvmpipe), a test publisher
// that writes worlds, parameters, states and driver inputs on a fresh loopback domain, the states
// it writes (built from a pose and chosen forces, as a server would report them), and screenshot
// analysis: pixels of a colour, their extent and centroid.
#pragma once

#include <sys/types.h>

#include <array>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>

#include "vdyn/diagnostics.pb.h"
#include "vdyn/input.pb.h"
#include "vdyn/state.pb.h"
#include "vdyn/transport/dds.h"
#include "vdyn/vehicle_params.pb.h"
#include "vdyn/viewer/renderer.h"
#include "vdyn/world.pb.h"

namespace vdyn::testing {

// An Xvfb of its own (display number chosen by the server: -displayfd), killed at the end.
class Xvfb {
 public:
  explicit Xvfb(int width = 1280, int height = 800);
  ~Xvfb();
  Xvfb(const Xvfb&) = delete;
  Xvfb& operator=(const Xvfb&) = delete;
  const std::string& display() const { return display_; }  // ":N"

 private:
  pid_t pid_ = -1;
  std::string display_;
};

// The geometry the tests give their vehicles (the server's default car): mount points A in the
// body frame, wheel radius, spring length.
struct TestCar {
  static constexpr double kB = 1.2, kC = 1.5, kBl = 0.78, kBp = 0.78, kZ = -0.02;
  static constexpr double kRadius = 0.32, kSpring = 0.25;
  static constexpr double kFront = 2.2, kRear = 2.5, kHalfWidth = 0.9;
  // The test world's road surface (the vehicles stand on it), and the height of T.
  static constexpr double kGround = 0.02;
  static constexpr double kHeight = kGround - kZ + kSpring + kRadius;
  static std::array<double, 3> Mount(int wheel);  // LF, RF, LR, RR
};

struct WheelForces {
  double fp = 3500, fh = 0, fb = 0, fy = 0;
};

// A vehicle standing (or rolling at `speed` along its heading) on flat ground at z = 0.
struct TestVehicle {
  std::uint32_t id = 1;
  std::string server = "test";
  double x = 0, y = 0, yaw = 0;  // m, m, rad
  double speed = 0;              // m/s along the heading
  std::uint64_t step = 1;
  std::array<WheelForces, 4> wheels{};
  double da = 0;                          // drag, N
  std::array<double, 3> f_wall{0, 0, 0};  // N
  std::string input_source = "test-rig";
};
pb::VehicleState MakeState(const TestVehicle& v);

// Flat ground 400 m x 400 m around the origin (SURFACE_GROUND, z = 0) and an 8 m road along X at
// y = 0 (SURFACE_ROAD, at TestCar::kGround), with the geometry of `vehicles` test cars.
pb::WorldDescription MakeWorld(const std::string& server, double north_yaw,
                               std::initializer_list<std::uint32_t> vehicles = {1});

class TestPublisher {
 public:
  explicit TestPublisher(std::uint32_t domain);
  bool World(const pb::WorldDescription& w);
  bool State(const pb::VehicleState& s);
  bool Params(std::uint32_t vehicle_id, const pb::VehicleParams& p);
  // A server's diagnostics, as its publisher writes them once a window.
  bool Diagnostics(const pb::Diagnostics& d);
  // Driver input with the next sequence number.
  bool Input(std::uint32_t vehicle_id, std::uint32_t buttons);
  transport::Participant& participant() { return participant_; }
  transport::RawWriter& state_writer() { return states_; }
  transport::RawWriter& input_writer() { return inputs_; }

 private:
  transport::Participant participant_;
  transport::Writer<pb::WorldDescription> worlds_;
  transport::Writer<pb::VehicleParams> params_;
  transport::Writer<pb::Diagnostics> diagnostics_;
  transport::RawWriter
      states_;  // vdyn/states, a state a sample: a viewer reads every vehicle there
  transport::Writer<pb::DriverInput> inputs_;
  std::uint64_t input_sequence_ = 0;
};

// --- screenshots ---------------------------------------------------------------------------

std::optional<viewer::Image> LoadPng(const std::filesystem::path& path);

struct Rect {
  int x0 = 0, y0 = 0, x1 = 1 << 30, y1 = 1 << 30;  // [x0, x1) x [y0, y1)
};

// The pixels within `tolerance` (per channel) of a colour.
struct Blob {
  int count = 0;
  double cx = 0, cy = 0;  // centroid, pixels
  int min_x = 0, max_x = 0, min_y = 0, max_y = 0;
};
Blob FindColour(const viewer::Image& img, std::uint8_t r, std::uint8_t g, std::uint8_t b,
                int tolerance, Rect region = {});

// Pixels of a region that a test classifies, and their mean colour (sRGB, 0..255).
struct RegionStats {
  int pixels = 0;
  int asphalt = 0;  // grey, dark to mid: the road's asphalt
  int grass = 0;    // green over red and blue: the ground's grass
  int white = 0;    // bright and grey: markings, white kerb blocks
  int red = 0;      // red kerb blocks
  double r = 0, g = 0, b = 0;
};
RegionStats Classify(const viewer::Image& img, Rect region);

// Where a world point lands on the map camera's image (top-down, orthographic, centred on
// `centre`, the geographic heading `up_yaw` pointing up, `half_height_m` from centre to the top):
// pixel x right, y down. The closed form, independent of the viewer's matrices.
std::array<double, 2> MapPixel(double x, double y, double centre_x, double centre_y, double up_yaw,
                               double half_height_m, int width, int height);

}  // namespace vdyn::testing
