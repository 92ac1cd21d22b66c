// vdyn-input: driver input for one vehicle over DDS, from a racing wheel with pedals, the
// keyboard, or a maneuver file; force feedback from the server's steering torque.
//
//   vdyn-input drive        the first wheel found, else the keyboard
//   vdyn-input keyboard     the keyboard, in a small window
//   vdyn-input list         the devices SDL sees, what each is recognised as, live values
//   vdyn-input calibrate    writes a wheel's mapping file (axes, pedals, buttons, FFB direction)
//   vdyn-input play FILE|demo   a maneuver played as live input (--maneuver M is the same)
//
// Input is written at a fixed rate (default 1 kHz) even when it does not change: the server's
// watchdog and the input topic's deadline expect a live writer; the strongest live writer of a
// vehicle drives it (a primary rig and a backup). Exit codes: 0 done, 1 transport failure or no
// server, 2 bad command line or input (a maneuver, a mapping file, no usable device).
#include <poll.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <iostream>
#include <map>
#include <thread>
#include <vector>

#include <SDL2/SDL.h>
#include <fmt/format.h>
#include <spdlog/spdlog.h>
#include <CLI/CLI.hpp>

#include "vdyn/base/scheduling.h"
#include "vdyn/base/text.h"
#include "vdyn/base/time.h"
#include "vdyn/cli/options.h"
#include "vdyn/client/driver_input.h"
#include "vdyn/client/loop.h"
#include "vdyn/client/session_view.h"
#include "vdyn/input.pb.h"
#include "vdyn/io/maneuver.h"
#include "vdyn/state.pb.h"
#include "vdyn/wheel_input/calibrate.h"
#include "vdyn/wheel_input/dds_link.h"
#include "vdyn/wheel_input/devices.h"
#include "vdyn/wheel_input/mapping.h"
#include "vdyn/wheel_input/rig.h"
#include "vdyn/wheel_input/sdl_haptic.h"

namespace {

namespace wi = vdyn::wheel_input;
using vdyn::base::MonoTime;
using vdyn::base::MonotonicNow;
using vdyn::base::Nanos;

// --device and --pedals: an index of SDL's device list (vdyn-input list).
constexpr vdyn::limits::Range kDeviceIndex{0, 255, false, false, "SDL device index"};

std::atomic<bool> g_stop{false};
extern "C" void OnSignal(int) {
  g_stop.store(true);
}

struct Common {
  std::uint32_t domain = 0, vehicle_id = 1;
  std::string source_id = "vdyn-input";
  std::int32_t strength = 10;
  double rate_hz = 1000.0;
  double wait_s = 10.0;
  bool status = false;
  // The 1 kHz loop's SCHED_FIFO priority where permitted (0: the normal scheduler, the default:
  // under busy-looping hogs SCHED_FIFO did not reduce the watchdog's take-overs, 2026-12-05,
  // bench/input_starvation.sh).
  int rt_priority = 0;
};

// Real-time scheduling for the calling (loop) thread where the system permits it; the line that
// says which, as vdyn-server prints it.
std::string SetUpLoopScheduling(const Common& c) {
  if (c.rt_priority == 0) return "SCHED_OTHER (--rt-priority 0)";
  return vdyn::base::SetUpRealtimeScheduling(c.rt_priority);
}

Nanos Period(double hz) {
  return Nanos{static_cast<std::int64_t>(1e9 / hz)};
}

// The vehicles the servers on the domain publish, by their parameters (kept for late joiners:
// they arrive soon after the reader matches, not always together), gathered for 1 s; empty where
// no server runs.
std::vector<std::uint32_t> VehiclesOnDomain(vdyn::transport::Participant& participant) {
  vdyn::client::SessionView view(
      participant, {.states = false,
                    .params = true,
                    .world = false,
                    .diagnostics = false,
                    .inputs = false,
                    .only_vehicle = std::nullopt});
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(1);
  while (std::chrono::steady_clock::now() < deadline) {
    (void)view.Wait(std::chrono::milliseconds(100));
    view.Poll();
  }
  std::vector<std::uint32_t> ids;
  for (const auto& [id, vehicle] : view.vehicles()) ids.push_back(id);
  return ids;
}

// Why no state or parameters of the vehicle came, for a person: no server, or servers with other
// vehicles (`others`) and how to drive one of them or add this one.
std::string WhyNoVehicle(const Common& c, const std::vector<std::uint32_t>& others) {
  if (others.empty()) return "is vdyn-server running?";
  std::string ids;
  for (const std::uint32_t id : others) ids += (ids.empty() ? "" : ",") + std::to_string(id);
  return std::string("vdyn-server there has ") + (others.size() == 1 ? "vehicle " : "vehicles ") +
         ids + ": drive " + (others.size() == 1 ? "it" : "one") + " with --vehicle-id " +
         std::to_string(others.front()) + ", or start vdyn-server with --vehicle-ids " + ids + "," +
         std::to_string(c.vehicle_id);
}

// --- play ------------------------------------------------------------------------------------

struct PlayOptions {
  std::string maneuver;
  std::string clock = "server";
  bool loop = false;
};

// A server publishes a state every step (1 kHz): this long without one, none is running (or it
// is paused).
constexpr double kSilentS = 2.0;

int Play(const Common& c, const PlayOptions& o) {
  const vdyn::Maneuver maneuver = vdyn::Maneuver::Named(o.maneuver);
  vdyn::transport::Participant participant(c.domain);
  vdyn::client::InputPublisher writer(participant, c.vehicle_id, c.source_id, c.strength);
  // This vehicle's states only (its partition): the others' are not sent here.
  vdyn::client::SessionView states(participant, {.states = true,
                                                 .params = false,
                                                 .world = false,
                                                 .diagnostics = false,
                                                 .inputs = false,
                                                 .only_vehicle = c.vehicle_id});
  if (!states.one_vehicle_fallback().empty()) {
    spdlog::warn("vdyn-input: reading every vehicle's states ({})", states.one_vehicle_fallback());
  }
  const bool server_clock = o.clock == "server";

  // The vehicle's newest simulation time (clock=server) and what its states say about this input.
  std::int64_t sim_ns = -1;
  std::uint64_t states_seen = 0, states_ours = 0;
  // Times the server's watchdog took the vehicle from this input (a state of ours, then one in
  // the watchdog's safe state): this input arrived too late (issue 31, bench/input_starvation.sh).
  std::uint64_t watchdog_takeovers = 0;
  bool was_ours = false;
  std::string other_source;  // the newest other source that drove the vehicle
  MonoTime last_state_at{};
  states.on_state = [&](const vdyn::pb::VehicleState& s, const vdyn::transport::SampleInfo&) {
    if (s.vehicle_id() != c.vehicle_id) return;
    sim_ns = s.sim_time_ns();
    ++states_seen;
    last_state_at = MonotonicNow();
    if (was_ours && s.control().watchdog_safe_state()) ++watchdog_takeovers;
    was_ours = s.input().source_id() == c.source_id;
    if (was_ours) {
      ++states_ours;
    } else if (!s.input().source_id().empty()) {
      other_source = s.input().source_id();
    }
  };
  auto poll_states = [&] {
    states.Poll();
  };
  const std::string where =
      "vehicle " + std::to_string(c.vehicle_id) + " on domain " + std::to_string(c.domain);
  if (server_clock) {
    const auto deadline =
        std::chrono::steady_clock::now() + std::chrono::duration<double>(c.wait_s);
    spdlog::info("vdyn-input: waiting up to {} s for a state of {}", c.wait_s, where);
    while (sim_ns < 0 && !g_stop && std::chrono::steady_clock::now() < deadline) {
      (void)states.Wait(std::chrono::milliseconds(50));
      poll_states();
    }
    if (g_stop) return 0;
    if (sim_ns < 0) {
      std::cerr << "vdyn-input: no state of " << where << " within " << c.wait_s << " s; "
                << WhyNoVehicle(c, VehiclesOnDomain(participant)) << "\n";
      return 1;
    }
  }
  spdlog::info(
      "vdyn-input: playing '{}' ({:.1f} s, {} clock) for vehicle {} as '{}' (strength {}); {}",
      o.maneuver, maneuver.end_time(), o.clock, c.vehicle_id, c.source_id, c.strength,
      SetUpLoopScheduling(c));

  const MonoTime wall_start = MonotonicNow();
  const std::int64_t sim_start = sim_ns;
  vdyn::client::FixedRateLoop loop_clock(Period(c.rate_hz), wall_start);
  vdyn::pb::DriverInput msg;
  bool warned_silent = false;
  double t = 0.0;
  while (!g_stop) {
    const auto tick = loop_clock.Wait();
    poll_states();
    // Silence: no server yet, or it went away or paused. The wall clock plays on; the server's
    // clock stands still without states, and the maneuver with it. Either way, it is said.
    const double silent_s = (tick.now - (states_seen > 0 ? last_state_at : wall_start)).seconds();
    if (silent_s >= kSilentS && !warned_silent) {
      warned_silent = true;
      if (states_seen == 0) {
        spdlog::warn(
            "vdyn-input: no state of {} after {:.0f} s of playing; is vdyn-server "
            "running? The maneuver plays on by the wall clock, heard by no one",
            where, kSilentS);
      } else {
        spdlog::warn(
            "vdyn-input: no state of {} for {:.0f} s, at {:.1f} s of the maneuver: "
            "vdyn-server is paused or has stopped; {}",
            where, kSilentS, t,
            server_clock ? "the maneuver waits for its clock"
                         : "the maneuver plays on by the wall clock");
      }
    } else if (silent_s < kSilentS && warned_silent) {
      warned_silent = false;
      spdlog::info("vdyn-input: states of {} again", where);
    }
    if (server_clock) {
      t = static_cast<double>(sim_ns - sim_start) * 1e-9;
    } else {
      t = (tick.now - wall_start).seconds();
    }
    if (t > maneuver.end_time()) {
      if (!o.loop) break;
      t = std::fmod(t, maneuver.end_time());
    }
    vdyn::client::FillFromManeuver(maneuver.At(t), msg);
    if (!writer.Publish(msg)) {
      std::cerr << "vdyn-input: " << writer.last_error() << "\n";
      return 1;
    }
  }
  // The outcome: whether a server took the input.
  const std::string played =
      g_stop ? "stopped at " + vdyn::base::FormatFixed(t, 1) + " s of '" + o.maneuver + "'"
             : "played '" + o.maneuver + "' to its end (" +
                   vdyn::base::FormatFixed(maneuver.end_time(), 1) + " s, " + o.clock + " clock)";
  if (states_seen == 0) {
    std::cerr << "vdyn-input: " << played << ", but no server took it: no state of " << where
              << " arrived; " << WhyNoVehicle(c, VehiclesOnDomain(participant)) << "\n";
    return g_stop ? 0 : 1;
  }
  std::string outcome = "vdyn-input: " + played + "; " + std::to_string(states_ours) + " of " +
                        std::to_string(states_seen) + " states of vehicle " +
                        std::to_string(c.vehicle_id) + " applied this input; watchdog took over " +
                        std::to_string(watchdog_takeovers) + " times";
  if (states_ours == 0 && !other_source.empty()) {
    outcome += " ('" + other_source + "' drove it: a stronger source than --strength " +
               std::to_string(c.strength) + ")";
  }
  std::printf("%s\n", outcome.c_str());
  return 0;
}

// --- drive / keyboard --------------------------------------------------------------------------

struct RigOptions {
  std::string mapping;
  int device = -1;
  double range_deg = 0;
  bool no_ffb = false;
  double ffb_gain = 1.0, ffb_cap_nm = 4.0, ffb_peak_nm = 0, ffb_rate_hz = 500, ffb_slew = 200,
         ffb_filter_hz = 40, ffb_damper = 0, ffb_damper_below_kmh = 15, ffb_effect_ms = 100;
  double gears = 6, neutral_brake = 0.3, key_steer_rate = 1.5;
  bool no_window = false;
  std::string screenshot;
  double duration_s = 0;
};

int Drive(const Common& c, const RigOptions& o, wi::RigConfig::Source source) {
  vdyn::transport::Participant participant(c.domain);
  wi::DdsLink link(participant, c.vehicle_id, c.source_id, c.strength);
  if (!link.WaitForParams(std::chrono::duration_cast<std::chrono::nanoseconds>(
          std::chrono::duration<double>(c.wait_s)))) {
    std::vector<std::uint32_t> others;
    for (const auto& [id, vehicle] : link.view().vehicles()) others.push_back(id);
    std::cerr << "vdyn-input: no parameters of vehicle " << c.vehicle_id << " on domain "
              << c.domain << " within " << c.wait_s << " s; " << WhyNoVehicle(c, others) << "\n";
    return 1;
  }
  wi::RigConfig cfg;
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

  const bool want_video = source == wi::RigConfig::Source::kKeyboard || !o.no_window;
  wi::SdlContext sdl(want_video);
  wi::RigLoop rig(cfg, sdl, link, link, &link);
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
  vdyn::client::FixedRateLoop clock(Period(c.rate_hz), start);
  MonoTime next_status = start + vdyn::base::Seconds(1);
  const Nanos cpu0 = vdyn::base::ProcessCpuTime();
  while (!g_stop) {
    const auto tick = clock.Wait();
    if (!rig.Tick(tick.now)) break;
    if (c.status && tick.now >= next_status) {
      next_status = next_status + vdyn::base::Seconds(1);
      std::printf("%s\n", rig.StatusLine().c_str());
      std::fflush(stdout);
    }
    if (o.duration_s > 0 && (tick.now - start).seconds() >= o.duration_s) break;
  }
  const double wall = (MonotonicNow() - start).seconds();
  const double cpu = (vdyn::base::ProcessCpuTime() - cpu0).seconds();
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

// --- list ------------------------------------------------------------------------------------

void PrintDevices(const std::vector<wi::DeviceInfo>& devices) {
  if (devices.empty()) {
    std::printf(
        "no joystick devices (plug in a wheel; on Linux the user needs read access to "
        "/dev/input/event*)\n");
    return;
  }
  for (const auto& d : devices) {
    std::printf("[%d] %s  %s  (%s%s)  %d axes, %d buttons, %d hats, force feedback: %s\n", d.index,
                d.name.c_str(), wi::VidPid(d.vendor_id, d.product_id).c_str(), d.type.c_str(),
                d.is_virtual ? ", virtual" : "", d.axes, d.buttons, d.hats,
                d.haptic ? "yes" : "no");
    std::printf("    recognised as: %s\n", d.recognised_as.c_str());
    if (d.kind == wi::DeviceInfo::Kind::kUserFile || d.kind == wi::DeviceInfo::Kind::kTable ||
        d.kind == wi::DeviceInfo::Kind::kGeneric) {
      const auto& m = d.mapping;
      std::string pedals;
      auto pedal = [&](const char* name, const vdyn::pb::PedalAxis& p) {
        if (!p.has_axis()) return;
        pedals += std::string(" ") + name + "=" + (p.on_pedal_device() ? "p" : "") +
                  std::to_string(p.axis()) + (p.full() < p.rest() ? " (inverted)" : "");
      };
      pedal("throttle", m.throttle());
      pedal("brake", m.brake());
      pedal("clutch", m.clutch());
      pedal("handbrake", m.handbrake());
      if (m.has_combined() && m.combined().has_axis()) {
        pedals += " throttle+brake combined=" + std::to_string(m.combined().axis());
      }
      std::printf("    steering axis %d (%.0f deg lock to lock), pedals:%s, peak torque %.1f N*m\n",
                  m.steer().axis(), m.steer().range_deg(),
                  pedals.empty() ? " none" : pedals.c_str(), m.ffb().peak_torque_nm());
      if (!m.source().empty()) std::printf("    source: %s\n", m.source().c_str());
    }
  }
}

int List(bool once, double seconds) {
  wi::SdlContext sdl(false);
  auto devices = wi::ScanDevices();
  PrintDevices(devices);
  if (once) return 0;
  std::printf("live values (Ctrl+C ends):\n");
  std::map<SDL_JoystickID, SDL_Joystick*> open;
  std::map<SDL_JoystickID, std::string> last_line;
  auto reopen = [&] {
    for (const auto& d : devices) {
      if (open.count(d.instance_id) == 0) {
        if (SDL_Joystick* js = SDL_JoystickOpen(d.index)) open[d.instance_id] = js;
      }
    }
  };
  reopen();
  const MonoTime start = MonotonicNow();
  MonoTime next_scan = start;
  vdyn::client::FixedRateLoop clock(vdyn::base::Milliseconds(100), start);
  while (!g_stop && (seconds <= 0 || (MonotonicNow() - start).seconds() < seconds)) {
    clock.Wait();
    SDL_JoystickUpdate();
    if (MonotonicNow() >= next_scan) {
      next_scan = MonotonicNow() + vdyn::base::Milliseconds(500);
      auto now_devices = wi::ScanDevices();
      for (auto it = open.begin(); it != open.end();) {
        if (SDL_JoystickGetAttached(it->second) != SDL_TRUE) {
          std::printf("unplugged: %s\n", SDL_JoystickName(it->second));
          SDL_JoystickClose(it->second);
          last_line.erase(it->first);
          it = open.erase(it);
        } else {
          ++it;
        }
      }
      for (const auto& d : now_devices) {
        if (open.count(d.instance_id) == 0) {
          std::printf("plugged in:\n");
          PrintDevices({d});
        }
      }
      devices = std::move(now_devices);
      reopen();
    }
    for (const auto& [id, js] : open) {
      std::string line = "  " + std::string(SDL_JoystickName(js)) + ":";
      for (int a = 0; a < SDL_JoystickNumAxes(js); ++a) {
        line += fmt::format(" a{}={}", a, SDL_JoystickGetAxis(js, a));
      }
      std::string pressed;
      for (int b = 0; b < SDL_JoystickNumButtons(js); ++b) {
        if (SDL_JoystickGetButton(js, b)) pressed += fmt::format(" {}", b);
      }
      line += "  buttons:" + (pressed.empty() ? std::string(" none") : pressed);
      if (line != last_line[id]) {
        std::printf("%s\n", line.c_str());
        std::fflush(stdout);
        last_line[id] = line;
      }
    }
  }
  for (auto& [id, js] : open) SDL_JoystickClose(js);
  return 0;
}

// --- calibrate -------------------------------------------------------------------------------

struct CalibrateOptions {
  int device = -1;
  int pedals = -1;
  std::string out;
  double range_deg = 0;
  bool no_ffb_test = false;
  double pedal_dead_zone = 0.02, pedal_gamma = 1.0, steer_dead_zone = 0.0;
  double timeout_s = 300;
};

// A line typed on the terminal, if one is waiting ("" for a bare Enter).
std::optional<std::string> ReadLineNow() {
  pollfd p{STDIN_FILENO, POLLIN, 0};
  if (poll(&p, 1, 0) <= 0 || (p.revents & POLLIN) == 0) return std::nullopt;
  std::string line;
  char ch = 0;
  while (read(STDIN_FILENO, &ch, 1) == 1 && ch != '\n') line += ch;
  return line;
}

int Calibrate(const CalibrateOptions& o) {
  wi::SdlContext sdl(false);
  const auto devices = wi::ScanDevices();
  const wi::DeviceInfo* wheel = nullptr;
  for (const auto& d : devices) {
    if (o.device >= 0 ? d.index == o.device : d.kind != wi::DeviceInfo::Kind::kNotAWheel) {
      wheel = &d;
      break;
    }
  }
  if (wheel == nullptr && o.device < 0 && !devices.empty()) wheel = &devices.front();
  if (wheel == nullptr) {
    std::cerr << "vdyn-input: "
              << (o.device >= 0 ? "no device " + std::to_string(o.device) : "no device")
              << " to calibrate (vdyn-input list shows what SDL sees)\n";
    return 2;
  }
  const wi::DeviceInfo* pedals = nullptr;
  if (o.pedals >= 0) {
    for (const auto& d : devices) {
      if (d.index == o.pedals && d.index != wheel->index) pedals = &d;
    }
    if (pedals == nullptr) {
      std::cerr << "vdyn-input: no pedal device " << o.pedals << "\n";
      return 2;
    }
  }
  SDL_Joystick* js = SDL_JoystickOpen(wheel->index);
  SDL_Joystick* pjs = pedals ? SDL_JoystickOpen(pedals->index) : nullptr;
  if (js == nullptr || (pedals && pjs == nullptr)) {
    std::cerr << "vdyn-input: cannot open the device: " << SDL_GetError() << "\n";
    return 2;
  }
  wi::Calibrator::Options opt;
  opt.base = wheel->kind == wi::DeviceInfo::Kind::kNotAWheel ||
                     wheel->kind == wi::DeviceInfo::Kind::kBrokenFile
                 ? wi::GenericWheel(wheel->vendor_id, wheel->product_id, wheel->axes)
                 : wheel->mapping;
  if (wheel->kind == wi::DeviceInfo::Kind::kNotAWheel) opt.base.set_name(wheel->name);
  opt.vendor_id = wheel->vendor_id;
  opt.product_id = wheel->product_id;
  if (pedals) {
    opt.pedal_vendor_id = pedals->vendor_id;
    opt.pedal_product_id = pedals->product_id;
  }
  opt.range_deg = o.range_deg > 0
                      ? o.range_deg
                      : (opt.base.steer().has_range_deg() ? opt.base.steer().range_deg() : 900.0);
  opt.pedal_dead_zone = o.pedal_dead_zone;
  opt.pedal_gamma = o.pedal_gamma;
  opt.steer_dead_zone = o.steer_dead_zone;
  std::unique_ptr<wi::SdlHaptic> haptic;
  if (!o.no_ffb_test) {
    std::string why;
    haptic = wi::SdlHaptic::Open(js, &why);
    if (!haptic) std::printf("(force-feedback direction test skipped: %s)\n", why.c_str());
  }
  opt.ffb = haptic != nullptr;
  wi::Calibrator cal(opt);
  std::printf("Calibrating [%d] %s %s; %s\n", wheel->index, wheel->name.c_str(),
              wi::VidPid(wheel->vendor_id, wheel->product_id).c_str(),
              pedals ? ("pedal set [" + std::to_string(pedals->index) + "] " + pedals->name).c_str()
                     : "pedals on the wheel");
  std::printf(
      "The wheel's rotation lock to lock is taken as %.0f degrees (--range-deg changes it).\n",
      opt.range_deg);
  const MonoTime start = MonotonicNow();
  vdyn::client::FixedRateLoop clock(vdyn::base::Milliseconds(5), start);
  std::string prompt;
  std::size_t logged = 0;
  wi::RawFrame frame;
  double playing = 0;
  while (!g_stop && !cal.done()) {
    const auto tick = clock.Wait();
    if ((tick.now - start).seconds() > o.timeout_s) {
      std::cerr << "vdyn-input: calibration not finished within " << o.timeout_s << " s\n";
      if (haptic) haptic->Stop();
      return 1;
    }
    SDL_JoystickUpdate();
    if (SDL_JoystickGetAttached(js) != SDL_TRUE) {
      std::cerr << "vdyn-input: the device was unplugged; calibration abandoned\n";
      return 1;
    }
    wi::ReadJoysticks(js, pjs, frame);
    cal.Feed(tick.now, frame);
    if (auto line = ReadLineNow()) {
      if (*line == "s" || *line == "S") {
        cal.Skip(tick.now);
      } else {
        cal.Confirm(tick.now);
      }
    }
    if (haptic) {
      const double level = cal.ffb_level();
      if (level != 0.0) {
        haptic->SetConstant(level, vdyn::base::Milliseconds(200));
      } else if (playing != 0.0) {
        haptic->Stop();
      }
      playing = level;
    }
    for (; logged < cal.log().size(); ++logged)
      std::printf("  ok: %s\n", cal.log()[logged].c_str());
    if (cal.Prompt() != prompt && !cal.done()) {
      prompt = cal.Prompt();
      std::printf("> %s\n", prompt.c_str());
    }
    std::fflush(stdout);
  }
  if (haptic) haptic->Stop();
  if (!cal.done()) return 1;
  const vdyn::pb::WheelMapping result = cal.result();
  const auto why = wi::ValidateMapping(result, wheel->axes, wheel->buttons);
  if (!why.empty()) {
    std::cerr << "vdyn-input: the calibration cannot be used:";
    for (const auto& w : why) std::cerr << "\n  " << w;
    std::cerr << "\n";
    return 1;
  }
  const std::filesystem::path out =
      o.out.empty() ? wi::DefaultMappingPath(wheel->vendor_id, wheel->product_id)
                    : std::filesystem::path(o.out);
  wi::WriteMappingFile(out, result);
  std::printf("\nwrote %s:\n%s", out.string().c_str(), wi::DumpMappingText(result).c_str());
  if (js) SDL_JoystickClose(js);
  if (pjs) SDL_JoystickClose(pjs);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "vdyn-input: drive a vdyn vehicle over DDS with a wheel, the keyboard or a maneuver"};
  app.require_subcommand(0, 1);
  app.fallthrough();
  Common c;
  app.add_option("--domain", c.domain, "DDS domain id")
      ->check(vdyn::cli::WholeInRange(vdyn::limits::kDomainId))
      ->capture_default_str();
  app.add_option("--vehicle-id", c.vehicle_id, "Vehicle to drive")
      ->check(vdyn::cli::VehicleId())
      ->capture_default_str();
  app.add_option("--source-id", c.source_id, "This source's name (shown in the state)")
      ->check(vdyn::cli::Id("source id"))
      ->capture_default_str();
  app.add_option("--strength", c.strength,
                 "Ownership strength: the strongest live source drives (primary rig > backup)")
      ->check(vdyn::cli::WholeInRange(vdyn::limits::kStrength))
      ->capture_default_str();
  app.add_option("--rate-hz", c.rate_hz, "Input messages per second")
      ->check(vdyn::cli::InRange(vdyn::limits::kRateHz))
      ->capture_default_str();
  app.add_option("--wait", c.wait_s, "Seconds to wait for the server (its state or parameters)")
      ->check(vdyn::cli::InRange(vdyn::limits::kWaitS))
      ->capture_default_str();
  app.add_flag("--status", c.status, "Print a status line every second");
  app.add_option("--rt-priority", c.rt_priority,
                 "SCHED_FIFO priority of the 1 kHz loop where permitted (0: the normal scheduler)")
      ->check(vdyn::cli::WholeInRange({0, 99, false, false, "SCHED_FIFO priority"}))
      ->capture_default_str();
  // Today's form of playback, kept: vdyn-input --maneuver M is vdyn-input play M.
  PlayOptions play_opt;
  app.add_option("--maneuver", play_opt.maneuver, "Maneuver CSV to play, or 'demo' (as 'play')");
  auto add_play = [&](CLI::App* a) {
    a->add_option("--clock", play_opt.clock,
                  "Maneuver time: 'server' (the vehicle's simulation time) or 'wall'")
        ->check(CLI::IsMember({"server", "wall"}))
        ->capture_default_str();
    a->add_flag("--loop", play_opt.loop, "Start the maneuver again at its end");
  };
  add_play(&app);

  CLI::App* play = app.add_subcommand("play", "Play a maneuver (CSV file or 'demo') as live input");
  play->add_option("maneuver", play_opt.maneuver, "Maneuver CSV, or 'demo'")->required();
  add_play(play);

  RigOptions rig;
  auto add_rig = [&](CLI::App* a, bool wheel) {
    if (wheel) {
      a->add_option("--mapping", rig.mapping,
                    "Wheel mapping file (default: the user's, else the table)");
      a->add_option("--device", rig.device,
                    "SDL device index (vdyn-input list); default: the first wheel")
          ->check(vdyn::cli::WholeInRange(kDeviceIndex));
      a->add_option("--range-deg", rig.range_deg, "The wheel's rotation lock to lock, degrees")
          ->check(vdyn::cli::InRange(vdyn::limits::kWheelRangeDeg));
      a->add_flag("--no-ffb", rig.no_ffb, "No force feedback");
      a->add_option("--ffb-gain", rig.ffb_gain, "Gain on the server's steering torque")
          ->check(vdyn::cli::InRange(vdyn::limits::kFfbGain))
          ->capture_default_str();
      a->add_option("--ffb-cap-nm", rig.ffb_cap_nm, "Largest torque played, N*m")
          ->check(vdyn::cli::InRange(vdyn::limits::kTorqueNm))
          ->capture_default_str();
      a->add_option("--ffb-peak-nm", rig.ffb_peak_nm,
                    "The device's torque at full level, N*m (default: the mapping's)")
          ->check(vdyn::cli::InRange(vdyn::limits::kTorqueNm));
      a->add_option("--ffb-rate-hz", rig.ffb_rate_hz, "Force feedback updates per second")
          ->check(vdyn::cli::InRange(vdyn::limits::kFfbRateHz))
          ->capture_default_str();
      a->add_option("--ffb-slew", rig.ffb_slew, "Torque slew limit, N*m/s")
          ->check(vdyn::cli::InRange(vdyn::limits::kFfbSlewNmPerS))
          ->capture_default_str();
      a->add_option("--ffb-filter-hz", rig.ffb_filter_hz, "Torque low-pass cut-off, Hz")
          ->check(vdyn::cli::InRange(vdyn::limits::kFfbFilterHz))
          ->capture_default_str();
      a->add_option("--ffb-damper", rig.ffb_damper,
                    "Damper at standstill (fraction of the device's)")
          ->check(vdyn::cli::InRange(vdyn::limits::kFfbDamper))
          ->capture_default_str();
      a->add_option("--ffb-damper-below-kmh", rig.ffb_damper_below_kmh,
                    "The damper fades out up to this speed")
          ->check(vdyn::cli::InRange(vdyn::limits::kSpeedKmh))
          ->capture_default_str();
      a->add_option("--ffb-effect-ms", rig.ffb_effect_ms, "Length of each effect update, ms")
          ->check(vdyn::cli::InRange(vdyn::limits::kFfbEffectMs))
          ->capture_default_str();
      a->add_option("--neutral-brake", rig.neutral_brake, "Brake while the wheel is unplugged")
          ->check(vdyn::cli::InRange(vdyn::limits::kBrake))
          ->capture_default_str();
      a->add_flag("--no-window", rig.no_window, "No window (the wheel needs none)");
    }
    a->add_option("--gears", rig.gears, "Forward gears the paddles count to")
        ->type_name("INT")
        ->check(vdyn::cli::WholeInRange(vdyn::limits::kGears))
        ->capture_default_str();
    a->add_option("--key-steer-rate", rig.key_steer_rate, "Keyboard steering, full lock per second")
        ->check(vdyn::cli::InRange(vdyn::limits::kKeyRatePerS))
        ->capture_default_str();
    a->add_option("--screenshot", rig.screenshot, "Write the window to this PNG at the end");
    a->add_option("--duration", rig.duration_s, "Stop after this many seconds (default: Ctrl+C)")
        ->check(vdyn::cli::InRange(vdyn::limits::kDurationS));
  };
  CLI::App* drive =
      app.add_subcommand("drive", "Drive with the first wheel found, else the keyboard");
  add_rig(drive, true);
  CLI::App* keyboard = app.add_subcommand("keyboard", "Drive with the keyboard (a small window)");
  add_rig(keyboard, false);

  bool list_once = false;
  double list_seconds = 0;
  CLI::App* list =
      app.add_subcommand("list", "The devices SDL sees and what each is recognised as, live");
  list->add_flag("--once", list_once, "Print the devices and end");
  list->add_option("--seconds", list_seconds, "Show live values this long (default: until Ctrl+C)")
      ->check(vdyn::cli::InRange(vdyn::limits::kDurationS));

  CalibrateOptions cal;
  CLI::App* calibrate =
      app.add_subcommand("calibrate", "Write a wheel's mapping file, step by step");
  calibrate->add_option("--device", cal.device, "SDL device index (default: the first wheel)")
      ->check(vdyn::cli::WholeInRange(kDeviceIndex));
  calibrate->add_option("--pedals", cal.pedals, "SDL device index of a separate pedal set")
      ->check(vdyn::cli::WholeInRange(kDeviceIndex));
  calibrate->add_option("--out", cal.out,
                        "Mapping file to write (default: the user's for this wheel)");
  calibrate->add_option("--range-deg", cal.range_deg, "The wheel's rotation lock to lock, degrees")
      ->check(vdyn::cli::InRange(vdyn::limits::kWheelRangeDeg));
  calibrate->add_option("--pedal-dead-zone", cal.pedal_dead_zone, "Pedal dead zone (fraction)")
      ->check(vdyn::cli::InRange(vdyn::limits::kDeadZone))
      ->capture_default_str();
  calibrate->add_option("--pedal-gamma", cal.pedal_gamma, "Pedal curve exponent")
      ->check(vdyn::cli::InRange(vdyn::limits::kPedalGamma))
      ->capture_default_str();
  calibrate->add_option("--steer-dead-zone", cal.steer_dead_zone, "Steering dead zone (fraction)")
      ->check(vdyn::cli::InRange(vdyn::limits::kDeadZone))
      ->capture_default_str();
  calibrate->add_flag("--no-ffb-test", cal.no_ffb_test, "Skip the force-feedback direction test");
  calibrate->add_option("--timeout", cal.timeout_s, "Give up after this many seconds")
      ->check(vdyn::cli::InRange(vdyn::limits::kWaitS))
      ->capture_default_str();

  // The options before the command are taken after it too; each command's --help says so.
  for (CLI::App* command : {play, drive, keyboard, list, calibrate}) {
    command->footer(
        "Before or after the command: --domain N, --vehicle-id ID, --source-id NAME, "
        "--strength N, --rate-hz HZ, --wait S, --status (vdyn-input --help).");
  }
  if (const int code = vdyn::cli::Parse(app, argc, argv); code >= 0) return code;
  std::signal(SIGINT, OnSignal);
  std::signal(SIGTERM, OnSignal);
  try {
    if (*play || (app.get_subcommands().empty() && !play_opt.maneuver.empty())) {
      return Play(c, play_opt);
    }
    if (*drive) return Drive(c, rig, wi::RigConfig::Source::kAuto);
    if (*keyboard) return Drive(c, rig, wi::RigConfig::Source::kKeyboard);
    if (*list) return List(list_once, list_seconds);
    if (*calibrate) return Calibrate(cal);
    std::cerr
        << "vdyn-input: choose what drives: drive, keyboard, list, calibrate, or play FILE|demo "
           "(--help)\n";
    return 2;
  } catch (const vdyn::ManeuverError& e) {
    std::cerr << "vdyn-input: " << e.what() << "\n";
    return 2;
  } catch (const wi::MappingError& e) {
    std::cerr << "vdyn-input: " << e.what() << "\n";
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "vdyn-input: " << e.what() << "\n";
    return 1;
  }
}
