#include "vdyn/wheel_input/ffb.h"

#include <algorithm>
#include <cmath>
#include <numbers>

#include <spdlog/spdlog.h>

namespace vdyn::wheel_input {

const char* ModeName(FfbOutput::Mode m) {
  switch (m) {
    case FfbOutput::Mode::kOff:
      return "off";
    case FfbOutput::Mode::kPlaying:
      return "on";
    case FfbOutput::Mode::kFading:
      return "fading (state late)";
    case FfbOutput::Mode::kStopped:
      return "stopped (no state)";
    case FfbOutput::Mode::kEstop:
      return "E-STOP";
  }
  return "?";
}

void RecordingHaptic::Record(Call c) {
  calls.push_back(c);
  if (on_call) on_call(calls.back());
}

bool RecordingHaptic::SetConstant(double level, base::Nanos length) {
  Record({Call::Kind::kConstant, base::MonotonicNow(), level, length});
  return true;
}

bool RecordingHaptic::SetDamper(double coefficient, base::Nanos length) {
  if (!has_damper_) return false;
  Record({Call::Kind::kDamper, base::MonotonicNow(), coefficient, length});
  return true;
}

void RecordingHaptic::Stop() {
  Record({Call::Kind::kStop, base::MonotonicNow(), 0.0, {}});
}

ForceFeedback::ForceFeedback(FfbParams params, HapticDevice* device)
    : params_(params), device_(device) {
  on_warning = [](const std::string& s) { spdlog::warn("vdyn-input: {}", s); };
}

void ForceFeedback::SetDevice(HapticDevice* device) {
  device_ = device;
  device_stopped_ = true;
  filtered_ = 0;
  slewed_ = 0;
}

void ForceFeedback::StopDevice(FfbOutput::Mode mode) {
  if (device_ != nullptr && !device_stopped_) device_->Stop();
  device_stopped_ = true;
  filtered_ = 0;
  slewed_ = 0;
  have_time_ = false;  // playing again starts from zero, through the slew limit
  last_ = FfbOutput{};
  last_.mode = mode;
}

double ForceFeedback::clip_fraction() const {
  std::uint64_t total = 0, clipped = 0;
  for (int i = 0; i < kSlots; ++i) {
    total += slot_total_[static_cast<std::size_t>(i)];
    clipped += slot_clipped_[static_cast<std::size_t>(i)];
  }
  return total == 0 ? 0.0 : static_cast<double>(clipped) / static_cast<double>(total);
}

void ForceFeedback::ClipMeter(base::MonoTime now, bool clipped) {
  if (!meter_started_) {
    meter_started_ = true;
    meter_start_ = now;
  }
  const std::int64_t slot_ns = std::max<std::int64_t>(params_.clip_window.ns / kSlots, 1);
  const std::int64_t index = (now - meter_start_).ns / slot_ns;
  if (index != slot_index_) {
    // Empty the slots the clock moved past (at most a whole window).
    const std::int64_t from = std::max(slot_index_ + 1, index - kSlots + 1);
    for (std::int64_t i = from; i <= index; ++i) {
      const auto s = static_cast<std::size_t>(i % kSlots);
      slot_total_[s] = 0;
      slot_clipped_[s] = 0;
    }
    slot_index_ = index;
  }
  const auto s = static_cast<std::size_t>(index % kSlots);
  ++slot_total_[s];
  if (clipped) ++slot_clipped_[s];
  const bool window_full = index >= kSlots - 1;
  if (window_full && index - last_warning_slot_ >= kSlots &&
      clip_fraction() > params_.clip_warn_fraction) {
    last_warning_slot_ = index;
    ++clip_warnings_;
    char text[200];
    std::snprintf(text, sizeof text,
                  "force feedback clips: %.1f %% of the updates in the last %.0f s asked for more "
                  "than %.2f N*m (lower --ffb-gain or raise --ffb-cap-nm)",
                  100.0 * clip_fraction(), params_.clip_window.seconds(),
                  std::min(params_.cap_nm, params_.peak_torque_nm));
    if (on_warning) on_warning(text);
  }
}

FfbOutput ForceFeedback::Update(base::MonoTime now, const FfbInput& in, bool estop) {
  // A late update (the loop was held up) counts as at most 20 ms: the slew limit stays a limit.
  const double dt = have_time_ ? std::clamp((now - last_time_).seconds(), 0.0, 0.02) : 0.0;
  have_time_ = true;
  last_time_ = now;
  ++updates_;
  if (params_.peak_torque_nm <= 0) {
    last_ = FfbOutput{};
    return last_;
  }
  if (estop) {
    StopDevice(FfbOutput::Mode::kEstop);
    return last_;
  }
  if (!in.has_state) {
    StopDevice(FfbOutput::Mode::kOff);
    return last_;
  }
  const base::Nanos age = now - in.received;
  if (age >= params_.stop_after) {
    StopDevice(FfbOutput::Mode::kStopped);
    return last_;
  }
  double fade = 1.0;
  if (age > params_.fade_after) {
    fade = std::max(0.0, 1.0 - static_cast<double>((age - params_.fade_after).ns) /
                                   static_cast<double>(params_.fade_over.ns));
  }
  const double requested = std::isfinite(in.torque_nm) ? params_.gain * in.torque_nm : 0.0;
  const double alpha =
      dt > 0 ? 1.0 - std::exp(-2.0 * std::numbers::pi * params_.filter_hz * dt) : 1.0;
  filtered_ += alpha * (requested - filtered_);
  const double limit = std::min(params_.cap_nm, params_.peak_torque_nm);
  FfbOutput out;
  out.clipped = std::abs(filtered_) > limit;
  const double capped = std::clamp(filtered_, -limit, limit);
  const double max_step = params_.slew_nm_per_s * dt;
  slewed_ += std::clamp(capped - slewed_, -max_step, max_step);
  out.torque_nm = slewed_ * fade;
  out.level = std::clamp(out.torque_nm / params_.peak_torque_nm, -1.0, 1.0);
  if (params_.invert) out.level = -out.level;
  out.mode = fade < 1.0 ? FfbOutput::Mode::kFading : FfbOutput::Mode::kPlaying;
  if (params_.damper > 0 && params_.damper_below_kmh > 0) {
    out.damper =
        params_.damper * std::max(0.0, 1.0 - std::abs(in.speed_kmh) / params_.damper_below_kmh);
  }
  if (device_ != nullptr) {
    if (!device_->SetConstant(out.level, params_.effect_length)) ++device_errors_;
    // The damper changes slowly: sent when it moved, or before its finite length runs out.
    if (params_.damper > 0 && device_->has_damper()) {
      if (std::abs(out.damper - damper_sent_) > 0.01 || device_stopped_ ||
          now - damper_sent_at_ >= base::Nanos{params_.effect_length.ns / 2}) {
        if (!device_->SetDamper(out.damper, params_.effect_length)) ++device_errors_;
        damper_sent_ = out.damper;
        damper_sent_at_ = now;
      }
    }
    device_stopped_ = false;
    if (in.step != last_step_ && in.source_wall_ns > 0) {
      state_to_haptic_.Add(base::Nanos{base::WallNow().ns - in.source_wall_ns});
    }
  }
  last_step_ = in.step;
  ClipMeter(now, out.clipped);
  last_ = out;
  return out;
}

}  // namespace vdyn::wheel_input
