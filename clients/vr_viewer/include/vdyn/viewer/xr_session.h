// Stereo through OpenXR with XR_KHR_opengl_enable (Xlib/GLX binding from the window's current GL
// context). The session's life follows the runtime's state events: READY -> xrBeginSession;
// frames (wait, begin, render both eyes and the HUD, end) while it runs; STOPPING ->
// xrEndSession; EXITING or LOSS_PENDING -> done. A frame is waited for first (WaitFrame: its
// predicted display time is the instant the scene is drawn at), then drawn and submitted (Frame):
// one projection layer (both eyes, in the reference space) and, with a HUD, one quad layer fixed
// in the reference space (a panel that stays where it is put while the head turns).
//
// Reference spaces: `seated` is LOCAL (the eyes at its origin), `standing` is STAGE (its origin on
// the floor; LOCAL with an assumed eye height where the runtime has no STAGE). The caller carries
// the origin through the world (at the driver's seat, behind the vehicle, ...) and gives its world
// pose each frame.
#pragma once

#include <functional>
#include <memory>
#include <stdexcept>
#include <string>

#include "vdyn/viewer/math.h"
#include "vdyn/viewer/renderer.h"

namespace vdyn::viewer {

class XrError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct XrOptions {
  bool seated = true;
  bool hud = true;
  int hud_width = 1024, hud_height = 640;
  double hud_width_m = 0.9;  // size of the HUD quad, m
  int samples = 4;
};

// One eye of one frame: its view and projection in the world, and the target to draw into.
struct XrEye {
  int index = 0;  // 0 left, 1 right
  Mat4 view, proj;
  Vec3 eye_W;
  RenderTarget* target = nullptr;
};

class Headset {
 public:
  // Creates instance, system and session on the current GL context. Throws XrError with a reason
  // a person can act on ("no OpenXR runtime: ...") when it cannot.
  explicit Headset(const XrOptions& options);
  ~Headset();
  Headset(const Headset&) = delete;
  Headset& operator=(const Headset&) = delete;

  // Handles the runtime's events; false once the session has ended (exit, loss).
  bool PollEvents();
  // True while frames are to be submitted (between READY and STOPPING).
  bool running() const;
  // Waits for the runtime's next frame slot (xrWaitFrame); Frame must follow.
  void WaitFrame();
  // The waited frame's predicted display time on this machine's monotonic clock, ns: the runtime's
  // time converted through XR_KHR_convert_timespec_time, or (a runtime without it) the time
  // WaitFrame returned plus the predicted display period.
  std::int64_t display_mono_ns() const;
  // Draws the waited frame's eyes and HUD through the callbacks and submits them.
  // `world_from_space` maps the reference space (OpenXR axes: X right, Y up, -Z forward, already
  // turned into the world's Z-up axes by the caller) to the world; `hud_in_space` is the HUD
  // quad's pose in the reference space (OpenXR axes; it faces along its +Z). Returns true when
  // the runtime asked for the frame to be drawn (false: submitted without layers).
  bool Frame(const Pose& world_from_space, const Pose& hud_in_space, double near_m, double far_m,
             const std::function<void(const XrEye&)>& draw_eye,
             const std::function<void(RenderTarget&)>& draw_hud);
  // A frame submitted with no layers (while leaving: the runtime still expects frames).
  void EmptyFrame();
  // Asks the runtime to end the session (it answers with STOPPING, then EXITING).
  void RequestExit();
  bool exit_requested() const;

  std::string runtime_name() const;
  std::string state_name() const;
  int eye_width() const;
  int eye_height() const;
  std::uint64_t frames_submitted() const;
  // The last frame's left eye (for the desktop mirror).
  const RenderTarget& mirror() const;
  // True when standing fell back to LOCAL: the caller adds an eye height to the origin.
  bool standing_on_local() const;
  // The head in the reference space at the last drawn frame (between the eyes, with their
  // orientation; OpenXR axes); false before the first tracked frame.
  bool head_in_space(Pose* out) const;
  // Counts the runtime's "reference space changed" events (it recentred the space itself).
  std::uint64_t space_changes() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace vdyn::viewer
