// vdyn-telemetry: one vehicle's states as the UDP telemetry rig software reads - OutSim for
// motion platforms and OutGauge for dashboards (Live for Speed's packets, also sent by BeamNG;
// SimHub, SimTools and the like read them) - at fixed rates, to every address given.
//
//   vdyn-telemetry --vehicle-id 1 --outsim 192.168.1.20:4123 --outgauge 127.0.0.1:4444
//
// Exit codes: 0 done (SIGINT, SIGTERM, --duration), 1 transport failure, 2 bad command line.
#include <atomic>
#include <csignal>
#include <cstdio>
#include <iostream>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include <CLI/CLI.hpp>

#include "vdyn/base/limits.h"
#include "vdyn/base/time.h"
#include "vdyn/cli/options.h"
#include "vdyn/telemetry/bridge.h"
#include "vdyn/transport/dds.h"

namespace {

std::atomic<bool> g_stop{false};
extern "C" void OnSignal(int) {
  g_stop.store(true);
}

}  // namespace

int main(int argc, char** argv) {
  namespace limits = vdyn::limits;
  namespace cli = vdyn::cli;
  CLI::App app{
      "vdyn-telemetry: a vehicle's states as OutSim (motion platforms) and OutGauge (dashboards) "
      "UDP packets, Live for Speed's layouts (docs/formats.md)"};
  std::uint32_t domain = 0, vehicle_id = 1;
  std::vector<std::string> outsim, outgauge;
  double outsim_hz = 100, outgauge_hz = 60, stale_ms = 500, duration_s = 0;
  std::int32_t outsim_id = 0, outgauge_id = 0;
  std::string car = "VDYN";
  bool no_status = false;
  app.add_option("--domain", domain, "DDS domain id")
      ->check(cli::WholeInRange(limits::kDomainId))
      ->capture_default_str();
  app.add_option("--vehicle-id", vehicle_id, "Vehicle whose states are sent")
      ->check(cli::VehicleId())
      ->capture_default_str();
  app.add_option("--outsim", outsim, "OutSim destination HOST:PORT (repeat for several)");
  app.add_option("--outgauge", outgauge, "OutGauge destination HOST:PORT (repeat for several)");
  app.add_option("--outsim-hz", outsim_hz, "OutSim packets per second")
      ->check(cli::InRange(limits::kTelemetryRateHz))
      ->capture_default_str();
  app.add_option("--outgauge-hz", outgauge_hz, "OutGauge packets per second")
      ->check(cli::InRange(limits::kTelemetryRateHz))
      ->capture_default_str();
  app.add_option("--outsim-id", outsim_id, "Append this ID to OutSim packets (68 bytes)")
      ->check(cli::WholeInRange(limits::kTelemetryId));
  app.add_option("--outgauge-id", outgauge_id, "Append this ID to OutGauge packets (96 bytes)")
      ->check(cli::WholeInRange(limits::kTelemetryId));
  app.add_option("--stale-ms", stale_ms,
                 "Send nothing while the newest state is older than this, ms")
      ->check(cli::InRange(limits::kStaleMs))
      ->capture_default_str();
  app.add_option("--car", car, "OutGauge car name: 1 to 4 letters, digits, _ or -")->capture_default_str();
  app.add_option("--duration", duration_s, "Stop after this many seconds (default: run on)")
      ->check(cli::InRange(limits::kDurationS));
  app.add_flag("--no-status", no_status, "No status line every second");
  if (const int rc = cli::Parse(app, argc, argv); rc >= 0) return rc;

  auto usage = [](const std::string& why) {
    std::cerr << "vdyn-telemetry: " << why << "\n";
    return 2;
  };
  if (outsim.empty() && outgauge.empty()) {
    return usage("give at least one destination: --outsim HOST:PORT or --outgauge HOST:PORT");
  }
  if (car.empty() || car.size() > 4 ||
      car.find_first_not_of("ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789_-") !=
          std::string::npos) {
    return usage("--car '" + car + "': 1 to 4 letters, digits, '_' or '-'");
  }
  vdyn::telemetry::BridgeConfig cfg;
  for (auto [texts, out, flag] : {std::tuple{&outsim, &cfg.outsim, "--outsim"},
                                  std::tuple{&outgauge, &cfg.outgauge, "--outgauge"}}) {
    for (const std::string& t : *texts) {
      std::string error;
      const auto e = vdyn::telemetry::ResolveEndpoint(t, error);
      if (!e) return usage(std::string(flag) + " " + error);
      out->push_back(*e);
    }
  }
  cfg.vehicle_id = vehicle_id;
  cfg.outsim_hz = outsim_hz;
  cfg.outgauge_hz = outgauge_hz;
  cfg.outsim_id = outsim_id;
  cfg.outgauge_id = outgauge_id;
  cfg.stale_after = vdyn::base::Nanos{static_cast<std::int64_t>(stale_ms * 1e6)};
  cfg.car = car;

  std::signal(SIGINT, OnSignal);
  std::signal(SIGTERM, OnSignal);
  try {
    vdyn::transport::Participant participant(domain);
    vdyn::telemetry::Bridge bridge(participant, cfg);
    std::atomic<bool> stop{false};
    const vdyn::base::MonoTime start = vdyn::base::MonotonicNow();
    const vdyn::base::Nanos cpu0 = vdyn::base::ProcessCpuTime();
    std::thread watch([&] {
      // Turns a signal or the end of --duration into the bridge's stop flag.
      while (!g_stop &&
             (duration_s <= 0 || (vdyn::base::MonotonicNow() - start).seconds() < duration_s)) {
        vdyn::base::SleepUntil(vdyn::base::MonotonicNow() + vdyn::base::Milliseconds(20));
      }
      stop = true;
    });
    bridge.Run(
        stop,
        [](const std::string& line) {
          std::printf("%s\n", line.c_str());
          std::fflush(stdout);
        },
        no_status ? vdyn::base::Nanos{0} : vdyn::base::Seconds(1));
    g_stop = true;
    watch.join();
    const double wall = (vdyn::base::MonotonicNow() - start).seconds();
    const double cpu = (vdyn::base::ProcessCpuTime() - cpu0).seconds();
    std::printf("%s\n  process CPU %.1f %% of one core over %.1f s\n", bridge.Summary().c_str(),
                wall > 0 ? 100.0 * cpu / wall : 0.0, wall);
  } catch (const std::exception& e) {
    std::cerr << "vdyn-telemetry: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
