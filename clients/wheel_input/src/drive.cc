#include <algorithm>
#include <chrono>
#include <cstdio>
#include <iostream>

#include <spdlog/spdlog.h>

#include "command_support.h"
#include "vdyn/client/loop.h"
#include "vdyn/wheel_input/commands.h"
#include "vdyn/wheel_input/dds_link.h"
#include "vdyn/wheel_input/rig.h"

namespace vdyn::wheel_input {

using base::MonoTime;
using base::MonotonicNow;
using base::Nanos;

int Drive(const CommonOptions& c, const RigOptions& o, const std::atomic<bool>& stop) {
  const RigConfig::Source source =
      o.keyboard ? RigConfig::Source::kKeyboard : RigConfig::Source::kAuto;
  transport::Participant participant(c.domain);
  DdsLink link(participant, c.vehicle_id, c.source_id, c.strength);
  // A server that is there answers at once; the wait is said when it takes longer (no window
  // and no line for the whole --wait before).
  const auto wait = std::chrono::duration_cast<std::chrono::nanoseconds>(
      std::chrono::duration<double>(c.wait_s));
  const auto first = std::min(wait, std::chrono::nanoseconds(std::chrono::milliseconds(500)));
  bool found = link.WaitForParams(first, &stop) && !stop;
  if (!found && !stop && wait > first) {
    spdlog::info("vdyn-input: waiting up to {} s for vehicle {} on domain {} (--wait)", c.wait_s,
                 c.vehicle_id, c.domain);
    found = link.WaitForParams(wait - first, &stop) && !stop;
  }
  if (stop) {  // Ctrl-C while waiting (it waited out the whole --wait)
    std::cerr << "vdyn-input: stopped while waiting for vehicle " << c.vehicle_id << "\n";
    return 0;
  }
  if (!found) {
    std::vector<std::uint32_t> others;
    for (const auto& [id, vehicle] : link.view().vehicles()) others.push_back(id);
    std::cerr << "vdyn-input: no parameters of vehicle " << c.vehicle_id << " on domain "
              << c.domain << " within " << c.wait_s << " s; " << WhyNoVehicle(c, others) << "\n";
    return 1;
  }
  RigConfig cfg;
  cfg.source = source;
  if (!o.mapping.empty()) cfg.mapping_file = o.mapping;
  cfg.device_index = o.device;
  if (o.range_deg > 0) cfg.range_deg = o.range_deg;
  if (o.ffb_peak_nm > 0) cfg.ffb_peak_nm = o.ffb_peak_nm;
  cfg.ffb = !o.no_ffb;
  cfg.ffb_params.gain = o.ffb_gain;
  cfg.ffb_params.cap_nm = o.ffb_cap_nm;
  cfg.ffb_params.slew_nm_per_s = o.ffb_slew;
  cfg.ffb_params.filter_hz = o.ffb_filter_hz;
  cfg.ffb_params.damper = o.ffb_damper;
  cfg.ffb_params.damper_below_kmh = o.ffb_damper_below_kmh;
  cfg.ffb_params.effect_length = Nanos{static_cast<std::int64_t>(o.ffb_effect_ms * 1e6)};
  cfg.ffb_rate_hz = std::min(o.ffb_rate_hz, c.rate_hz);
  cfg.builder.forward_gears = static_cast<int>(o.gears);
  cfg.neutral_brake = o.neutral_brake;
  cfg.keyboard.steer_rate = o.key_steer_rate;
  cfg.window = !o.no_window;
  cfg.vehicle_id = c.vehicle_id;
  cfg.source_id = c.source_id;

  const bool want_video = source == RigConfig::Source::kKeyboard || !o.no_window;
  SdlContext sdl(want_video);
  RigLoop rig(cfg, sdl, link, link, &link);
  try {
    rig.Start();
  } catch (const std::runtime_error& e) {
    std::cerr << "vdyn-input: " << e.what() << "\n";
    return 2;
  }
  spdlog::info("vdyn-input: {} drives vehicle {} as '{}' (strength {}) at {:.0f} Hz; {}",
               rig.device_name(), c.vehicle_id, c.source_id, c.strength, c.rate_hz,
               SetUpLoopScheduling(c));
  const MonoTime start = MonotonicNow();
  client::FixedRateLoop clock(LoopPeriod(c.rate_hz), start);
  MonoTime next_status = start + base::Seconds(1);
  const Nanos cpu0 = base::ProcessCpuTime();
  while (!stop) {
    const auto tick = clock.Wait();
    if (!rig.Tick(tick.now)) break;
    if (c.status && tick.now >= next_status) {
      next_status = next_status + base::Seconds(1);
      std::printf("%s\n", rig.StatusLine().c_str());
      std::fflush(stdout);
    }
    if (o.duration_s > 0 && (tick.now - start).seconds() >= o.duration_s) break;
  }
  const double wall = (MonotonicNow() - start).seconds();
  const double cpu = (base::ProcessCpuTime() - cpu0).seconds();
  if (!o.screenshot.empty()) {
    rig.Screenshot(o.screenshot);
    rig.DrawNow();
    if (rig.window() == nullptr) std::cerr << "vdyn-input: no window to take a screenshot of\n";
  }
  std::printf(
      "%s\n  ticks skipped (this machine was busy) %llu; process CPU %.1f %% of one core "
      "over %.1f s\n",
      rig.Summary().c_str(), static_cast<unsigned long long>(clock.skipped_total()),
      wall > 0 ? 100.0 * cpu / wall : 0.0, wall);
  return 0;
}

}  // namespace vdyn::wheel_input
