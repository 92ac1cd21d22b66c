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
// server, 2 bad command line or input (a maneuver, a mapping file, no usable device).#include
// <atomic>
#include <csignal>
#include <iostream>

#include <CLI/CLI.hpp>

#include "vdyn/cli/options.h"
#include "vdyn/io/maneuver.h"
#include "vdyn/wheel_input/commands.h"
#include "vdyn/wheel_input/mapping.h"

namespace {

namespace wi = vdyn::wheel_input;

// --device and --pedals: an index of SDL's device list (vdyn-input list).
constexpr vdyn::limits::Range kDeviceIndex{0, 255, false, false, "SDL device index"};

std::atomic<bool> g_stop{false};
extern "C" void OnSignal(int) {
  g_stop.store(true);
}

// The options every command takes, before or after its name.
void AddCommonOptions(CLI::App& app, wi::CommonOptions& c) {
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
}

// drive's options (`wheel`) or keyboard's.
void AddRigOptions(CLI::App* a, wi::RigOptions& rig, bool wheel) {
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
    a->add_option("--ffb-damper", rig.ffb_damper, "Damper at standstill (fraction of the device's)")
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
}

void AddCalibrateOptions(CLI::App* calibrate, wi::CalibrateOptions& cal) {
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
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "vdyn-input: drive a vdyn vehicle over DDS with a wheel, the keyboard or a maneuver"};
  app.require_subcommand(0, 1);
  app.fallthrough();
  wi::CommonOptions c;
  AddCommonOptions(app, c);
  // Today's form of playback, kept: vdyn-input --maneuver M is vdyn-input play M.
  wi::PlayOptions play_opt;
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

  wi::RigOptions rig;
  CLI::App* drive =
      app.add_subcommand("drive", "Drive with the first wheel found, else the keyboard");
  AddRigOptions(drive, rig, true);
  CLI::App* keyboard = app.add_subcommand("keyboard", "Drive with the keyboard (a small window)");
  AddRigOptions(keyboard, rig, false);

  bool list_once = false;
  double list_seconds = 0;
  CLI::App* list =
      app.add_subcommand("list", "The devices SDL sees and what each is recognised as, live");
  list->add_flag("--once", list_once, "Print the devices and end");
  list->add_option("--seconds", list_seconds, "Show live values this long (default: until Ctrl+C)")
      ->check(vdyn::cli::InRange(vdyn::limits::kDurationS));

  wi::CalibrateOptions cal;
  CLI::App* calibrate =
      app.add_subcommand("calibrate", "Write a wheel's mapping file, step by step");
  AddCalibrateOptions(calibrate, cal);

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
      return wi::Play(c, play_opt, g_stop);
    }
    if (*drive || *keyboard) {
      rig.keyboard = keyboard->parsed();
      return wi::Drive(c, rig, g_stop);
    }
    if (*list) return wi::List(list_once, list_seconds, g_stop);
    if (*calibrate) return wi::Calibrate(cal, g_stop);
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
