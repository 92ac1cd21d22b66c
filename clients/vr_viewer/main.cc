// vdyn-viewer: watch a vdyn session - live, or a recording played back by `vdyn-recorder play` -
// on the desktop or in an OpenXR headset (docs in clients/vr_viewer/README.md).
// Exit codes: 0 done, 1 no display / OpenGL / transport failure or an unwritable output, 2 bad
// command line or a car model that cannot be read.
#include <cmath>
#include <csignal>
#include <iostream>

#include <spdlog/spdlog.h>
#include <CLI/CLI.hpp>

#include "vdyn/cli/options.h"
#include "vdyn/viewer/car_model.h"
#include "vdyn/viewer/viewer.h"

namespace {

volatile std::sig_atomic_t g_stop = 0;
extern "C" void OnSignal(int) {
  g_stop = 1;
}

// The command line's values that are not ViewerOptions fields as they are.
struct Choices {
  explicit Choices(const vdyn::viewer::ViewerOptions& o)
      : arrow_m_per_kn(o.arrows.metres_per_newton * 1000.0),
        map_half_height(o.camera.map_half_height),
        delay_ms(static_cast<double>(o.delay_ns) * 1e-6) {}
  std::uint32_t follow = 0;
  std::string camera = "chase";
  double arrow_m_per_kn;
  double paddle_step_deg = 45.0, fov_deg = 60.0;
  double map_half_height;
  std::vector<double> orbit;
  std::string xr_space = "seated";
  std::string quality = "high", car_model;
  std::string horizon = "level";
  double delay_ms;
  bool no_hud = false;
};

void AddOptions(CLI::App& app, vdyn::viewer::ViewerOptions& o, Choices& c) {
  namespace cli = vdyn::cli;
  namespace limits = vdyn::limits;
  app.add_option("--domain", o.domain, "DDS domain id")
      ->check(cli::WholeInRange(limits::kDomainId))
      ->capture_default_str();
  app.add_option("--follow", c.follow, "Vehicle to follow (default: the lowest id on the domain)")
      ->check(cli::VehicleId());
  app.add_option("--camera", c.camera,
                 "chase, driver, orbit, map, north or beside (default: chase; in a headset the "
                 "driver's seat seated, beside the vehicle standing)")
      ->check(CLI::IsMember({"chase", "driver", "orbit", "map", "north", "beside"}))
      ->capture_default_str();
  app.add_option("--horizon", c.horizon,
                 "Chase and orbit cameras: level (the horizon stays level) or body (they roll "
                 "and pitch with the vehicle); K switches")
      ->check(CLI::IsMember({"level", "body"}))
      ->capture_default_str();
  app.add_option("--delay", c.delay_ms,
                 "Presentation delay, ms: each frame shows the vehicles this long before its "
                 "display time, interpolated between the states around that instant (0: the "
                 "newest state as it arrives)")
      ->check(cli::InRange(limits::kPresentationDelayMs))
      ->capture_default_str();
  app.add_option("--orbit", c.orbit, "Orbit camera: yaw_deg,pitch_deg,distance_m (world frame)")
      ->delimiter(',')
      ->expected(3);
  app.add_option("--map-span", c.map_half_height, "Map camera: metres from the centre to the top")
      ->check(cli::InRange(limits::kMapHalfHeight))
      ->capture_default_str();
  app.add_option("--fov", c.fov_deg, "Vertical field of view of the desktop cameras, deg")
      ->check(cli::InRange(limits::kFovDeg))
      ->capture_default_str();
  app.add_option("--arrow-scale", c.arrow_m_per_kn, "Force arrows: metres per kN")
      ->check(cli::InRange(limits::kArrowScale))
      ->capture_default_str();
  app.add_option("--paddle-step", c.paddle_step_deg,
                 "Turn of the geographic cameras per paddle press or Q/E, deg")
      ->check(cli::InRange(limits::kPaddleStepDeg))
      ->capture_default_str();
  app.add_option("--width", o.width, "Window width, pixels")
      ->check(cli::WholeInRange(limits::kWindowPixels))
      ->capture_default_str();
  app.add_option("--height", o.height, "Window height, pixels")
      ->check(cli::WholeInRange(limits::kWindowPixels))
      ->capture_default_str();
  app.add_option("--msaa", o.samples,
                 "Multisampling of the scene (0: off; default 4, off on a software renderer)")
      ->check(cli::WholeInRange(limits::kSamples));
  app.add_option("--quality", c.quality,
                 "high: sun shadows, clouds, glossy paint; low: none of them, for a slow or "
                 "software renderer")
      ->check(CLI::IsMember({"low", "high"}))
      ->capture_default_str();
  app.add_option("--car-model", c.car_model,
                 "A car body from a glTF/GLB file (+Y up, +Z forward), fitted to each vehicle (one "
                 "that cannot be read: the built-in body)");
  app.add_option("--fps", o.fps, "Frame rate cap, Hz (0: as fast as it draws)")
      ->check(cli::InRange(limits::kViewerFps))
      ->capture_default_str();
  app.add_option("--frames", o.frames,
                 "End after this many frames (counted once the world and the followed vehicle "
                 "are there, or after --wait)")
      ->check(cli::WholeInRange(limits::kFrames));
  app.add_option("--screenshot", o.screenshot, "Write the last frame to this PNG file at the end");
  app.add_option("--wait", o.wait_s,
                 "Seconds to wait for the world and a vehicle before "
                 "counting --frames anyway")
      ->check(cli::InRange(limits::kWaitS))
      ->capture_default_str();
  app.add_option("--stats-out", o.stats_out,
                 "Write frame times, latency and refusal counts here at the end");
  app.add_flag("--hidden", o.hidden, "No window on the screen (drawing is offscreen anyway)");
  app.add_flag("--no-hud", c.no_hud, "Start with the HUD hidden (H shows it)");
  app.add_flag("--landmarks", o.landmarks, "Start with the landmarks shown (M toggles them)");
  app.add_flag("--playback", o.playback, "Label the view PLAYBACK (a player's diagnostics do it)");
  app.add_flag("--xr", o.xr, "Stereo in an OpenXR headset (desktop window when no runtime)");
  app.add_option("--xr-space", c.xr_space,
                 "seated: at the driver's seat; standing: on the ground beside the vehicle")
      ->check(CLI::IsMember({"seated", "standing"}))
      ->capture_default_str();
}

// The choices into the options: 2 for a bad value (said on stderr), else -1.
int ApplyChoices(const CLI::App& app, const Choices& c, vdyn::viewer::ViewerOptions& o) {
  namespace limits = vdyn::limits;
  using vdyn::viewer::Rad;

  if (app.count("--follow") > 0) o.follow = c.follow;
  o.camera.mode = *vdyn::viewer::CameraFromName(c.camera);
  o.camera_chosen = app.count("--camera") > 0;
  o.camera.horizon_locked = c.horizon == "level";
  o.delay_ns = static_cast<std::int64_t>(std::llround(c.delay_ms * 1e6));
  o.camera.paddle_step = Rad(c.paddle_step_deg);
  o.camera.fovy = Rad(c.fov_deg);
  o.camera.map_half_height = c.map_half_height;
  if (c.orbit.size() == 3) {
    for (double v : c.orbit) {
      if (!std::isfinite(v)) {
        std::cerr << "vdyn-viewer: --orbit: numbers must be finite\n";
        return 2;
      }
    }
    if (const std::string why = limits::Check(limits::kCameraDistance, c.orbit[2]); !why.empty()) {
      std::cerr << "vdyn-viewer: --orbit: " << why << "\n";
      return 2;
    }
    o.camera.orbit_yaw = Rad(c.orbit[0]);
    o.camera.orbit_pitch = Rad(std::clamp(c.orbit[1], -89.0, 89.0));
    o.camera.orbit_distance = c.orbit[2];
  }
  o.arrows.metres_per_newton = c.arrow_m_per_kn / 1000.0;
  o.xr_seated = c.xr_space == "seated";
  o.hud = !c.no_hud;
  o.quality = *vdyn::viewer::QualityFromName(c.quality);
  return -1;
}

// A car model from a file, or the built-in body when it cannot be read (a look, not the data).
void UseCarModel(const std::string& path, vdyn::viewer::ViewerOptions& o) {
  if (!path.empty()) {
    try {
      o.car_model =
          std::make_shared<const vdyn::viewer::ModelMesh>(vdyn::viewer::LoadCarModel(path));
      spdlog::info("vdyn-viewer: car model '{}': {} triangles", path, o.car_model->triangles());
    } catch (const vdyn::viewer::CarModelError& e) {
      // A model is a look, not the data: the view goes on with the built-in body.
      std::cerr << "vdyn-viewer: " << e.what() << "; drawing the built-in body instead\n";
    }
  }
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "vdyn-viewer: the world, the vehicles and their force arrows, live or played back, "
      "on the desktop or in an OpenXR headset"};
  vdyn::viewer::ViewerOptions o;
  Choices c(o);
  AddOptions(app, o, c);
  if (const int code = vdyn::cli::Parse(app, argc, argv); code >= 0) return code;
  if (const int code = ApplyChoices(app, c, o); code >= 0) return code;
  UseCarModel(c.car_model, o);

  std::signal(SIGINT, OnSignal);
  std::signal(SIGTERM, OnSignal);
  try {
    vdyn::viewer::Viewer viewer(o);
    while (!g_stop && viewer.Frame()) {
    }
    if (g_stop) spdlog::info("vdyn-viewer: stopped by a signal");
    return viewer.Finish();
  } catch (const std::exception& e) {
    std::cerr << "vdyn-viewer: " << e.what() << "\n";
    return 1;
  }
}
