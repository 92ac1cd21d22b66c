// The small SDL window of vdyn-input: what is being sent (steering, throttle, brake, clutch,
// handbrake, gear, cruise, paddles and buttons), whether this rig drives the vehicle, its speed,
// force feedback and the emergency stop, and the keys. Drawn with SDL's renderer and its built-in
// 8x8 font (SDL2_test); it receives the keyboard. Screenshots as PNG.
#pragma once

#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include <SDL2/SDL.h>

#include "vdyn/input.pb.h"

namespace vdyn::wheel_input {

// Without a state for this long the server is said to be gone (window and log), s.
inline constexpr double kStateSilenceS = 2.0;

struct WindowView {
  std::string mode;           // "KEYBOARD", "WHEEL: Logitech G29"
  std::string status;         // one line: "driving", "wheel unplugged: neutral", ...
  bool status_alarm = false;  // shown in red
  std::uint32_t vehicle_id = 0;
  std::string source_id;
  bool driving = false;  // the newest state applied this rig's input
  bool have_state = false;
  double state_age_s = 0;  // since the newest state arrived (a stopped server: it grows)
  double speed_kmh = 0;
  pb::DriverInput input;      // as sent
  std::string shift_refusal;  // a gear shift refused in the last few seconds, and why
  double steer_fraction = 0;  // of the lock (road wheel) or of the hand-wheel range, [-1, 1]
  double hand_angle_deg = 0;
  bool ffb_present = false;
  double ffb_torque_nm = 0;
  double ffb_cap_nm = 0;
  std::string ffb_mode;
  double clip_percent = 0;
  bool estop = false;
  bool keyboard_help = false;
};

// One thing the window draws, in window pixels. A text's box is its extent in SDL2_test's 8x8
// font (8 pixels a character); a bar's box is its frame.
struct WindowItem {
  enum class Kind { kText, kBar, kCentredBar, kFilledBox };
  Kind kind = Kind::kText;
  SDL_Rect box{0, 0, 0, 0};
  std::string text;  // kText
  double value = 0;  // kBar: [0, 1] from the left; kCentredBar: [-1, 1], positive to the left
  SDL_Color color{255, 255, 255, 255};
};

// The window's content for `v` in a window `width` pixels wide, top to bottom. Text too long for
// a line wraps at spaces (a field a person named, such as a device, ends in "..." past its lines),
// so nothing reaches past the right edge, and with every field at its longest the rows fit
// StatusWindow::kHeight (tests check both). The e-stop banner's place is kept when it is off.
std::vector<WindowItem> LayoutWindow(const WindowView& v, int width);

// The speed line: "SPEED   70.0 KM/H", "SPEED    0.0 KM/H" at rest (never -0.0), "SPEED   --".
std::string SpeedText(const WindowView& v);

class StatusWindow {
 public:
  // Needs SDL video; nullptr and the reason when a window cannot be made.
  static std::unique_ptr<StatusWindow> Create(const std::string& title, std::string* why);
  ~StatusWindow();
  StatusWindow(const StatusWindow&) = delete;
  StatusWindow& operator=(const StatusWindow&) = delete;

  void Draw(const WindowView& v);
  // The next frame drawn is also written to `path` as a PNG; screenshot_error() says if it failed.
  void RequestScreenshot(const std::filesystem::path& path) { screenshot_ = path; }
  bool screenshot_pending() const { return !screenshot_.empty(); }
  const std::string& screenshot_error() const { return screenshot_error_; }
  std::uint32_t window_id() const { return SDL_GetWindowID(window_); }

  static constexpr int kWidth = 560;
  static constexpr int kHeight = 300;

 private:
  StatusWindow() = default;
  SDL_Window* window_ = nullptr;
  SDL_Renderer* renderer_ = nullptr;
  std::filesystem::path screenshot_;
  std::string screenshot_error_;
};

}  // namespace vdyn::wheel_input
