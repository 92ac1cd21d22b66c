// vdyn-viewer: what a person watching a session sees - the world from the server's description,
// every vehicle of the followed vehicle's server with its wheels and force arrows, the cameras,
// the HUD, the legend, the compass and the parameters panel - on the desktop (SDL2 + OpenGL 3.3)
// and, with --xr, in an OpenXR headset. Live and playback look the same: both are the DDS topics.
//
// One Frame() = events; the display slot (the headset's xrWaitFrame, or the frame-rate cap) and
// its display time; DDS samples taken (SessionView) into each vehicle's history; the scene at the
// display time (each vehicle interpolated between the states around it: motion.h); the HUD; drawn
// (into an offscreen target that the window shows and a screenshot reads; with a headset into both
// eyes and the HUD panel); presented; timed. Bad input is refused and counted, never fatal: a
// world that cannot be drawn (CheckWorld), a state that cannot (CheckState; non-finite ones the
// transport already drops), a vehicle geometry that is malformed.
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "vdyn/base/time.h"
#include "vdyn/client/session_view.h"
#include "vdyn/transport/dds.h"
#include "vdyn/viewer/camera.h"
#include "vdyn/viewer/draw_list.h"
#include "vdyn/viewer/labels.h"
#include "vdyn/viewer/motion.h"
#include "vdyn/viewer/renderer.h"
#include "vdyn/viewer/scene.h"

namespace vdyn::viewer {

struct ViewerOptions {
  std::uint32_t domain = 0;
  std::optional<std::uint32_t> follow;  // vehicle id; default: the lowest on the domain
  CameraState camera;
  bool camera_chosen = false;  // --camera given (else a headset starts at its seat or beside)
  ArrowStyle arrows;
  int width = 1280, height = 720;
  int samples = -1;  // multisampling of the scene; -1: 4, or 0 on a software renderer
  Quality quality = Quality::kHigh;  // shadows, clouds, glossy paint (renderer.h)
  // A car model (LoadCarModel) every vehicle gets instead of the built-in body; null: built-in.
  std::shared_ptr<const ModelMesh> car_model;
  double fps = 60;      // frame rate cap; 0: as fast as it draws
  bool hidden = false;  // no window on the screen (headless use: drawn into a target of its own)
  // In a visible window without multisampling (a software renderer's default), the scene and the
  // HUD are drawn straight into the window's back buffer, saving a copy of every frame; else
  // into a target of their own, copied to the window. false: always the latter.
  bool in_window = true;
  bool hud = true;
  // The landmarks (the world's named points): a marker and its name; off by default (key M).
  bool landmarks = false;
  // Headless: after `frames` frames (counted once the world and the followed vehicle are there,
  // or once `wait_s` has passed), write `screenshot` (when set) and end. 0: run until closed.
  std::uint64_t frames = 0;
  std::string screenshot;
  double wait_s = 10;
  std::string stats_out;  // key-value lines at the end: frames, frame times, latency, refusals
  bool playback = false;  // label the HUD PLAYBACK whatever the diagnostics say
  // Each frame shows the vehicles this long before its display time (motion.h); 0: the newest
  // state as it arrives, not interpolated.
  std::int64_t delay_ns = kDefaultPresentationDelayNs;
  // OpenXR: stereo in a headset; without a runtime, the desktop window with a clear message.
  bool xr = false;
  bool xr_seated = true;
  std::string client_id;  // for control requests; default vdyn-viewer-<pid>
};

// Percentiles of a sample (nearest rank), for the stats and benchmarks.
double Percentile(std::vector<double> v, double p);

struct ViewerStats {
  std::uint64_t frames = 0;          // frames drawn
  std::uint64_t counted_frames = 0;  // frames counted towards --frames
  std::uint64_t xr_frames = 0;       // frames submitted to an OpenXR runtime
  std::uint64_t worlds_accepted = 0;
  std::uint64_t worlds_refused = 0;
  std::uint64_t states_refused = 0;  // failed CheckState (non-finite ones: transport drops)
  std::uint64_t paddle_presses = 0;
  std::uint64_t camera_buttons = 0;  // the driver's camera button pressed (the next camera)
  std::string last_refusal;
  std::vector<double> frame_ms;  // work per frame (events to presented), ms
  // The instant a frame shows (publisher's clock) to the frame on the screen, ms: the delay, the
  // transit and the frame's own work.
  std::vector<double> latency_ms;
  std::int64_t last_display_mono_ns = 0;  // the last frame's display time (monotonic clock)
  std::string renderer;                   // GL_RENDERER
  bool drawn_in_window = false;           // the scene drawn straight into the window (in_window)
  std::string xr_status;                  // "off", "runtime '...'", or why it fell back
};

class Viewer {
 public:
  // Opens the window (throws std::runtime_error without a display or GL 3.3) and joins the domain.
  explicit Viewer(ViewerOptions options);
  ~Viewer();
  Viewer(const Viewer&) = delete;
  Viewer& operator=(const Viewer&) = delete;

  // One frame; false when the viewer should end (window closed, Esc, --frames done).
  bool Frame();
  // Frames until the end; the exit code (0; 1 when the screenshot or the stats cannot be written).
  int Run();
  // Writes the screenshot and the stats (as Run does at its end); the exit code.
  int Finish();

  // The last frame as drawn on the desktop (HUD included), rows top down. Drawn in the window
  // (ViewerOptions::in_window), a frame's image is kept only when it ends a `frames` run or F12
  // asked for it: the last such image (empty before the first).
  Image Screenshot() const;
  const ViewerStats& stats() const { return stats_; }
  const ViewerOptions& options() const { return options_; }
  void WriteStats(const std::string& path) const;

  CameraState& camera() { return options_.camera; }
  ArrowStyle& arrows() { return options_.arrows; }
  std::optional<std::uint32_t> followed() const { return followed_; }
  // True once the followed vehicle has a state and its server's world has been accepted.
  bool ready() const;
  bool xr_active() const;
  // The drawn view of a vehicle at the last frame's instant (null before its first good state).
  const VehicleView* vehicle(std::uint32_t id) const;
  // The received state the last frame's instant lies at or after (the HUD's), or null.
  const pb::VehicleState* shown_state(std::uint32_t id) const;
  // The HUD's lines of text as the last frame drew them (empty with the HUD hidden).
  const std::vector<std::string>& hud_text() const;
  // The labels (landmark names, vehicle numbers) the last desktop frame drew.
  struct ShownLabel {
    std::string text;
    LabelBox box;
    float alpha = 1;
  };
  const std::vector<ShownLabel>& labels() const;
  // The HUD's boxes as the last frame drew them (pixels, y down): its panels, the compass last.
  const std::vector<LabelBox>& hud_boxes() const;
  // The camera of the last desktop frame.
  const CameraView& last_camera() const { return last_camera_; }
  class ParamsEditor& params_editor();
  client::SessionView& session();

 private:
  struct Impl;
  // The constructor's stages.
  void AcceptWorld(const pb::WorldDescription& w);  // a server's world, checked and measured
  void HandlePaddles(const pb::DriverInput& in);    // paddles turn the geographic camera
  void OpenWindow();                                // the window and its OpenGL 3.3 context
  void StartRenderer();                             // the renderer at the quality asked for
  void StartImGui();
  void StartHeadset();  // the OpenXR session (--xr), or the desktop window if none can start
  ViewerOptions options_;
  ViewerStats stats_;
  std::optional<std::uint32_t> followed_;
  CameraView last_camera_;
  std::unique_ptr<Impl> impl_;
};

}  // namespace vdyn::viewer
