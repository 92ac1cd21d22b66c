#include "vdyn/wheel_input/window.h"

#include <SDL2/SDL_test_font.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

#include <fmt/format.h>
#include <stb/stb_image_write.h>

#include "vdyn/base/text.h"

namespace vdyn::wheel_input {
namespace {

constexpr int kMargin = 12;
constexpr int kLine = 14;  // text rows: 8 pixels of letters, 6 between
constexpr int kChar = 8;   // SDL2_test's font: 8x8 pixels a character

SDL_Color Rgb(std::uint8_t red, std::uint8_t green, std::uint8_t blue) {
  return SDL_Color{red, green, blue, 255};
}

// `text` in lines of at most `columns` characters, broken at spaces (a word longer than a line is
// cut), at most `max_lines` of them; the last ends in "..." when text is left over.
std::vector<std::string> Wrap(const std::string& text, int columns, int max_lines) {
  const std::size_t cols = static_cast<std::size_t>(std::max(columns, 4));
  std::vector<std::string> lines;
  std::string rest = text;
  while (!rest.empty()) {
    if (static_cast<int>(lines.size()) == max_lines) {
      std::string& last = lines.back();
      if (last.size() + 3 > cols) last.resize(cols - 3);
      last += "...";
      break;
    }
    if (rest.size() <= cols) {
      lines.push_back(rest);
      break;
    }
    std::size_t cut = rest.rfind(' ', cols);
    if (cut == std::string::npos || cut == 0) cut = cols;
    std::string line = rest.substr(0, cut);
    while (!line.empty() && line.back() == ' ') line.pop_back();
    lines.push_back(line);
    rest.erase(0, cut);
    while (!rest.empty() && rest.front() == ' ') rest.erase(0, 1);
  }
  return lines;
}

class Layout {
 public:
  explicit Layout(int width) : width_(width) {}

  // Text at (x, y), wrapped to the right margin; returns the number of lines.
  int Text(int x, int y, const std::string& text, SDL_Color c, int max_lines = 1) {
    const int columns = (width_ - kMargin - x) / kChar;
    const std::vector<std::string> lines = Wrap(text, columns, max_lines);
    for (std::size_t i = 0; i < lines.size(); ++i) {
      WindowItem t;
      t.kind = WindowItem::Kind::kText;
      t.text = lines[i];
      t.box = SDL_Rect{x, y + static_cast<int>(i) * kLine,
                       static_cast<int>(lines[i].size()) * kChar, kChar};
      t.color = c;
      items_.push_back(std::move(t));
    }
    return static_cast<int>(lines.size());
  }
  // Text lines from the left margin at the cursor, which moves below them.
  void Line(const std::string& text, SDL_Color c, int max_lines = 1) {
    y_ += kLine * Text(kMargin, y_, text, c, max_lines);
  }
  void Add(WindowItem::Kind kind, SDL_Rect box, double value, SDL_Color c) {
    WindowItem b;
    b.kind = kind;
    b.box = box;
    b.value = value;
    b.color = c;
    items_.push_back(std::move(b));
  }

  int& y() { return y_; }
  std::vector<WindowItem> Take() { return std::move(items_); }

 private:
  int width_;
  int y_ = kMargin;
  std::vector<WindowItem> items_;
};

void Color(SDL_Renderer* r, SDL_Color c) {
  SDL_SetRenderDrawColor(r, c.r, c.g, c.b, c.a);
}

// A bar of `value` in [0, 1] from the left, with a frame.
void DrawBar(SDL_Renderer* r, const WindowItem& b) {
  Color(r, Rgb(60, 60, 60));
  SDL_RenderDrawRect(r, &b.box);
  const int len = static_cast<int>(std::lround(std::clamp(b.value, 0.0, 1.0) * (b.box.w - 2)));
  if (len <= 0) return;
  Color(r, b.color);
  SDL_Rect fill{b.box.x + 1, b.box.y + 1, len, b.box.h - 2};
  SDL_RenderFillRect(r, &fill);
}

// A bar centred at the middle: positive values fill to the LEFT (vdyn's steering sign: left +).
void DrawCentredBar(SDL_Renderer* r, const WindowItem& b) {
  Color(r, Rgb(60, 60, 60));
  SDL_RenderDrawRect(r, &b.box);
  const int mid = b.box.x + b.box.w / 2;
  const int len =
      static_cast<int>(std::lround(std::clamp(std::abs(b.value), 0.0, 1.0) * (b.box.w / 2 - 1)));
  if (len > 0) {
    Color(r, b.color);
    SDL_Rect fill = b.value >= 0 ? SDL_Rect{mid - len, b.box.y + 1, len, b.box.h - 2}
                                 : SDL_Rect{mid, b.box.y + 1, len, b.box.h - 2};
    SDL_RenderFillRect(r, &fill);
  }
  Color(r, Rgb(200, 200, 200));
  SDL_RenderDrawLine(r, mid, b.box.y, mid, b.box.y + b.box.h - 1);
}

}  // namespace

std::string SpeedText(const WindowView& v) {
  if (!v.have_state) return "SPEED   --";
  return fmt::format("SPEED {:>6} KM/H", base::FormatFixed(v.speed_kmh, 1));
}

std::vector<WindowItem> LayoutWindow(const WindowView& v, int width) {
  const SDL_Color white = Rgb(255, 255, 255), grey = Rgb(170, 170, 170), help = Rgb(140, 140, 140);
  Layout l(width);
  const int inner = width - 2 * kMargin;
  l.Line("VDYN-INPUT  " + v.mode, white);
  l.Line("VEHICLE " + std::to_string(v.vehicle_id) + "  SOURCE " + v.source_id +
             (!v.have_state ? "  NO STATE YET"
              : v.state_age_s >= kStateSilenceS
                  ? fmt::format("  NO STATE FOR {:.0f} S (SERVER GONE?)", v.state_age_s)
              : v.driving ? "  DRIVING"
                          : "  NOT DRIVING (ANOTHER SOURCE OWNS IT)"),
         v.have_state && v.state_age_s >= kStateSilenceS ? Rgb(255, 90, 80) : grey, 2);
  l.Line(v.status, v.status_alarm ? Rgb(255, 90, 80) : Rgb(120, 220, 120), 2);
  l.y() += 8;

  const auto& in = v.input;
  const bool hand = in.steer_mode() == pb::STEER_HAND_WHEEL;
  l.Line(
      "STEER " +
          fmt::format("{:>6}", base::FormatFixed(in.steer() * 180.0 / 3.141592653589793, 1, true)) +
          " DEG " + (hand ? "HAND WHEEL" : "ROAD WHEEL") + "   (WHEEL " +
          fmt::format("{:>5}", base::FormatFixed(v.hand_angle_deg, 0, true)) + " DEG)",
      white);
  l.Add(WindowItem::Kind::kCentredBar, SDL_Rect{kMargin, l.y(), inner, 14}, v.steer_fraction,
        Rgb(80, 160, 255));
  l.y() += 24;

  // Pedals in two columns: a label of 13 characters ("THROTTLE 1.00"), then its bar.
  constexpr int kColumnGap = 16, kLabel = 13 * kChar, kBarGap = 8;
  const int column = (inner - kColumnGap) / 2;
  const int bar = column - kLabel - kBarGap;
  auto pedal = [&](const char* name, double value, SDL_Color c, int col) {
    const int x0 = kMargin + col * (column + kColumnGap);
    l.Text(x0, l.y() + 3, fmt::format("{:<8} {:4.2f}", name, value), white);
    l.Add(WindowItem::Kind::kBar, SDL_Rect{x0 + kLabel + kBarGap, l.y(), bar, 14}, value, c);
  };
  pedal("THROTTLE", std::max(in.throttle(), 0.0), Rgb(80, 200, 90), 0);
  pedal("CLUTCH", in.clutch(), Rgb(200, 200, 80), 1);
  l.y() += 20;
  pedal("BRAKE", in.brake(), Rgb(230, 70, 60), 0);
  pedal("HANDBRK", in.handbrake(), Rgb(230, 140, 60), 1);
  l.y() += 26;

  const std::string gear =
      in.gear() == 0 ? "AUTO" : (in.gear() < 0 ? "R" : std::to_string(in.gear()));
  const std::string cruise =
      in.cruise_on()
          ? fmt::format("ON {:.0f} KM/H", in.cruise_set_kmh())
          : (in.cruise_set_kmh() > 0 ? fmt::format("OFF (SET {:.0f})", in.cruise_set_kmh())
                                     : "OFF");
  l.Line("GEAR " + gear + "   CRUISE " + cruise, white);
  if (!v.shift_refusal.empty()) {
    l.Line("SHIFT REFUSED:", Rgb(255, 170, 60));
    l.Line("  " + v.shift_refusal, Rgb(255, 170, 60));
  }
  const std::uint32_t b = in.buttons();
  std::string buttons = "PADDLES ";
  buttons += (b & pb::BUTTON_PADDLE_LEFT) ? "[L]" : " L ";
  buttons += (b & pb::BUTTON_PADDLE_RIGHT) ? "[R]" : " R ";
  buttons += "  BUTTONS";
  if (b & pb::BUTTON_CRUISE_TOGGLE) buttons += " CRUISE";
  if (b & pb::BUTTON_CRUISE_UP) buttons += " +";
  if (b & pb::BUTTON_CRUISE_DOWN) buttons += " -";
  if (b & pb::BUTTON_RESET) buttons += " RESET";
  if (b & pb::BUTTON_CAMERA) buttons += " CAMERA";
  if (b & pb::BUTTON_HORN) buttons += " HORN";
  l.Line(buttons, white);
  l.Line(SpeedText(v), white);
  l.Line(v.ffb_present ? "FFB " + base::FormatFixed(v.ffb_torque_nm, 2, true) + " N*M (CAP " +
                             base::FormatFixed(v.ffb_cap_nm, 1) + ")  " + v.ffb_mode + "  CLIP " +
                             base::FormatFixed(v.clip_percent, 1) + " %"
                       : std::string("FFB NONE"),
         white);
  l.y() += 4;

  // The e-stop banner: a red box of as many rows as its text needs; its place is kept when off.
  const std::string rearm =
      v.keyboard_help ? "RE-ARM: F2" : "RE-ARM: F2, OR HOLD THE E-STOP BUTTON 2 S";
  const std::string banner = "EMERGENCY STOP: FORCE FEEDBACK OFF.  " + rearm;
  const int banner_rows = static_cast<int>(Wrap(banner, (inner - 12) / kChar, 3).size());
  const int banner_h = 8 + banner_rows * 12 - 4;
  if (v.estop) {
    l.Add(WindowItem::Kind::kFilledBox, SDL_Rect{kMargin, l.y(), inner, banner_h}, 0,
          Rgb(200, 30, 30));
    const std::vector<std::string> rows = Wrap(banner, (inner - 12) / kChar, 3);
    for (std::size_t i = 0; i < rows.size(); ++i) {
      l.Text(kMargin + 6, l.y() + 4 + static_cast<int>(i) * 12, rows[i], white);
    }
  }
  l.y() += banner_h + 8;
  if (v.keyboard_help) {
    l.Line("UP/W THROTTLE  DOWN/S BRAKE  LEFT/A RIGHT/D STEER  SPACE HANDBRAKE", help, 2);
    l.Line("C CRUISE  PGUP/= PGDN/- SET SPEED  Q/E PADDLES  BACKSPACE RESET", help, 2);
    l.Line("V CAMERA  H HORN  ESC E-STOP  F2 RE-ARM  F12 SCREENSHOT", help, 2);
  }
  return l.Take();
}

std::unique_ptr<StatusWindow> StatusWindow::Create(const std::string& title, std::string* why) {
  std::unique_ptr<StatusWindow> w(new StatusWindow());
  w->window_ = SDL_CreateWindow(title.c_str(), SDL_WINDOWPOS_UNDEFINED, SDL_WINDOWPOS_UNDEFINED,
                                kWidth, kHeight, SDL_WINDOW_SHOWN);
  if (w->window_ == nullptr) {
    if (why) *why = std::string("SDL_CreateWindow: ") + SDL_GetError();
    return nullptr;
  }
  // Software rendering: a few rectangles and letters, no GPU needed (and none under Xvfb).
  w->renderer_ = SDL_CreateRenderer(w->window_, -1, SDL_RENDERER_SOFTWARE);
  if (w->renderer_ == nullptr) {
    if (why) *why = std::string("SDL_CreateRenderer: ") + SDL_GetError();
    return nullptr;
  }
  return w;
}

StatusWindow::~StatusWindow() {
  if (renderer_ != nullptr) SDL_DestroyRenderer(renderer_);
  if (window_ != nullptr) SDL_DestroyWindow(window_);
}

void StatusWindow::Draw(const WindowView& v) {
  SDL_Renderer* r = renderer_;
  Color(r, Rgb(18, 20, 24));
  SDL_RenderClear(r);
  for (const WindowItem& item : LayoutWindow(v, kWidth)) {
    switch (item.kind) {
      case WindowItem::Kind::kText:
        Color(r, item.color);
        SDLTest_DrawString(r, item.box.x, item.box.y, item.text.c_str());
        break;
      case WindowItem::Kind::kBar:
        DrawBar(r, item);
        break;
      case WindowItem::Kind::kCentredBar:
        DrawCentredBar(r, item);
        break;
      case WindowItem::Kind::kFilledBox:
        Color(r, item.color);
        SDL_RenderFillRect(r, &item.box);
        break;
    }
  }
  if (!screenshot_.empty()) {
    std::vector<std::uint8_t> rgba(static_cast<std::size_t>(kWidth) * kHeight * 4);
    if (SDL_RenderReadPixels(r, nullptr, SDL_PIXELFORMAT_ABGR8888, rgba.data(), kWidth * 4) != 0) {
      screenshot_error_ = std::string("SDL_RenderReadPixels: ") + SDL_GetError();
    } else if (stbi_write_png(screenshot_.c_str(), kWidth, kHeight, 4, rgba.data(), kWidth * 4) ==
               0) {
      screenshot_error_ = screenshot_.string() + ": cannot write the PNG";
    } else {
      screenshot_error_.clear();
    }
    screenshot_.clear();
  }
  SDL_RenderPresent(r);
}

}  // namespace vdyn::wheel_input
