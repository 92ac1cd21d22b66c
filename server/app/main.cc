// vdyn-server: the vehicle-dynamics simulation server.
//
// Modes: real time over DDS (the default), lockstep over DDS (--lockstep), batch drives
// (--batch, --demo), and the parameter/maneuver dumps. Exit codes: 0 success, 1 the simulation
// failed (non-finite state), 2 bad command line or input file, 3 lockstep client gone.
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <memory>
#include <numbers>
#include <optional>
#include <thread>

#include <csignal>

#include <CLI/CLI.hpp>
#include <spdlog/spdlog.h>

#include "vdyn/cli/options.h"

#include "vdyn/base/progress.h"
#include "vdyn/bridge/convert.h"
#include "vdyn/bridge/params.h"
#include "vdyn/bridge/tire_curves.h"
#include "vdyn/bridge/world_files.h"
#include "vdyn/io/maneuver.h"
#include "vdyn/io/tire_file.h"
#include "vdyn/runtime/batch.h"
#include "vdyn/runtime/server_node.h"

namespace {

std::atomic<bool> g_stop{false};
extern "C" void OnSignal(int) { g_stop.store(true); }

constexpr double kDeg = std::numbers::pi / 180.0;

struct Options {
  bool batch = false;
  bool demo = false;
  bool dump_vehicle = false;
  std::string dump_maneuver;
  std::string world = "facility";
  vdyn::WorldFileOptions world_file;
  std::string world_up = "z";
  std::string vehicle;
  std::string model;  // "paper" or "full": overrides the parameters' model
  std::string maneuver;
  std::optional<double> duration;
  std::string csv;
  int csv_every = 1;
  double step_ms = 1.0;
  std::vector<double> spawn;
  double speed_kmh = 0.0;
  bool quiet = false;
  // Networked modes.
  bool lockstep = false;
  std::uint32_t domain = 0;
  std::string server_id = "vdyn";
  std::vector<std::string> vehicle_id_entries = {"1"};  // ids and ranges (1..256)
  std::vector<std::uint32_t> vehicle_ids;
  int max_vehicles = 64;
  int step_threads = 0;  // 0: chosen from --max-vehicles (DefaultStepThreads)
  double watchdog_ms = vdyn::limits::kDefaultWatchdogMs;
  double lockstep_timeout_s = 10.0;
  int rt_priority = 50;
  int state_writer_nice = 0;
  bool status = false;
  bool no_status = false;
  std::string stats_out;
  // Tyres: a .tir file for every wheel, the front ones, the rear ones; the curves of one.
  std::string tire, tire_front, tire_rear;
  std::string tire_curves;
  std::vector<double> fz;
};

// The tyre files of the command line on their wheels (over --vehicle's), checked.
void ApplyTires(const Options& o, vdyn::pb::VehicleParams& p) {
  if (o.tire.empty() && o.tire_front.empty() && o.tire_rear.empty()) return;
  vdyn::pb::WheelParams* wheels[] = {p.mutable_lf(), p.mutable_rf(), p.mutable_lr(),
                                     p.mutable_rr()};
  for (int w = 0; w < vdyn::kNumWheels; ++w) {
    const std::string& file = vdyn::IsFront(w) && !o.tire_front.empty()   ? o.tire_front
                              : !vdyn::IsFront(w) && !o.tire_rear.empty() ? o.tire_rear
                                                                          : o.tire;
    if (!file.empty()) *wheels[w]->mutable_magic_formula() = vdyn::ReadTireFile(file);
  }
  const auto issues = vdyn::ValidateVehicleParams(p);
  if (!issues.empty()) throw vdyn::ParamsError("--tire: " + vdyn::FormatIssues(issues));
}

// --tire-curves FILE [--fz N,..]: the tyre's characteristic curves as CSV on stdout.
int RunTireCurves(const Options& o) {
  const vdyn::MagicFormula mf = vdyn::MagicFormulaFromProto(vdyn::ReadTireFile(o.tire_curves));
  std::cout << vdyn::TireCurvesCsv(mf, o.fz);
  return 0;
}

void AddTireOptions(CLI::App& app, Options& o) {
  app.add_option("--tire", o.tire,
                 "A Magic Formula tyre (.tir, MF 6.1 / 6.2) on every wheel, over --vehicle's");
  app.add_option("--tire-front", o.tire_front, "A .tir tyre on the front wheels (over --tire)");
  app.add_option("--tire-rear", o.tire_rear, "A .tir tyre on the rear wheels (over --tire)");
  app.add_option("--tire-curves", o.tire_curves,
                 "Print a .tir tyre's characteristic curves as CSV (Fy, Mz over alpha; Fx over "
                 "kappa; combined slip) and exit");
  app.add_option("--fz", o.fz, "--tire-curves: the loads, N (default 0.5, 1, 1.5 x FNOMIN)")
      ->delimiter(',')
      ->check(vdyn::cli::InRange({0, 1e6, true, false, "load, N"}));
}

vdyn::pb::VehicleParams LoadParams(const Options& o) {
  vdyn::pb::VehicleParams p =
      o.vehicle.empty() ? vdyn::DefaultVehicleParams() : vdyn::LoadVehicleParamsFile(o.vehicle);
  ApplyTires(o, p);
  if (o.model == "paper") p.set_model(vdyn::pb::VEHICLE_MODEL_PAPER);
  if (o.model == "full") p.set_model(vdyn::pb::VEHICLE_MODEL_FULL);
  if (!o.model.empty()) {
    const auto issues = vdyn::ValidateVehicleParams(p);
    if (!issues.empty()) {
      throw vdyn::ParamsError("--model " + o.model + ": " + vdyn::FormatIssues(issues));
    }
  }
  return p;
}

std::shared_ptr<const vdyn::World> LoadWorldFrom(const Options& o) {
  vdyn::WorldFileOptions wfo = o.world_file;
  wfo.up_axis = o.world_up.empty() ? 'z' : o.world_up[0];
  std::shared_ptr<const vdyn::World> world = vdyn::LoadWorld(o.world, wfo);
  const vdyn::Terrain& t = world->terrain;
  if (t.dropped_triangles() > 0) {
    spdlog::warn("{}: {} of {} triangles dropped (degenerate, or with a vertex that is not a finite "
                 "number or lies beyond 1e9 m); {} kept",
                 o.world, t.dropped_triangles(), t.dropped_triangles() + t.triangle_count(),
                 t.triangle_count());
  }
  if (t.embree_errors() > 0) {
    spdlog::warn("{}: Embree reported {} error(s) while building the terrain (last code {})",
                 o.world, t.embree_errors(), t.last_embree_error());
  }
  if (!o.spawn.empty()) {
    auto w = std::const_pointer_cast<vdyn::World>(world);
    w->spawn = {o.spawn[0], o.spawn[1], o.spawn[2] * kDeg};
  }
  return world;
}

// Without --step-threads: one thread per 128 vehicles, at most one per hardware thread (2 for 256
// on two cores). A second stepping thread costs more than it parallelises while other processes
// share the cores (the loop and the worker wake each other every step): at 128 vehicles the
// server alone took 59-61 % of a core on one thread against 72-77 % on two, and beside a recorder
// and 8 rigs 92-103 % against 104-113 %, with about half the worst lateness (bench/README.md,
// "One stepping thread up to 128").
int DefaultStepThreads(int max_vehicles) {
  const int hardware = std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
  return std::clamp((max_vehicles + 127) / 128, 1, hardware);
}

// Which of the server's modes the command line asks for, and an option of another mode it gives:
// the reason, or empty.
std::string ModeConflict(const CLI::App& app, const Options& o) {
  auto given = [&app](const char* name) { return app.count(name) > 0; };
  std::vector<std::string> modes;  // the one-shot commands and the batch
  for (const char* m : {"--dump-vehicle", "--dump-maneuver", "--tire-curves"})
    if (given(m)) modes.push_back(m);
  const bool batch = o.batch || o.demo;
  if (batch) modes.push_back(o.demo ? "--demo" : "--batch");
  if (o.lockstep) modes.push_back("--lockstep");
  if (modes.size() > 1) return modes[0] + " and " + modes[1] + " are two things to do: give one";
  if (given("--fz") && !given("--tire-curves")) return "--fz is for --tire-curves";
  if (!batch) {
    for (const char* opt : {"--maneuver", "--csv", "--csv-every", "--quiet"}) {
      if (given(opt)) {
        return std::string(opt) +
               " is for --batch (or --demo): a networked server drives from its clients and "
               "writes no CSV (vdyn-recorder records and exports it)";
      }
    }
  }
  if (batch || !modes.empty()) {
    const std::string mode = modes.empty() ? "--batch" : modes[0];
    for (const char* opt : {"--domain", "--server-id", "--vehicle-ids", "--max-vehicles",
                            "--step-threads", "--watchdog-ms", "--lockstep-timeout", "--rt-priority",
                            "--state-writer-nice", "--status", "--no-status", "--stats-out"}) {
      if (given(opt) && !(mode == "--lockstep")) {
        return std::string(opt) + " is for a networked server; " + mode + " runs without one";
      }
    }
  }
  if (o.lockstep && given("--duration")) {
    return "--duration is for real time and --batch: a lockstep server steps as its client asks "
           "and stops after --lockstep-timeout without a request";
  }
  if (!o.lockstep && given("--lockstep-timeout")) return "--lockstep-timeout is for --lockstep";
  return {};
}

// What the parsed command line asks that cannot be done, said as one (exit 2); fills the
// vehicle ids from their entries.
std::string CheckCommandLine(const CLI::App& app, Options& o) {
  o.vehicle_ids = vdyn::cli::ExpandVehicleIds(o.vehicle_id_entries);
  // A vehicle listed twice is a slip in the list, said as one (not "vehicle 1 exists already").
  for (auto id = o.vehicle_ids.begin(); id != o.vehicle_ids.end(); ++id) {
    if (std::find(o.vehicle_ids.begin(), id, *id) != id) {
      return "--vehicle-ids: vehicle " + std::to_string(*id) + " is listed twice";
    }
  }
  // Options of another mode than the one run are refused, not ignored (a networked server took
  // --csv and wrote nothing; --lockstep ran past --duration).
  if (std::string why = ModeConflict(app, o); !why.empty()) return why;
  // More vehicles listed than the server may run: said with the option that raises the limit.
  if (o.vehicle_ids.size() > static_cast<std::size_t>(o.max_vehicles)) {
    return "--vehicle-ids lists " + std::to_string(o.vehicle_ids.size()) +
           " vehicles and --max-vehicles is " + std::to_string(o.max_vehicles) +
           ": raise --max-vehicles to " + std::to_string(o.vehicle_ids.size()) + " (at most " +
           std::to_string(static_cast<int>(vdyn::limits::kMaxVehicles.hi)) + ") or list fewer";
  }
  return {};
}

int RunNetworked(const Options& o) {
  vdyn::ServerOptions so;
  so.mode = o.lockstep ? vdyn::ServerOptions::Mode::kLockstep
                       : vdyn::ServerOptions::Mode::kRealtime;
  so.domain_id = o.domain;
  so.vehicle_ids = o.vehicle_ids;
  so.start_speed_mps = o.speed_kmh / 3.6;
  so.session.max_vehicles = static_cast<std::size_t>(o.max_vehicles);
  so.session.step_threads =
      o.step_threads > 0 ? o.step_threads : DefaultStepThreads(o.max_vehicles);
  so.session.server_id = o.server_id;
  so.session.step_ns = std::llround(o.step_ms * 1e6);
  so.session.watchdog_s = o.watchdog_ms / 1000.0;
  so.session.default_params = LoadParams(o);
  so.duration = vdyn::base::FromSeconds(o.duration.value_or(0.0));
  so.lockstep_timeout = vdyn::base::FromSeconds(o.lockstep_timeout_s);
  so.rt_priority = o.rt_priority;
  so.state_writer_nice = o.state_writer_nice;
  so.status_line = o.status || (!o.no_status && isatty(STDERR_FILENO) == 1 && !o.lockstep);
  so.stats_out = o.stats_out;
  std::signal(SIGINT, OnSignal);
  std::signal(SIGTERM, OnSignal);
  vdyn::ServerNode node(LoadWorldFrom(o), so);
  return node.Run(g_stop);
}

int RunBatchMode(const Options& o) {
  const vdyn::ValidParams params = vdyn::ParamsFromProto(LoadParams(o));
  const vdyn::Maneuver maneuver = vdyn::Maneuver::Named(o.maneuver);
  std::shared_ptr<const vdyn::World> world = LoadWorldFrom(o);
  vdyn::SimConfig config;
  config.step_ns = std::llround(o.step_ms * 1e6);
  vdyn::Simulator sim(world, params, config);
  sim.Spawn(world->spawn, o.speed_kmh / 3.6);

  const double duration = o.duration.value_or(maneuver.end_time());
  std::unique_ptr<vdyn::CsvWriter> csv;
  if (!o.csv.empty()) csv = std::make_unique<vdyn::CsvWriter>(o.csv);

  vdyn::base::ProgressBar bar(o.demo ? "demo drive" : "batch");
  vdyn::BatchOptions bo;
  bo.duration = duration;
  bo.csv_every = o.csv_every;
  const vdyn::BatchSummary s =
      vdyn::RunBatch(sim, maneuver, bo, csv.get(), [&bar](double f) { bar.Update(f); });
  bar.Finish();
  if (csv) csv->Close();

  if (!o.quiet) {
    std::printf("vdyn %s on %s: %.3f s simulated in %.3f s (%.0fx real time), %lld steps of %g ms\n",
                o.demo ? "demo drive" : "batch drive", world->name.c_str(), s.sim_time, s.wall_time,
                s.wall_time > 0 ? s.sim_time / s.wall_time : 0.0,
                static_cast<long long>(s.steps), o.step_ms);
    const Eigen::Vector3d p = vdyn::Position(sim.state().x);
    std::printf("  distance %.1f m, top speed %.1f km/h, airborne %.2f s, largest spring force %.1f kN\n",
                s.distance, 3.6 * s.max_speed, s.airborne_time, s.max_Fp / 1000.0);
    std::printf("  final position (%.2f, %.2f, %.3f) m, speed %.2f km/h, state hash %016llx\n",
                p.x(), p.y(), p.z(), 3.6 * vdyn::Velocity(sim.state().x).norm(),
                static_cast<unsigned long long>(s.final_hash));
    if (csv) {
      std::printf("  CSV: %s (%zu rows, %zu columns)\n", o.csv.c_str(), s.csv_rows,
                  vdyn::CsvColumns().size());
    }
  }
  if (!s.ok) {
    spdlog::error("{}", s.error);
    return 1;
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"vdyn-server: deterministic vehicle-dynamics simulation (RK4 at a fixed step)"};
  Options o;
  app.add_flag("--batch", o.batch, "Run a maneuver as fast as possible, no network");
  app.add_flag("--demo", o.demo,
               "The built-in demo drive on facility (batch); CSV to out/demo.csv unless --csv");
  app.add_flag("--dump-vehicle", o.dump_vehicle,
               "Print the effective vehicle parameters (defaults, or --vehicle merged over them)");
  app.add_option("--dump-maneuver", o.dump_maneuver, "Print a built-in maneuver: demo")
      ->check(CLI::IsMember({"demo"}));
  app.add_option("--world", o.world, "facility, flat, or a terrain file (OBJ, STL, glTF, FBX, "
                                     "height-map image)")
      ->capture_default_str();
  app.add_option("--world-scale", o.world_file.scale, "Terrain file units to metres")
      ->check(vdyn::cli::InRange(vdyn::limits::kWorldScale))
      ->capture_default_str();
  app.add_option("--world-up", o.world_up, "Up axis of a terrain mesh file: y or z")
      ->check(CLI::IsMember({"y", "z"}))
      ->capture_default_str();
  app.add_option("--heightmap-cell", o.world_file.heightmap_cell, "Height map: metres per pixel")
      ->check(vdyn::cli::InRange(vdyn::limits::kHeightmapCell))
      ->capture_default_str();
  app.add_option("--heightmap-height", o.world_file.heightmap_height,
                 "Height map: metres for full white")
      ->check(vdyn::cli::InRange(vdyn::limits::kHeightmapHeight))
      ->capture_default_str();
  app.add_option("--vehicle", o.vehicle,
                 "Vehicle parameter file (protobuf text, or JSON if *.json); lists only changes");
  app.add_option("--model", o.model,
                 "Vehicle model: full (default: tires, wheel spin, drivetrain, steering system) or "
                 "paper (the paper's model, bit for bit); overrides the parameters' model")
      ->check(CLI::IsMember({"paper", "full"}));
  app.add_option("--maneuver", o.maneuver,
                 "Maneuver CSV (t_s,steer_deg,throttle,brake,cruise_kmh) or 'demo'");
  app.add_option("--duration", o.duration, "Simulated seconds (default: the maneuver's last row)")
      ->check(vdyn::cli::InRange(vdyn::limits::kDurationS));
  app.add_option("--csv", o.csv, "Write every computed quantity to this CSV file");
  app.add_option("--csv-every", o.csv_every, "Write every Nth step to the CSV")
      ->check(vdyn::cli::WholeInRange({1, 1e6, false, false, "rows interval"}))
      ->capture_default_str();
  app.add_option("--step-ms", o.step_ms, "Integration step h in milliseconds")
      ->check(vdyn::cli::InRange(vdyn::limits::kStepMs))
      ->capture_default_str();
  app.add_option("--spawn", o.spawn, "Start pose x_m,y_m,yaw_deg (default: the world's spawn)")
      ->expected(3)
      ->delimiter(',')
      ->check(vdyn::cli::InRange({-1e7, 1e7, false, false, "spawn coordinate"}));
  app.add_option("--speed-kmh", o.speed_kmh, "Initial speed along the heading, km/h (batch and the vehicles a networked server starts with)")
      ->check(vdyn::cli::InRange(vdyn::limits::kSpeedKmh))
      ->capture_default_str();
  app.add_flag("--quiet", o.quiet, "Print no summary");
  app.add_flag("--lockstep", o.lockstep,
               "Networked, advancing only when a client asks for steps (ControlRequest.step)");
  app.add_option("--domain", o.domain, "DDS domain id")
      ->check(vdyn::cli::WholeInRange(vdyn::limits::kDomainId))
      ->capture_default_str();
  app.add_option("--server-id", o.server_id, "This server's id (several may share a domain)")
      ->check(vdyn::cli::Id("server id"))
      ->capture_default_str();
  app.add_option("--vehicle-ids", o.vehicle_id_entries,
                 "Vehicles to spawn at start, e.g. 1,2 or 1..256 (ids from 1), side by side on "
                 "the free ground around the world's spawn")
      ->delimiter(',')
      ->check(vdyn::cli::VehicleIds())
      ->capture_default_str();
  app.add_option("--max-vehicles", o.max_vehicles,
                 "Vehicles this server runs at most (started and spawned); spawns beyond are "
                 "refused")
      ->check(vdyn::cli::WholeInRange(vdyn::limits::kMaxVehicles))
      ->capture_default_str();
  app.add_option("--step-threads", o.step_threads,
                 "Threads that step the vehicles, the loop's included (results are the same for "
                 "any count); default: one per 128 --max-vehicles, at most one per hardware "
                 "thread")
      ->check(vdyn::cli::WholeInRange(vdyn::limits::kStepThreads));
  app.add_option("--watchdog-ms", o.watchdog_ms,
                 "Without live input for this long a vehicle brakes to a safe state (a live backup "
                 "source takes over after 3/4 of it, or 200 ms when that is shorter)")
      ->check(vdyn::cli::InRange(vdyn::limits::kWatchdogMs))
      ->capture_default_str();
  app.add_option("--lockstep-timeout", o.lockstep_timeout_s,
                 "Lockstep: stop when no request arrives for this many seconds")
      ->check(vdyn::cli::InRange(vdyn::limits::kLockstepTimeoutS))
      ->capture_default_str();
  app.add_option("--rt-priority", o.rt_priority, "SCHED_FIFO priority of the 1 kHz loop")
      ->check(vdyn::cli::WholeInRange({1, 99, false, false, "SCHED_FIFO priority"}))
      ->capture_default_str();
  app.add_option("--state-writer-nice", o.state_writer_nice,
                 "Real time: nice value of the state writer thread (-20 to 19; below 0 needs "
                 "CAP_SYS_NICE): below 0 it runs ahead of the machine's other ordinary threads")
      ->check(vdyn::cli::WholeInRange({-20, 19, false, false, "nice value"}))
      ->capture_default_str();
  app.add_flag("--status", o.status, "Print the status line (default: on a terminal)");
  app.add_flag("--no-status", o.no_status, "No status line");
  app.add_option("--stats-out", o.stats_out,
                 "Real time: write a run summary (lateness distribution, drift, CPU) at the end");
  AddTireOptions(app, o);

  // --help is a success; every parse error is a usage error (exit code 2).
  if (const int code = vdyn::cli::Parse(app, argc, argv); code >= 0) return code;
  if (const std::string why = CheckCommandLine(app, o); !why.empty()) {
    std::cerr << "vdyn-server: " << why << "\n";
    return 2;
  }

  try {
    if (o.dump_vehicle) {
      std::cout << vdyn::DumpVehicleParamsText(LoadParams(o));
      return 0;
    }
    if (!o.tire_curves.empty()) return RunTireCurves(o);
    if (!o.dump_maneuver.empty()) {
      std::cout << vdyn::DemoManeuverCsv();
      return 0;
    }
    if (o.demo) {
      o.batch = true;
      if (o.maneuver.empty()) o.maneuver = "demo";
      if (o.csv.empty()) o.csv = "out/demo.csv";
    }
    if (!o.batch) return RunNetworked(o);
    if (o.maneuver.empty()) {
      std::cerr << "vdyn-server: --batch needs --maneuver FILE (or 'demo')\n";
      return 2;
    }
    return RunBatchMode(o);
  } catch (const vdyn::ParamsError& e) {
    std::cerr << "vdyn-server: " << e.what() << "\n";
  } catch (const vdyn::ManeuverError& e) {
    std::cerr << "vdyn-server: " << e.what() << "\n";
  } catch (const vdyn::WorldError& e) {
    std::cerr << "vdyn-server: " << e.what() << "\n";
  } catch (const vdyn::transport::TransportError& e) {
    std::cerr << "vdyn-server: " << e.what() << "\n";
    return 1;
  } catch (const std::exception& e) {
    std::cerr << "vdyn-server: " << e.what() << "\n";
  }
  return 2;
}
