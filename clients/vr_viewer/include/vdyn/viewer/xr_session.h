// Stereo through OpenXR with XR_KHR_opengl_enable (Xlib/GLX binding from the window's current GL
// context). The session's life follows the runtime's state events: READY -> xrBeginSession;
// frames (wait, begin, render both eyes and the HUD, end) while it runs; STOPPING ->
// xrEndSession; EXITING or LOSS_PENDING -> done. A frame submits one projection layer (both eyes,
// in the reference space) and, with a HUD, one quad layer fixed in front of the head (view space).
//
// Reference spaces: `seated` is LOCAL, its origin carried at the driver's seat of the followed
// vehicle (it moves, rolls and pitches with the body); `standing` is STAGE (LOCAL with an assumed
// eye height where the runtime has no STAGE), its origin on the ground beside the vehicle, facing
// it, following its position and heading. The caller gives the world pose of that origin.
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
  double hud_distance_m = 1.2;
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
  // One frame: waits for the runtime's slot, draws each eye and the HUD through the callbacks,
  // submits. `world_from_space` maps the reference space (OpenXR axes: X right, Y up, -Z
  // forward, already turned into the world's Z-up axes by the caller) to the world. Returns true
  // when the runtime asked for the frame to be drawn (false: submitted without layers).
  bool Frame(const Pose& world_from_space, double near_m, double far_m,
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

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// The reference space's axes in a frame whose X is forward, Y left, Z up (body or ground): X_s =
// right = -Y, Y_s = up = Z, Z_s = back = -X.
Mat3 XrAxesIn(const Mat3& frame_forward_left_up);

}  // namespace vdyn::viewer
