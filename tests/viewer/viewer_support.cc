#include "viewer_support.h"

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <stdexcept>
#include <vector>

#include <stb_image.h>

#include "vdyn/transport/topics.h"

extern char** environ;

namespace vdyn::testing {

Xvfb::Xvfb(int width, int height) {
  int fds[2];
  if (pipe(fds) != 0) throw std::runtime_error("pipe for Xvfb");
  // The display number comes back on fd 3 once the server accepts connections.
  posix_spawn_file_actions_t fa;
  posix_spawn_file_actions_init(&fa);
  // The read end first: it may be fd 3 itself.
  posix_spawn_file_actions_addclose(&fa, fds[0]);
  posix_spawn_file_actions_adddup2(&fa, fds[1], 3);
  posix_spawn_file_actions_addopen(&fa, 1, "/dev/null", O_WRONLY, 0);
  posix_spawn_file_actions_addopen(&fa, 2, "/dev/null", O_WRONLY, 0);
  const std::string screen = std::to_string(width) + "x" + std::to_string(height) + "x24";
  std::vector<std::string> argv = {"/usr/bin/Xvfb", "-displayfd", "3",   "-screen", "0",
                                   screen,          "-nolisten",  "tcp", "-noreset"};
  std::vector<char*> args;
  for (auto& a : argv) args.push_back(a.data());
  args.push_back(nullptr);
  const int rc = posix_spawn(&pid_, args[0], &fa, nullptr, args.data(), environ);
  posix_spawn_file_actions_destroy(&fa);
  close(fds[1]);
  if (rc != 0) {
    close(fds[0]);
    throw std::runtime_error("cannot start /usr/bin/Xvfb (install xvfb)");
  }
  std::string number;
  pollfd p{fds[0], POLLIN, 0};
  for (int i = 0; i < 200 && number.find('\n') == std::string::npos; ++i) {  // 20 s at most
    if (poll(&p, 1, 100) <= 0) continue;
    char buf[16];
    const ssize_t n = read(fds[0], buf, sizeof buf);
    if (n <= 0) break;
    number.append(buf, static_cast<std::size_t>(n));
  }
  close(fds[0]);
  while (!number.empty() && (number.back() == '\n' || number.back() == ' ')) number.pop_back();
  if (number.empty()) {
    kill(pid_, SIGKILL);
    waitpid(pid_, nullptr, 0);
    throw std::runtime_error("Xvfb did not report its display within 20 s");
  }
  display_ = ":" + number;
}

Xvfb::~Xvfb() {
  if (pid_ > 0) {
    kill(pid_, SIGTERM);
    waitpid(pid_, nullptr, 0);
  }
}

std::array<double, 3> TestCar::Mount(int wheel) {
  const double x = wheel < 2 ? kB : -kC;
  const double y = (wheel % 2 == 0) ? kBl : -kBp;
  return {x, y, kZ};
}

pb::VehicleState MakeState(const TestVehicle& v) {
  pb::VehicleState s;
  s.set_vehicle_id(v.id);
  s.set_server_id(v.server);
  s.set_step(v.step);
  s.set_sim_time_ns(static_cast<std::int64_t>(v.step) * 1'000'000);
  s.set_step_ns(1'000'000);
  const double c = std::cos(v.yaw), sn = std::sin(v.yaw);
  auto set = [](pb::Vec3* out, double x, double y, double z) {
    out->set_x(x);
    out->set_y(y);
    out->set_z(z);
  };
  set(s.mutable_p_wt_w(), v.x, v.y, TestCar::kHeight);
  s.mutable_q_wb()->set_w(std::cos(0.5 * v.yaw));
  s.mutable_q_wb()->set_z(std::sin(0.5 * v.yaw));
  set(s.mutable_rpy(), 0, 0, v.yaw);
  set(s.mutable_v_wt_b(), v.speed, 0, 0);
  set(s.mutable_v_wt_w(), v.speed * c, v.speed * sn, 0);
  s.set_speed_kmh(std::abs(v.speed) * 3.6);
  s.set_da(v.da);
  set(s.mutable_f_wall_w(), v.f_wall[0], v.f_wall[1], v.f_wall[2]);
  for (int w = 0; w < 4; ++w) {
    const auto m = TestCar::Mount(w);
    const double ax = v.x + c * m[0] - sn * m[1], ay = v.y + sn * m[0] + c * m[1];
    const double az = TestCar::kHeight + m[2];
    pb::WheelState* ws = s.add_wheels();
    ws->set_contact(true);
    ws->set_fp(v.wheels[static_cast<std::size_t>(w)].fp);
    ws->set_fh(v.wheels[static_cast<std::size_t>(w)].fh);
    ws->set_fb(v.wheels[static_cast<std::size_t>(w)].fb);
    ws->set_fy(v.wheels[static_cast<std::size_t>(w)].fy);
    ws->set_ls(TestCar::kSpring);
    set(ws->mutable_p_a_w(), ax, ay, az);
    set(ws->mutable_p_b_w(), ax, ay, TestCar::kGround);
    set(ws->mutable_n_w(), 0, 0, 1);
  }
  s.mutable_input()->set_source_id(v.input_source);
  return s;
}

namespace {

// A rectangle [x0, x1] x [y0, y1] at height z as two triangles, appended to a mesh.
void AddRect(pb::Mesh& m, double x0, double y0, double x1, double y1, double z) {
  const auto base = static_cast<std::uint32_t>(m.vertices_size() / 3);
  for (auto [x, y] : {std::pair{x0, y0}, {x1, y0}, {x1, y1}, {x0, y1}}) {
    m.add_vertices(x);
    m.add_vertices(y);
    m.add_vertices(z);
  }
  for (std::uint32_t i : {0u, 1u, 2u, 0u, 2u, 3u}) m.add_indices(base + i);
}

}  // namespace

pb::WorldDescription MakeWorld(const std::string& server, double north_yaw,
                               std::initializer_list<std::uint32_t> vehicles) {
  pb::WorldDescription w;
  w.set_server_id(server);
  w.set_name("test_flat");
  w.set_north_yaw(north_yaw);
  w.set_step_ns(1'000'000);
  pb::Mesh* ground = w.add_meshes();
  ground->set_name("ground");
  ground->set_kind(pb::SURFACE_GROUND);
  for (int i = -4; i < 4; ++i) {
    for (int j = -4; j < 4; ++j)
      AddRect(*ground, 50.0 * i, 50.0 * j, 50.0 * (i + 1), 50.0 * (j + 1), 0.0);
  }
  pb::Mesh* road = w.add_meshes();
  road->set_name("road");
  road->set_kind(pb::SURFACE_ROAD);
  AddRect(*road, -200, -4, 200, 4, TestCar::kGround);
  for (std::uint32_t id : vehicles) {
    pb::VehicleGeometry* g = w.add_vehicles();
    g->set_vehicle_id(id);
    for (int k = 0; k < 4; ++k) {
      const auto m = TestCar::Mount(k);
      pb::Vec3* a = g->add_mount_points_b();
      a->set_x(m[0]);
      a->set_y(m[1]);
      a->set_z(m[2]);
      g->add_wheel_radius(TestCar::kRadius);
      g->add_free_length(0.35);
    }
    g->set_body_front(TestCar::kFront);
    g->set_body_rear(TestCar::kRear);
    g->set_body_half_width(TestCar::kHalfWidth);
  }
  return w;
}

TestPublisher::TestPublisher(std::uint32_t domain)
    : participant_(domain),
      worlds_(participant_, transport::TopicId::kWorld),
      params_(participant_, transport::TopicId::kParams),
      diagnostics_(participant_, transport::TopicId::kDiagnostics),
      states_(participant_, transport::TopicId::kStates),
      inputs_(participant_, transport::TopicId::kInput, 10) {}

bool TestPublisher::World(const pb::WorldDescription& w) {
  return worlds_.Write(transport::ServerKey(w.server_id()), w);
}
bool TestPublisher::State(const pb::VehicleState& s) {
  pb::VehicleStates b;
  *b.add_states() = s;
  return states_.Write(transport::ServerKey(s.server_id()), b);
}
bool TestPublisher::Params(std::uint32_t vehicle_id, const pb::VehicleParams& p) {
  return params_.Write(vehicle_id, p);
}
bool TestPublisher::Diagnostics(const pb::Diagnostics& d) {
  return diagnostics_.Write(transport::ServerKey(d.server_id()), d);
}
bool TestPublisher::Input(std::uint32_t vehicle_id, std::uint32_t buttons) {
  pb::DriverInput in;
  in.set_vehicle_id(vehicle_id);
  in.set_source_id("test-rig");
  in.set_sequence(++input_sequence_);
  in.set_buttons(buttons);
  return inputs_.Write(vehicle_id, in);
}

std::optional<viewer::Image> LoadPng(const std::filesystem::path& path) {
  int w = 0, h = 0, n = 0;
  unsigned char* data = stbi_load(path.c_str(), &w, &h, &n, 4);
  if (data == nullptr) return std::nullopt;
  viewer::Image img;
  img.width = w;
  img.height = h;
  img.rgba.assign(data, data + static_cast<std::size_t>(w) * static_cast<std::size_t>(h) * 4);
  stbi_image_free(data);
  return img;
}

Blob FindColour(const viewer::Image& img, std::uint8_t r, std::uint8_t g, std::uint8_t b,
                int tolerance, Rect region) {
  Blob out;
  double sx = 0, sy = 0;
  const int x1 = std::min(region.x1, img.width), y1 = std::min(region.y1, img.height);
  for (int y = std::max(region.y0, 0); y < y1; ++y) {
    for (int x = std::max(region.x0, 0); x < x1; ++x) {
      const std::uint8_t* p =
          img.rgba.data() + (static_cast<std::size_t>(y) * static_cast<std::size_t>(img.width) +
                             static_cast<std::size_t>(x)) *
                                4;
      if (std::abs(p[0] - r) > tolerance || std::abs(p[1] - g) > tolerance ||
          std::abs(p[2] - b) > tolerance) {
        continue;
      }
      if (out.count == 0) {
        out.min_x = out.max_x = x;
        out.min_y = out.max_y = y;
      }
      ++out.count;
      sx += x + 0.5;
      sy += y + 0.5;
      out.min_x = std::min(out.min_x, x);
      out.max_x = std::max(out.max_x, x);
      out.min_y = std::min(out.min_y, y);
      out.max_y = std::max(out.max_y, y);
    }
  }
  if (out.count > 0) {
    out.cx = sx / out.count;
    out.cy = sy / out.count;
  }
  return out;
}

RegionStats Classify(const viewer::Image& img, Rect region) {
  RegionStats s;
  const int x1 = std::min(region.x1, img.width), y1 = std::min(region.y1, img.height);
  for (int y = std::max(region.y0, 0); y < y1; ++y) {
    for (int x = std::max(region.x0, 0); x < x1; ++x) {
      const std::uint8_t* p =
          img.rgba.data() + (static_cast<std::size_t>(y) * static_cast<std::size_t>(img.width) +
                             static_cast<std::size_t>(x)) *
                                4;
      const int r = p[0], g = p[1], b = p[2];
      const int hi = std::max({r, g, b}), lo = std::min({r, g, b});
      ++s.pixels;
      s.r += r;
      s.g += g;
      s.b += b;
      if (hi - lo <= 16 && hi >= 25 && hi <= 150) ++s.asphalt;
      if (hi - lo <= 30 && lo >= 170) ++s.white;
      if (g > r + 6 && g > b + 20) ++s.grass;
      if (r > 120 && r > 3 * g && r > 3 * b) ++s.red;
    }
  }
  if (s.pixels > 0) {
    s.r /= s.pixels;
    s.g /= s.pixels;
    s.b /= s.pixels;
  }
  return s;
}

std::array<double, 2> MapPixel(double x, double y, double centre_x, double centre_y, double up_yaw,
                               double half_height_m, int width, int height) {
  const double ppm = height / (2.0 * half_height_m);
  const double dx = x - centre_x, dy = y - centre_y;
  const double up = dx * std::cos(up_yaw) + dy * std::sin(up_yaw);
  const double right = dx * std::sin(up_yaw) - dy * std::cos(up_yaw);
  return {0.5 * width + right * ppm, 0.5 * height - up * ppm};
}

}  // namespace vdyn::testing
