// Force feedback: the steering torque the server publishes in every state (N*m at the hand wheel,
// positive turns it left) played on the wheel as one CONSTANT effect.
//
//   torque -> x gain -> low-pass filter -> cap (min of the user's cap and the device's peak;
//   samples beyond it counted by the clipping meter) -> slew limit -> x stale fade -> / peak
//   -> level in [-1, 1] (sign flipped for a device that turns the other way)
//
// Safety: when the newest state is older than 20 ms the torque fades to zero over 100 ms; after
// 250 ms, or on an emergency stop, every effect stops at once. Each update carries a finite effect
// length, so a hung client goes quiet by itself. The device is behind an interface: SDL's haptic
// layer for wheels (sdl_haptic.h), a recording fake for tests and benchmarks.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "vdyn/base/time.h"
#include "vdyn/wheel_input/latency.h"

namespace vdyn::wheel_input {

class HapticDevice {
 public:
  virtual ~HapticDevice() = default;
  // A constant force of `level` times the device's peak (positive turns the wheel left), played
  // for `length` from now unless updated again. False when the device refused (last_error()).
  virtual bool SetConstant(double level, base::Nanos length) = 0;
  // A damper of `coefficient` times the device's strongest; false when the device has none.
  virtual bool SetDamper(double coefficient, base::Nanos length) = 0;
  // Every effect off at once.
  virtual void Stop() = 0;
  virtual bool has_damper() const = 0;
  virtual const std::string& last_error() const = 0;
};

// Records every call with the time it was made (tests, benchmarks).
class RecordingHaptic : public HapticDevice {
 public:
  struct Call {
    enum class Kind { kConstant, kDamper, kStop };
    Kind kind;
    base::MonoTime at;
    double value = 0;
    base::Nanos length{};
  };
  explicit RecordingHaptic(bool has_damper = true) : has_damper_(has_damper) {
    calls.reserve(1 << 16);
  }
  bool SetConstant(double level, base::Nanos length) override;
  bool SetDamper(double coefficient, base::Nanos length) override;
  void Stop() override;
  bool has_damper() const override { return has_damper_; }
  const std::string& last_error() const override { return error_; }

  std::vector<Call> calls;
  // Called after each recorded call (a benchmark's clock).
  std::function<void(const Call&)> on_call;

 private:
  void Record(Call c);
  bool has_damper_;
  std::string error_;
};

struct FfbParams {
  double gain = 1.0;          // user gain on the server's torque
  double peak_torque_nm = 0;  // the device's torque at level 1 (0: no force feedback)
  double cap_nm = 4.0;        // the user's cap on the commanded torque
  double slew_nm_per_s = 200.0;
  double filter_hz = 40.0;  // first-order low-pass cut-off
  bool invert = false;      // the device turns right for a positive level
  base::Nanos fade_after = base::Milliseconds(20);
  base::Nanos fade_over = base::Milliseconds(100);
  base::Nanos stop_after = base::Milliseconds(250);
  base::Nanos effect_length = base::Milliseconds(100);
  double damper = 0.0;             // at standstill, fraction of the device's; 0: none
  double damper_below_kmh = 15.0;  // the damper fades out linearly up to this speed
  base::Nanos clip_window = base::Seconds(10);
  double clip_warn_fraction = 0.025;
};

// What the newest state says (FfbInput::has_state false: none yet).
struct FfbInput {
  bool has_state = false;
  double torque_nm = 0;
  double speed_kmh = 0;
  base::MonoTime received{};        // when this client took it
  std::int64_t source_wall_ns = 0;  // the server's wall clock when it wrote it (latency)
  std::uint64_t step = 0;           // identifies the state
};

struct FfbOutput {
  enum class Mode { kOff, kPlaying, kFading, kStopped, kEstop };
  Mode mode = Mode::kOff;
  double torque_nm = 0;  // commanded at the hand wheel (after cap, slew and fade)
  double level = 0;      // sent to the device
  double damper = 0;
  bool clipped = false;
};

const char* ModeName(FfbOutput::Mode m);

class ForceFeedback {
 public:
  // `device` may be null (the pipeline runs; nothing is played).
  ForceFeedback(FfbParams params, HapticDevice* device);

  FfbOutput Update(base::MonoTime now, const FfbInput& in, bool estop);
  // The device went away (unplugged) or another takes its place.
  void SetDevice(HapticDevice* device);

  const FfbParams& params() const { return params_; }
  const FfbOutput& last() const { return last_; }
  // Clipping meter: share of the updates in the last clip_window whose torque was beyond the cap.
  double clip_fraction() const;
  std::uint64_t clip_warnings() const { return clip_warnings_; }
  std::uint64_t updates() const { return updates_; }
  std::uint64_t device_errors() const { return device_errors_; }
  // From the server writing a state to the haptic update that first played it (same machine:
  // both wall clocks), per state played.
  const LatencyHistogram& state_to_haptic() const { return state_to_haptic_; }
  // Called with the warning text when the clipping meter trips (default: spdlog warning).
  std::function<void(const std::string&)> on_warning;

 private:
  void StopDevice(FfbOutput::Mode mode);
  void ClipMeter(base::MonoTime now, bool clipped);

  FfbParams params_;
  HapticDevice* device_;
  FfbOutput last_;
  bool have_time_ = false;
  base::MonoTime last_time_{};
  double filtered_ = 0;
  double slewed_ = 0;
  bool device_stopped_ = true;
  double damper_sent_ = 0;
  base::MonoTime damper_sent_at_{};
  std::uint64_t last_step_ = ~0ull;
  std::uint64_t updates_ = 0, device_errors_ = 0, clip_warnings_ = 0;
  LatencyHistogram state_to_haptic_;
  // The clipping meter: 100 slots of clip_window / 100, each with (updates, clipped).
  static constexpr int kSlots = 100;
  std::array<std::uint32_t, kSlots> slot_total_{}, slot_clipped_{};
  std::int64_t slot_index_ = -1;
  base::MonoTime meter_start_{};
  bool meter_started_ = false;
  std::int64_t last_warning_slot_ = -1'000'000;
};

}  // namespace vdyn::wheel_input
