#include "vdyn/wheel_input/rig.h"

#include <SDL2/SDL.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <stdexcept>

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include "command_support.h"
#include "vdyn/base/text.h"
#include "vdyn/base/time.h"
#include "vdyn/wheel_input/mapping.h"
#include "vdyn/wheel_input/sdl_haptic.h"

namespace vdyn::wheel_input {

HapticFactory SdlHapticFactory() {
  return [](const WheelDevice& wheel, std::string* why) -> std::unique_ptr<HapticDevice> {
    auto h = SdlHaptic::Open(wheel.joystick(), why);
    if (h) spdlog::info("vdyn-input: force feedback on {}: {}", wheel.info().name, h->features());
    return h;
  };
}

RigLoop::RigLoop(RigConfig config, SdlContext& sdl, InputSink& sink, VehicleFeed& feed,
                 Resetter* resetter, HapticFactory haptics)
    : cfg_(std::move(config)),
      sdl_(sdl),
      sink_(sink),
      feed_(feed),
      resetter_(resetter),
      haptics_(std::move(haptics)),
      keyboard_(cfg_.keyboard),
      builder_(cfg_.builder) {}

RigLoop::~RigLoop() {
  if (ffb_) ffb_->SetDevice(nullptr);
  if (haptic_) haptic_->Stop();
}

bool RigLoop::OpenWheel(const std::vector<DeviceInfo>& devices, const DeviceInfo& d,
                        std::string* why) {
  std::vector<std::string> notes;
  auto w = WheelDevice::Open(d, devices, &notes, why);
  if (!w) return false;
  for (const auto& n : notes) spdlog::info("vdyn-input: {}: {}", d.name, n);
  pb::WheelMapping m = w->mapping();
  if (cfg_.range_deg) m.mutable_steer()->set_range_deg(*cfg_.range_deg);
  if (cfg_.ffb_peak_nm) m.mutable_ffb()->set_peak_torque_nm(*cfg_.ffb_peak_nm);
  reader_ = std::make_unique<WheelReader>(m);
  wheel_ = std::move(w);
  device_name_ = d.name;
  want_vendor_ = d.vendor_id;
  want_product_ = d.product_id;

  FfbParams p = cfg_.ffb_params;
  p.peak_torque_nm = m.ffb().peak_torque_nm();
  p.invert = m.ffb().invert();
  haptic_.reset();
  if (!cfg_.ffb) {
    p.peak_torque_nm = 0;
  } else if (p.peak_torque_nm <= 0) {
    spdlog::info(
        "vdyn-input: {}: no force feedback (no peak torque known: --ffb-peak-nm or the "
        "mapping's ffb.peak_torque_nm)",
        d.name);
  } else {
    std::string reason;
    haptic_ = haptics_ ? haptics_(*wheel_, &reason) : nullptr;
    if (!haptic_) {
      spdlog::info("vdyn-input: {}: no force feedback: {}", d.name, reason);
      p.peak_torque_nm = 0;
    }
  }
  ffb_ = std::make_unique<ForceFeedback>(p, haptic_.get());
  ffb_errors_said_ = 0;
  return true;
}

void RigLoop::Start() {
  const bool want_wheel = cfg_.source != RigConfig::Source::kKeyboard;
  if (want_wheel) {
    const auto devices = ScanDevices(cfg_.mapping_file);
    const DeviceInfo* chosen = nullptr;
    for (const auto& d : devices) {
      if (cfg_.device_index >= 0) {
        if (d.index == cfg_.device_index) chosen = &d;
      } else if (d.kind == DeviceInfo::Kind::kUserFile || d.kind == DeviceInfo::Kind::kTable ||
                 d.kind == DeviceInfo::Kind::kGeneric) {
        chosen = &d;
        break;
      }
      if (chosen) break;
    }
    if (cfg_.device_index >= 0 && chosen == nullptr) {
      throw std::runtime_error("no device " + std::to_string(cfg_.device_index) +
                               " (vdyn-input list shows the devices)");
    }
    // A wheel whose mapping is broken is not left for the keyboard without a word (it drove with
    // the keyboard, exit 0), and a --mapping that names another device is not set aside for the
    // table's or the generic mapping.
    if (chosen == nullptr) {
      for (const auto& d : devices) {
        if (d.kind == DeviceInfo::Kind::kBrokenFile) {
          throw std::runtime_error("cannot use " + d.name + " [" +
                                   VidPid(d.vendor_id, d.product_id) + "]: " + d.recognised_as);
        }
      }
    }
    if (chosen != nullptr && cfg_.mapping_file && chosen->mapping_path != *cfg_.mapping_file) {
      throw std::runtime_error("--mapping " + cfg_.mapping_file->string() +
                               " is for another device (its vendor_id and product_id) than " +
                               chosen->name + " [" +
                               VidPid(chosen->vendor_id, chosen->product_id) +
                               "] (vdyn-input list shows the devices and their ids)");
    }
    if (chosen != nullptr) {
      std::string why;
      if (!OpenWheel(devices, *chosen, &why)) {
        throw std::runtime_error("cannot use " + chosen->name + ": " + why);
      }
      wheel_mode_ = true;
      spdlog::info("vdyn-input: wheel {} [{}]: {}", chosen->name,
                   VidPid(chosen->vendor_id, chosen->product_id), chosen->recognised_as);
    } else if (cfg_.source == RigConfig::Source::kWheel) {
      throw std::runtime_error("no wheel found (vdyn-input list shows what SDL sees)");
    }
  }
  if (!wheel_mode_) {
    if (!sdl_.video()) {
      throw std::runtime_error(std::string(want_wheel ? "no wheel found, and " : "") +
                               "the keyboard needs a window, but there is no display (" +
                               sdl_.video_error() + ")");
    }
    device_name_ = "keyboard";
    ffb_ = std::make_unique<ForceFeedback>(FfbParams{.peak_torque_nm = 0}, nullptr);
  }
  if (sdl_.video() && (cfg_.window || !wheel_mode_)) {
    std::string why;
    window_ = StatusWindow::Create(
        "vdyn-input: " + device_name_ + " -> vehicle " + std::to_string(cfg_.vehicle_id), &why);
    if (!window_) {
      if (!wheel_mode_) throw std::runtime_error("the keyboard needs a window: " + why);
      spdlog::info("vdyn-input: no window: {}", why);
    }
  }
  status_ = wheel_mode_ ? "wheel " + device_name_ : "keyboard: arrow keys or WASD";
}

void RigLoop::Screenshot(const std::filesystem::path& path) {
  if (window_) window_->RequestScreenshot(path);
}

void RigLoop::PumpEvents(base::MonoTime now) {
  if (!sdl_.video()) return;
  if (now < next_events_) return;
  next_events_ = now + LoopPeriod(cfg_.events_hz);
  SDL_Event e;
  while (SDL_PollEvent(&e) != 0) {
    switch (e.type) {
      case SDL_QUIT:
        quit_ = true;
        break;
      case SDL_KEYDOWN:
      case SDL_KEYUP:
        if (e.key.repeat != 0) break;
        keyboard_.OnKey(e.key.keysym.scancode, e.type == SDL_KEYDOWN);
        if (e.type == SDL_KEYDOWN && e.key.keysym.scancode == SDL_SCANCODE_F12 && window_) {
          // Named by the wall clock's milliseconds, as the viewer's: a counter started at 1 in
          // every run and overwrote the last run's screenshots.
          ++screenshots_;
          const auto path = cfg_.screenshot_dir /
                            ("vdyn-input-" + std::to_string(base::WallNow().ns / 1'000'000) + ".png");
          window_->RequestScreenshot(path);
          spdlog::info("vdyn-input: screenshot {}", path.string());
        }
        break;
      case SDL_WINDOWEVENT:
        if (e.window.event == SDL_WINDOWEVENT_FOCUS_LOST) keyboard_.ReleaseAll();
        if (e.window.event == SDL_WINDOWEVENT_CLOSE) quit_ = true;
        break;
      default:
        break;
    }
  }
  if (keyboard_.TakeEstopPress()) {
    builder_.LatchEstop();
    spdlog::warn("vdyn-input: EMERGENCY STOP (key): force feedback off; F2 re-arms");
  }
  if (keyboard_.TakeRearmPress() && builder_.estop()) {
    builder_.RearmEstop();
    spdlog::info("vdyn-input: emergency stop re-armed (key)");
  }
}

void RigLoop::TryReplug(base::MonoTime now) {
  if (now < next_scan_) return;
  next_scan_ = now + cfg_.replug_scan;
  const auto devices = ScanDevices(cfg_.mapping_file);
  for (const auto& d : devices) {
    if (d.vendor_id != want_vendor_ || d.product_id != want_product_) continue;
    std::string why;
    if (OpenWheel(devices, d, &why)) {
      ++replugs_;
      status_ = "wheel " + device_name_;
      status_alarm_ = false;
      spdlog::info("vdyn-input: wheel {} is back: driving again", d.name);
      return;
    }
  }
}

bool RigLoop::Tick(base::MonoTime now) {
  const double dt = have_tick_ ? (now - last_tick_).seconds() : 0.0;
  have_tick_ = true;
  last_tick_ = now;
  PumpEvents(now);

  base::MonoTime sampled = now;
  if (wheel_mode_) {
    SDL_JoystickUpdate();
    sampled = base::MonotonicNow();
    if (wheel_ && !wheel_->attached()) {
      ++unplugs_;
      spdlog::warn(
          "vdyn-input: wheel {} unplugged: safe neutral (no throttle, brake {:.2f}, "
          "steering held) until it is plugged in again",
          device_name_, cfg_.neutral_brake);
      if (ffb_) ffb_->SetDevice(nullptr);
      haptic_.reset();
      wheel_.reset();
      status_ = "WHEEL UNPLUGGED: NEUTRAL, BRAKE " + fmt::format("{:.2f}", cfg_.neutral_brake);
      status_alarm_ = true;
      next_scan_ = now + cfg_.replug_scan;
    }
    if (!wheel_) TryReplug(now);
    if (wheel_) {
      wheel_->Read(frame_);
      const WheelControls c = reader_->Read(frame_);
      builder_.Build(sampled, c, info_, msg_);
      const double half_range =
          0.5 * reader_->mapping().steer().range_deg() * std::numbers::pi / 180.0;
      steer_fraction_ = half_range > 0 ? c.hand_angle_rad / half_range : 0.0;
    } else {
      builder_.Neutral(cfg_.neutral_brake, info_, msg_);
    }
  } else {
    const WheelControls c = keyboard_.Step(dt, info_);
    builder_.Build(sampled, c, info_, msg_);
    steer_fraction_ = keyboard_.steer_fraction();
  }

  if (sink_.Publish(msg_, sampled)) {
    ++published_;
    sample_to_write_.Add(base::MonotonicNow() - sampled);
  } else {
    if (publish_errors_++ == 0)
      spdlog::warn("vdyn-input: cannot write input: {}", sink_.last_error());
  }

  if (builder_.TakeResetRequest()) {
    ++resets_;
    if (resetter_ != nullptr) resetter_->RequestReset();
  }

  // The vehicle's newest state and parameters are taken at the force-feedback rate, just before
  // the update that plays them (the input needs only the speed and the steering ratio from them).
  if (now >= next_ffb_) {
    const base::Nanos period = LoopPeriod(cfg_.ffb_rate_hz);
    next_ffb_ = next_ffb_.ns == 0 || now - next_ffb_ > period ? now + period : next_ffb_ + period;
    feed_.Poll();
    if (const pb::VehicleParams* p = feed_.params()) ApplyParams(*p, info_);
    const pb::VehicleState* s = feed_.state();
    // A server that stopped sends no state: said once (the input is still sent), and again when
    // states come back; the window says it too.
    if (s != nullptr) {
      const bool silent = now - feed_.state_received() >= base::Seconds(kStateSilenceS);
      if (silent && !silence_said_) {
        spdlog::warn("vdyn-input: no state of vehicle {} for {:.0f} s: the server stopped or is "
                     "unreachable (input is still sent)",
                     cfg_.vehicle_id, kStateSilenceS);
      } else if (!silent && silence_said_) {
        spdlog::info("vdyn-input: states of vehicle {} again", cfg_.vehicle_id);
      }
      silence_said_ = silent;
    }
    if (s != nullptr) {
      info_.speed_known = true;
      info_.speed_kmh = s->v_wt_b().x() * 3.6;
      driving_ = s->input().source_id() == cfg_.source_id;
    }
    FfbInput in;
    if (s != nullptr) {
      in.has_state = true;
      in.torque_nm = s->steering_torque();
      in.speed_kmh = info_.speed_kmh;
      in.received = feed_.state_received();
      in.source_wall_ns = feed_.state_source_wall_ns();
      in.step = s->step();
    }
    if (ffb_) {
      ffb_->Update(now, in, builder_.estop());
      // A device that refuses the updates is said (once a second), not only counted for the
      // summary at the end (the status line read "on" with every update failing).
      if (ffb_->device_errors() > ffb_errors_said_ && now >= ffb_errors_next_say_) {
        spdlog::warn("vdyn-input: {}: force feedback: the device refused {} update(s) ({} in all)",
                     device_name_, ffb_->device_errors() - ffb_errors_said_,
                     ffb_->device_errors());
        ffb_errors_said_ = ffb_->device_errors();
        ffb_errors_next_say_ = now + base::Seconds(1);
      }
    }
  }

  if (window_ && now >= next_draw_) {
    next_draw_ = now + LoopPeriod(cfg_.window_hz);
    DrawWindow();
  }
  return !quit_;
}

void RigLoop::DrawWindow() {
  WindowView v;
  v.mode = wheel_mode_ ? "WHEEL: " + device_name_ : "KEYBOARD";
  v.status = status_;
  v.status_alarm = status_alarm_;
  v.vehicle_id = cfg_.vehicle_id;
  v.source_id = cfg_.source_id;
  v.driving = driving_;
  v.have_state = feed_.state() != nullptr;
  v.state_age_s = v.have_state ? (base::MonotonicNow() - feed_.state_received()).seconds() : 0.0;
  v.speed_kmh = info_.speed_kmh;
  v.input = msg_;
  // A refused shift stays on the window for 3 s: long enough to read why.
  if (builder_.shifts_refused() > 0 &&
      base::MonotonicNow() - builder_.shift_refused_at() < base::Seconds(3)) {
    v.shift_refusal = builder_.shift_refusal();
  }
  v.steer_fraction = steer_fraction_;
  v.hand_angle_deg = builder_.last_hand_angle_rad() * 180.0 / std::numbers::pi;
  v.ffb_present = ffb_ && ffb_->params().peak_torque_nm > 0;
  if (ffb_) {
    v.ffb_torque_nm = ffb_->last().torque_nm;
    v.ffb_cap_nm = std::min(ffb_->params().cap_nm, ffb_->params().peak_torque_nm);
    v.ffb_mode = ModeName(ffb_->last().mode);
    v.clip_percent = 100.0 * ffb_->clip_fraction();
  }
  v.estop = builder_.estop();
  v.keyboard_help = !wheel_mode_;
  window_->Draw(v);
  if (!window_->screenshot_error().empty()) {
    spdlog::warn("vdyn-input: {}", window_->screenshot_error());
  }
}

std::string RigLoop::StatusLine() const {
  const double deg = msg_.steer() * 180.0 / std::numbers::pi;
  std::string line =
      device_name_ + (wheel_mode_ && !wheel_ ? " UNPLUGGED" : "") +
      fmt::format(" | steer {:>6} deg ", base::FormatFixed(deg, 1, true)) +
      (msg_.steer_mode() == pb::STEER_HAND_WHEEL ? "hand" : "road") +
      fmt::format(" | thr {:.2f} brk {:.2f}", msg_.throttle(), msg_.brake()) + " | gear " +
      (msg_.gear() == 0 ? std::string("auto") : std::to_string(msg_.gear())) + " | cruise " +
      (msg_.cruise_on() ? fmt::format("{:.0f} km/h", msg_.cruise_set_kmh()) : "off");
  if (feed_.state() != nullptr) {
    line += " | " + base::FormatFixed(info_.speed_kmh, 1) + " km/h" +
            (driving_ ? " driving" : " NOT driving");
  }
  if (ffb_ && ffb_->params().peak_torque_nm > 0) {
    line += " | ffb " + base::FormatFixed(ffb_->last().torque_nm, 2, true) + " N*m " +
            ModeName(ffb_->last().mode) +
            fmt::format(" clip {:.1f} %", 100.0 * ffb_->clip_fraction());
    if (ffb_->device_errors() > 0)
      line += fmt::format(" DEVICE ERRORS {}", ffb_->device_errors());
  }
  if (builder_.estop()) line += " | E-STOP";
  line += fmt::format(" | sample->write p99 {:.0f} us", sample_to_write_.PercentileUs(99));
  return line;
}

std::string RigLoop::Summary() const {
  std::string s =
      "vdyn-input: " + std::to_string(published_) + " inputs written (" +
      std::to_string(publish_errors_) + " failed); sample to DDS write p50 " +
      fmt::format("{:.0f} us, p99 {:.0f} us, max {:.0f} us", sample_to_write_.PercentileUs(50),
                  sample_to_write_.PercentileUs(99), sample_to_write_.MaxUs());
  if (wheel_mode_) {
    s += "\n  wheel " + device_name_ + ": unplugged " + std::to_string(unplugs_) + " times, back " +
         std::to_string(replugs_) + " times";
    if (reader_) {
      s += "; axis values not a number " + std::to_string(reader_->nonfinite()) +
           ", outside the calibrated travel " + std::to_string(reader_->out_of_range());
    }
  }
  s += "\n  fields clamped to the limits " + std::to_string(builder_.clamped()) +
       ", reset requests " + std::to_string(resets_);
  if (ffb_ && ffb_->params().peak_torque_nm > 0) {
    s += "\n  force feedback: " + std::to_string(ffb_->updates()) + " updates, device errors " +
         std::to_string(ffb_->device_errors()) + ", clipping warnings " +
         std::to_string(ffb_->clip_warnings()) +
         fmt::format(", state to haptic update p50 {:.0f} us, p99 {:.0f} us",
                     ffb_->state_to_haptic().PercentileUs(50),
                     ffb_->state_to_haptic().PercentileUs(99));
  }
  return s;
}

}  // namespace vdyn::wheel_input
