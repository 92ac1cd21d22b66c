#include "vdyn/wheel_input/window.h"

#include <SDL2/SDL_test_font.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

#include <fmt/format.h>
#include <stb/stb_image_write.h>

namespace vdyn::wheel_input {
namespace {

constexpr int kMargin = 12;
constexpr int kLine = 14;

void Color(SDL_Renderer* r, std::uint8_t red, std::uint8_t green, std::uint8_t blue) {
  SDL_SetRenderDrawColor(r, red, green, blue, 255);
}

void Text(SDL_Renderer* r, int x, int y, const std::string& s) {
  SDLTest_DrawString(r, x, y, s.c_str());
}

// A bar of `value` in [0, 1] from the left, with a frame.
void Bar(SDL_Renderer* r, int x, int y, int w, int h, double value, std::uint8_t red,
         std::uint8_t green, std::uint8_t blue) {
  Color(r, 60, 60, 60);
  SDL_Rect frame{x, y, w, h};
  SDL_RenderDrawRect(r, &frame);
  const int len = static_cast<int>(std::lround(std::clamp(value, 0.0, 1.0) * (w - 2)));
  if (len <= 0) return;
  Color(r, red, green, blue);
  SDL_Rect fill{x + 1, y + 1, len, h - 2};
  SDL_RenderFillRect(r, &fill);
}

// A bar centred at the middle: positive values fill to the LEFT (vdyn's steering sign: left +).
void CentredBar(SDL_Renderer* r, int x, int y, int w, int h, double value) {
  Color(r, 60, 60, 60);
  SDL_Rect frame{x, y, w, h};
  SDL_RenderDrawRect(r, &frame);
  const int mid = x + w / 2;
  const int len =
      static_cast<int>(std::lround(std::clamp(std::abs(value), 0.0, 1.0) * (w / 2 - 1)));
  if (len > 0) {
    Color(r, 80, 160, 255);
    SDL_Rect fill =
        value >= 0 ? SDL_Rect{mid - len, y + 1, len, h - 2} : SDL_Rect{mid, y + 1, len, h - 2};
    SDL_RenderFillRect(r, &fill);
  }
  Color(r, 200, 200, 200);
  SDL_RenderDrawLine(r, mid, y - 2, mid, y + h + 1);
}

}  // namespace

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
  Color(r, 18, 20, 24);
  SDL_RenderClear(r);
  int y = kMargin;
  Color(r, 255, 255, 255);
  Text(r, kMargin, y, "VDYN-INPUT  " + v.mode);
  y += kLine;
  Color(r, 170, 170, 170);
  Text(r, kMargin, y,
       "VEHICLE " + std::to_string(v.vehicle_id) + "  SOURCE " + v.source_id +
           (v.have_state ? (v.driving ? "  DRIVING" : "  NOT DRIVING (ANOTHER SOURCE OWNS IT)")
                         : "  NO STATE YET"));
  y += kLine;
  if (v.status_alarm) {
    Color(r, 255, 90, 80);
  } else {
    Color(r, 120, 220, 120);
  }
  Text(r, kMargin, y, v.status);
  y += kLine + 8;

  const auto& in = v.input;
  const bool hand = in.steer_mode() == pb::STEER_HAND_WHEEL;
  Color(r, 255, 255, 255);
  Text(r, kMargin, y,
       "STEER " + fmt::format("{:+7.1f} DEG ", in.steer() * 180.0 / 3.141592653589793) +
           (hand ? "HAND WHEEL" : "ROAD WHEEL") +
           fmt::format("   (WHEEL {:+6.0f} DEG)", v.hand_angle_deg));
  y += kLine;
  CentredBar(r, kMargin, y, kWidth - 2 * kMargin, 14, v.steer_fraction);
  y += 24;
  const int label = 100, bar_w = 170;
  auto pedal = [&](const char* name, double value, std::uint8_t red, std::uint8_t green,
                   std::uint8_t blue, int x0) {
    Color(r, 255, 255, 255);
    Text(r, x0, y + 3, std::string(name) + fmt::format(" {:4.2f}", value));
    Bar(r, x0 + label + 8, y, bar_w, 14, value, red, green, blue);
  };
  pedal("THROTTLE", std::max(in.throttle(), 0.0), 80, 200, 90, kMargin);
  pedal("CLUTCH  ", in.clutch(), 200, 200, 80, kMargin + label + bar_w + 24);
  y += 20;
  pedal("BRAKE   ", in.brake(), 230, 70, 60, kMargin);
  pedal("HANDBRK ", in.handbrake(), 230, 140, 60, kMargin + label + bar_w + 24);
  y += 26;

  Color(r, 255, 255, 255);
  const std::string gear =
      in.gear() == 0 ? "AUTO" : (in.gear() < 0 ? "R" : std::to_string(in.gear()));
  std::string cruise = in.cruise_on() ? fmt::format("ON {:.0f} KM/H", in.cruise_set_kmh())
                                      : (in.cruise_set_kmh() > 0
                                             ? fmt::format("OFF (SET {:.0f})", in.cruise_set_kmh())
                                             : "OFF");
  Text(r, kMargin, y, "GEAR " + gear + "   CRUISE " + cruise);
  y += kLine;
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
  Text(r, kMargin, y, buttons);
  y += kLine;
  Text(r, kMargin, y,
       (v.have_state ? fmt::format("SPEED {:6.1f} KM/H", v.speed_kmh) : std::string("SPEED   --")) +
           (v.ffb_present ? "   FFB " + fmt::format("{:+5.2f} N*M", v.ffb_torque_nm) +
                                fmt::format(" (CAP {:.1f}) ", v.ffb_cap_nm) + v.ffb_mode +
                                fmt::format("  CLIP {:.1f} %", v.clip_percent)
                          : std::string("   FFB NONE")));
  y += kLine + 4;
  if (v.estop) {
    Color(r, 200, 30, 30);
    SDL_Rect box{kMargin, y, kWidth - 2 * kMargin, 18};
    SDL_RenderFillRect(r, &box);
    Color(r, 255, 255, 255);
    Text(r, kMargin + 6, y + 5,
         "EMERGENCY STOP: FORCE FEEDBACK OFF  (F2 OR HOLD THE BUTTON 2 S TO RE-ARM)");
  }
  y += 24;
  if (v.keyboard_help) {
    Color(r, 140, 140, 140);
    Text(r, kMargin, y, "UP/W THROTTLE  DOWN/S BRAKE  LEFT/A RIGHT/D STEER  SPACE HANDBRAKE");
    y += kLine;
    Text(r, kMargin, y, "C CRUISE  PGUP/= PGDN/- SET SPEED  Q/E PADDLES  BACKSPACE RESET");
    y += kLine;
    Text(r, kMargin, y, "V CAMERA  H HORN  ESC E-STOP  F2 RE-ARM  F12 SCREENSHOT");
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
