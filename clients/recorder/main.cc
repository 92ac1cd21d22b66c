// vdyn-recorder: records a vdyn session to MCAP, and exports, plots, plays back, re-simulates,
// takes over and recovers recordings. Exit codes: 0 done (verify: bit-exact), 1 the work failed
// (verify: diverged or cannot re-simulate; transport failure), 2 bad command line or bad file.
#include <unistd.h>

#include <atomic>
#include <csignal>
#include <cstdio>
#include <iostream>

#include <spdlog/spdlog.h>
#include <CLI/CLI.hpp>

#include "vdyn/base/memory.h"
#include "vdyn/cli/errors.h"
#include "vdyn/cli/options.h"
#include "vdyn/recorder/capture.h"
#include "vdyn/recorder/commands.h"
#include "vdyn/recorder/export_foxglove.h"
#include "vdyn/recorder/output_file.h"
#include "vdyn/recorder/recording.h"
#include "vdyn/recorder/verify.h"
#include "vdyn/transport/dds.h"
#include "vdyn/transport/topics.h"

namespace {

std::atomic<bool> g_stop{false};
// The first Ctrl-C or SIGTERM asks the command to stop (a recording is closed whole); a second one
// ends the process at once, as the signal's default would: a command blocked where no flag is
// looked at (writing into a FIFO whose reader does not read) could not be stopped but by SIGKILL.
// Installed without SA_RESTART, so that a blocking call (opening a FIFO nobody reads) returns at
// the first one.
extern "C" void OnSignal(int sig) {
  if (g_stop.exchange(true)) {
    static constexpr char kSay[] =
        "\nvdyn-recorder: a second signal: ending at once (an unfinished output stays beside its "
        "name as NAME.partial-XXXXXX.EXT; a recording's holds what was recorded: "
        "`vdyn-recorder recover` it)\n";
    (void)!::write(STDERR_FILENO, kSay, sizeof kSay - 1);
    std::signal(sig, SIG_DFL);
    std::raise(sig);
  }
}
void OnSignals() {
  struct sigaction sa {};
  sa.sa_handler = OnSignal;
  sigemptyset(&sa.sa_mask);
  sa.sa_flags = 0;  // no SA_RESTART
  ::sigaction(SIGINT, &sa, nullptr);
  ::sigaction(SIGTERM, &sa, nullptr);
}

std::string CommandLine(int argc, char** argv) {
  std::string s;
  for (int i = 0; i < argc; ++i) {
    if (i > 0) s += ' ';
    s += argv[i];
  }
  return s;
}

std::optional<vdyn::transport::TopicId> TopicByName(const std::string& name) {
  const std::string full = name.rfind("vdyn/", 0) == 0 ? name : "vdyn/" + name;
  const auto* s = vdyn::transport::SpecByName(full);
  if (s == nullptr) return std::nullopt;
  // vdyn/states carries the same states as vdyn/state, a step's in one sample; both are recorded
  // as vdyn/state.
  if (s->id == vdyn::transport::TopicId::kStates) return vdyn::transport::TopicId::kState;
  return s->id;
}

CLI::Validator TopicNames() {
  return CLI::Validator(
      [](std::string& text) -> std::string {
        if (TopicByName(text)) return {};
        std::vector<std::string> names;
        for (const auto& spec : vdyn::transport::AllTopics()) {
          if (spec.id == vdyn::transport::TopicId::kStates) continue;  // recorded as vdyn/state
          const std::string name = spec.name;
          names.push_back(name.rfind("vdyn/", 0) == 0 ? name.substr(5) : name);
        }
        std::string why = "'" + vdyn::base::Quote(text, 60) + "' is not a vdyn topic";
        if (const auto near = vdyn::cli::Nearest(text, names); !near.empty()) {
          why += "; did you mean '" + near.front() + "'?";
        }
        std::string all;
        for (const std::string& n : names) all += (all.empty() ? "" : ", ") + n;
        return why + " (the topics: " + all + ")";
      },
      "TOPIC");
}

namespace recorder = vdyn::recorder;
namespace limits = vdyn::limits;
namespace cli = vdyn::cli;

// The terminal the recorder runs in, and the argument list (recorded and takeover's files name it).
struct Invocation {
  int argc = 0;
  char** argv = nullptr;
  bool tty = false;
};

// --status / --no-status, as record, play and takeover take them.
struct StatusFlags {
  bool on = false, off = false;
  void Add(CLI::App* c) {
    c->add_flag("--status", on, "Print the status line (default: on a terminal)");
    c->add_flag("--no-status", off, "No status line");
  }
  bool Show(bool tty) const { return on || (!off && tty); }
};

// A vehicle id option (--vehicle, --as): into an optional only when given.
struct VehicleOption {
  std::uint32_t id = 0;
  CLI::Option* option = nullptr;
  void Add(CLI::App* c, const std::string& name, const std::string& help) {
    option = c->add_option(name, id, help)->check(cli::VehicleId());
  }
  void Into(std::optional<std::uint32_t>& to) const {
    if (*option) to = id;
  }
};

// Each command: its options (the constructor adds them) and its run.
struct Record {
  recorder::RecordOptions ro;
  std::uint32_t domain = 0;
  std::vector<std::string> topic_names;
  std::vector<std::uint32_t> vehicles;
  std::string compression = "zstd";
  double chunk_kb = 1024, queue_mb = 256, split_mb = 0, split_s = 0;
  StatusFlags status;
  CLI::App* cmd;

  explicit Record(CLI::App& app)
      : cmd(app.add_subcommand("record", "Record every vdyn topic of a domain into an MCAP file")) {
    cmd->add_option("out", ro.out, "The recording, e.g. out/session.mcap")->required();
    cmd->add_option("--domain", domain, "DDS domain id")
        ->check(cli::WholeInRange(limits::kDomainId))
        ->capture_default_str();
    cmd->add_option("--duration", ro.duration_s,
                    "Stop after this many seconds (default: at Ctrl-C / SIGTERM)")
        ->check(cli::InRange(limits::kDurationS));
    cmd->add_option("--topics", topic_names, "Only these topics, e.g. state,events,world,params")
        ->delimiter(',')
        ->check(TopicNames());
    cmd->add_option("--vehicles", vehicles,
                    "Only these vehicles, e.g. 1,2 (events are kept for all)")
        ->delimiter(',')
        ->check(cli::VehicleId());
    cmd->add_option("--split-mb", split_mb, "Start a new file after this many MiB")
        ->check(cli::InRange(limits::kSplitMb));
    cmd->add_option("--split-s", split_s, "Start a new file after this many seconds")
        ->check(cli::InRange(limits::kSplitS));
    cmd->add_option("--compression", compression, "Chunk compression: zstd, lz4 or none")
        ->check(CLI::IsMember({"zstd", "lz4", "none"}))
        ->capture_default_str();
    cmd->add_option("--chunk-kb", chunk_kb, "Close a chunk at this size (or after 250 ms)")
        ->check(cli::InRange(limits::kChunkKb))
        ->capture_default_str();
    cmd->add_option(
           "--queue-mb", queue_mb,
           "Memory for samples waiting to be written; beyond it they are dropped and counted")
        ->check(cli::InRange(limits::kRecorderQueueMb))
        ->capture_default_str();
    status.Add(cmd);
  }

  int Run(const Invocation& in) {
    ro.command_line = CommandLine(in.argc, in.argv);
    for (const std::string& t : topic_names) ro.topics.insert(*TopicByName(t));
    ro.vehicles.insert(vehicles.begin(), vehicles.end());
    ro.writer.compression = compression == "zstd"  ? vdyn::mcap::Compression::kZstd
                            : compression == "lz4" ? vdyn::mcap::Compression::kLz4
                                                   : vdyn::mcap::Compression::kNone;
    ro.writer.chunk_bytes = static_cast<std::size_t>(chunk_kb * 1024);
    ro.queue_bytes = static_cast<std::size_t>(queue_mb * 1024 * 1024);
    ro.split_bytes = static_cast<std::uint64_t>(split_mb * 1024 * 1024);
    ro.split_s = split_s;
    ro.status_line = status.Show(in.tty);
    ro.status_tty = in.tty;
    vdyn::transport::Participant participant(domain, limits::kRecorderReceiveBufferBytes);
    recorder::Capture capture(participant, ro);
    spdlog::info("vdyn-recorder: recording domain {} to {}{}", domain, ro.out.string(),
                 ro.duration_s > 0 ? " for " + vdyn::base::FormatNumber(ro.duration_s) + " s"
                                   : "; Ctrl-C ends");
    const recorder::CaptureSummary s = capture.Run(g_stop);
    std::string files;
    for (const auto& f : s.files) files += (files.empty() ? "" : ", ") + f.string();
    std::cout << "recorded " << s.messages << " messages in " << recorder::FormatDuration(s.seconds)
              << " to " << files << " ("
              << recorder::FormatBytes(static_cast<double>(s.bytes_on_disk)) << ")";
    std::cout << "; lost " << s.total_lost() << ", dropped " << s.total_dropped()
              << s.dropped_by_topic();
    std::printf("; CPU %.2f s (%.1f%% of one core); buffer peak %s\n", s.cpu_seconds,
                s.seconds > 0 ? 100.0 * s.cpu_seconds / s.seconds : 0.0,
                recorder::FormatBytes(static_cast<double>(s.queue_peak_bytes)).c_str());
    const auto heard = [&s](vdyn::transport::TopicId t) {
      const auto it = s.topics.find(t);
      return it != s.topics.end() && it->second.messages > 0;
    };
    if (!heard(vdyn::transport::TopicId::kWorld) && !heard(vdyn::transport::TopicId::kState)) {
      spdlog::warn(
          "vdyn-recorder: no server was heard on domain {}: no world and no state arrived (is "
          "vdyn-server running with --domain {}?)",
          domain, domain);
    }
    return 0;
  }
};

struct Info {
  std::filesystem::path file;
  CLI::App* cmd;
  explicit Info(CLI::App& app)
      : cmd(app.add_subcommand(
            "info",
            "Channels, counts, time range, vehicles, world, gaps; whether it re-simulates")) {
    cmd->add_option("file", file, "A recording")->required();
  }
  int Run() const { return recorder::RunInfo(file, std::cout); }
};

// A time range whose end comes before its start: a bad command line (exit 2), said as such.
bool TimeRangeInOrder(const char* command, double from_s, const std::optional<double>& to_s) {
  if (!to_s || *to_s >= from_s) return true;
  std::cerr << "vdyn-recorder " << command << ": --from " << from_s << " s is after --to " << *to_s
            << " s: the range is empty\n";
  return false;
}

struct Export {
  recorder::ExportOptions eo;
  recorder::FoxgloveExportOptions fo;
  VehicleOption vehicle;
  CLI::App* cmd;
  CLI::Option* csv;
  CLI::Option* foxglove;

  explicit Export(CLI::App& app)
      : cmd(app.add_subcommand("export",
                               "States to CSV (columns as vdyn-server --batch --csv), or a copy "
                               "with Foxglove's scene")) {
    cmd->add_option("file", eo.file, "A recording")->required();
    csv = cmd->add_option("--csv", eo.csv, "The CSV file");
    foxglove = cmd->add_option("--foxglove", fo.out,
                               "A copy of the recording with Foxglove's scene added (MCAP)");
    csv->excludes(foxglove);
    CLI::Option* scene_hz =
        cmd->add_option("--scene-hz", fo.scene_hz, "--foxglove: scenes per second of log time")
            ->check(cli::InRange(limits::kFoxgloveSceneHz))
            ->capture_default_str();
    CLI::Option* arrows =
        cmd->add_option("--arrow-scale", fo.arrow_m_per_kn, "--foxglove: force arrows, m per kN")
            ->check(cli::InRange(limits::kArrowScale))
            ->capture_default_str();
    vehicle.Add(cmd, "--vehicle", "--csv: only this vehicle");
    CLI::Option* each =
        cmd->add_flag("--each", eo.each, "--csv: every vehicle to its own file: OUT-v<ID>.csv");
    CLI::Option* from = cmd->add_option("--from", eo.from_s, "--csv: start, s from the recording's start")
                            ->check(cli::InRange(limits::kRecordingTimeS));
    CLI::Option* to = cmd->add_option("--to", eo.to_s, "--csv: end, s from the recording's start")
                          ->check(cli::InRange(limits::kRecordingTimeS));
    CLI::Option* every =
        cmd->add_option("--every", eo.every, "--csv: rows whose step is a multiple of N (as --csv-every)")
            ->check(cli::WholeInRange({1, 1e6, false, false, "--every"}));
    // The Foxglove copy is the whole recording with its scene: a range or a vehicle of it was
    // ignored (exit 0, everything copied), as the scene's options were by --csv.
    for (CLI::Option* o : {vehicle.option, each, from, to, every}) foxglove->excludes(o);
    for (CLI::Option* o : {scene_hz, arrows}) csv->excludes(o);
  }

  int Run() {
    if (!TimeRangeInOrder("export", eo.from_s, eo.to_s)) return 2;
    if (*foxglove) {
      fo.file = eo.file;
      return recorder::RunExportFoxglove(fo, std::cout);
    }
    if (!*csv) {
      std::cerr << "vdyn-recorder export: give --csv OUT.csv or --foxglove OUT.mcap\n";
      return 2;
    }
    vehicle.Into(eo.vehicle);
    return recorder::RunExport(eo, std::cout);
  }
};

struct Plot {
  recorder::PlotOptions po;
  VehicleOption vehicle;
  CLI::App* cmd;

  explicit Plot(CLI::App& app)
      : cmd(app.add_subcommand("plot", "Figures (gnuplot, PNG or SVG) and one HTML page")) {
    cmd->add_option("file", po.file, "A recording")->required();
    cmd->add_option(
        "--out", po.out_dir,
        "Folder for the figures (default: beside FILE, named after it: run.mcap -> run-plots)");
    vehicle.Add(cmd, "--vehicle", "The vehicle (default: the first)");
    cmd->add_option("--format", po.format, "png or svg")
        ->check(CLI::IsMember({"png", "svg"}))
        ->capture_default_str();
    cmd->add_option("--from", po.from_s, "Start, s from the recording's start")
        ->check(cli::InRange(limits::kRecordingTimeS));
    cmd->add_option("--to", po.to_s, "End, s from the recording's start")
        ->check(cli::InRange(limits::kRecordingTimeS));
  }

  int Run() {
    if (!TimeRangeInOrder("plot", po.from_s, po.to_s)) return 2;
    vehicle.Into(po.vehicle);
    return recorder::RunPlot(po, std::cout);
  }
};

struct Play {
  recorder::PlayOptions pl;
  std::vector<std::string> topics;
  VehicleOption vehicle;
  bool no_keys = false;
  StatusFlags status;
  CLI::App* cmd;

  explicit Play(CLI::App& app)
      : cmd(app.add_subcommand("play",
                               "Republish a recording to DDS (world, params, states, inputs) at "
                               "its recorded timing")) {
    cmd->add_option("file", pl.file, "A recording")->required();
    cmd->add_option("--domain", pl.domain, "DDS domain id")
        ->check(cli::WholeInRange(limits::kDomainId))
        ->capture_default_str();
    cmd->add_option("--rate", pl.rate, "Playback speed, 1 = real time")
        ->check(cli::InRange(limits::kPlaybackRate))
        ->capture_default_str();
    cmd->add_flag("--loop", pl.loop, "Start again at the end");
    cmd->add_flag("--paused", pl.paused, "Start paused (space or a resume request starts it)");
    cmd->add_option("--from", pl.from_s, "Start, s from the recording's start")
        ->check(cli::InRange(limits::kRecordingTimeS));
    cmd->add_option("--to", pl.to_s, "End, s from the recording's start")
        ->check(cli::InRange(limits::kRecordingTimeS));
    cmd->add_option("--topics", topics, "Topics to republish (default: world,params,state,input)")
        ->delimiter(',')
        ->check(TopicNames());
    vehicle.Add(cmd, "--vehicle", "Only this vehicle");
    cmd->add_option("--server-id", pl.server_id, "The id control requests address the player by")
        ->check(cli::Id("server id"))
        ->capture_default_str();
    cmd->add_flag("--no-keys", no_keys, "Ignore the keyboard");
    cmd->add_flag("--force", pl.force, "Play even where a live server runs");
    status.Add(cmd);
  }

  int Run(const Invocation& in) {
    if (!TimeRangeInOrder("play", pl.from_s, pl.to_s)) return 2;
    vehicle.Into(pl.vehicle);
    if (!topics.empty()) {
      pl.topics.clear();
      for (const std::string& t : topics)
        pl.topics.insert(vdyn::transport::Spec(*TopicByName(t)).name);
    }
    pl.keyboard = !no_keys;
    pl.status_line = status.Show(in.tty);
    return recorder::RunPlay(pl, g_stop, std::cout);
  }
};

struct Verify {
  recorder::VerifyOptions vo;
  VehicleOption vehicle;
  CLI::App* cmd;

  explicit Verify(CLI::App& app)
      : cmd(app.add_subcommand(
            "verify", "Re-simulate from the recorded events; compare every recorded state hash")) {
    cmd->add_option("file", vo.file, "A recording")->required();
    vehicle.Add(cmd, "--vehicle", "Only this vehicle");
  }

  int Run() {
    vehicle.Into(vo.vehicle);
    return recorder::RunVerify(vo, std::cout);
  }
};

struct Takeover {
  recorder::TakeoverOptions to;
  VehicleOption vehicle, as_vehicle;
  StatusFlags status;
  CLI::App* cmd;

  explicit Takeover(CLI::App& app)
      : cmd(app.add_subcommand("takeover",
                               "A live server resumes from the recorded state at --at; the new "
                               "recording names this one")) {
    cmd->add_option("file", to.file, "A recording")->required();
    cmd->add_option("--at", to.at_s, "Seconds from the recording's start")
        ->required()
        ->check(cli::InRange(limits::kRecordingTimeS));
    cmd->add_option("--domain", to.domain, "DDS domain id of the live server")
        ->check(cli::WholeInRange(limits::kDomainId))
        ->capture_default_str();
    vehicle.Add(cmd, "--vehicle", "The recorded vehicle (default: the first)");
    as_vehicle.Add(cmd, "--as", "The live vehicle id to restore into (default: the same)");
    cmd->add_option("--out", to.out, "The new recording (default: FILE-takeover.mcap)");
    cmd->add_option("--duration", to.duration_s,
                    "Stop after this many seconds (default: at Ctrl-C)")
        ->check(cli::InRange(limits::kDurationS));
    cmd->add_option("--wait", to.wait_s, "Seconds to wait for the live server")
        ->check(cli::InRange(limits::kWaitS))
        ->capture_default_str();
    status.Add(cmd);
  }

  int Run(const Invocation& in) {
    vehicle.Into(to.vehicle);
    as_vehicle.Into(to.as_vehicle);
    to.command_line = CommandLine(in.argc, in.argv);
    to.status_line = status.Show(in.tty);
    to.status_tty = in.tty;
    return recorder::RunTakeover(to, g_stop, std::cout);
  }
};

struct Recover {
  recorder::RecoverOptions co;
  CLI::App* cmd;
  explicit Recover(CLI::App& app)
      : cmd(app.add_subcommand(
            "recover", "Salvage a truncated or damaged recording into a closed, indexed copy")) {
    cmd->add_option("file", co.file, "The damaged recording")->required();
    cmd->add_option("-o,--out", co.out, "The copy (default: FILE-recovered.mcap)");
  }
  int Run() const { return recorder::RunRecover(co, std::cout); }
};

// Runs a command; what it throws becomes a message and an exit code (the file's header says which).
template <typename F>
int Guarded(F&& run) {
  try {
    return run();
  } catch (const vdyn::mcap::Interrupted& e) {
    std::cerr
        << "vdyn-recorder: " << e.what()
        << ": stopped before the end; no output was completed (an unfinished file is removed)\n";
    return 1;
  } catch (const vdyn::mcap::McapError& e) {
    std::cerr << "vdyn-recorder: " << e.what() << "\n";
    return 2;
  } catch (const recorder::OutputError& e) {  // an output that is an input, or a folder
    std::cerr << "vdyn-recorder: " << e.what() << "\n";
    return 2;
  } catch (const vdyn::transport::TransportError& e) {
    std::cerr << "vdyn-recorder: " << e.what() << "\n";
    return 1;
  } catch (const std::exception& e) {
    std::cerr << "vdyn-recorder: " << e.what() << "\n";
    return 1;
  }
}

}  // namespace

int main(int argc, char** argv) {
  // Recording takes DDS samples and writes chunks at a high rate: keep freed memory rather than
  // fault it back in (base/memory.h; a quarter less CPU at 128 vehicles).
  (void)vdyn::base::KeepFreedMemory();
  CLI::App app{
      "vdyn-recorder: record vdyn sessions to MCAP; info, export, plot, play, verify, takeover, "
      "recover"};
  app.require_subcommand(1);
  Record record(app);
  Info info(app);
  Export exp(app);
  Plot plot(app);
  Play play(app);
  Verify verify(app);
  Takeover takeover(app);
  Recover recover(app);
  if (const int code = cli::Parse(app, argc, argv); code >= 0) return code;
  OnSignals();
  if (!record.cmd->parsed() && !play.cmd->parsed() && !takeover.cmd->parsed()) {
    // The commands that only read a file stop at the next record on a signal (record, play
    // and takeover stop on g_stop themselves).
    vdyn::mcap::StopReadsWhen(&g_stop);
  }
  const Invocation in{argc, argv, isatty(STDERR_FILENO) == 1};
  return Guarded([&] {
    if (record.cmd->parsed()) return record.Run(in);
    if (info.cmd->parsed()) return info.Run();
    if (exp.cmd->parsed()) return exp.Run();
    if (plot.cmd->parsed()) return plot.Run();
    if (play.cmd->parsed()) return play.Run(in);
    if (verify.cmd->parsed()) return verify.Run();
    if (takeover.cmd->parsed()) return takeover.Run(in);
    if (recover.cmd->parsed()) return recover.Run();
    return 2;
  });
}
