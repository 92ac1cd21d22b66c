// vdyn-recorder: records a vdyn session to MCAP, and exports, plots, plays back, re-simulates,
// takes over and recovers recordings. Exit codes: 0 done (verify: bit-exact), 1 the work failed
// (verify: diverged or cannot re-simulate; transport failure), 2 bad command line or bad file.
#include <unistd.h>

#include <atomic>
#include <csignal>
#include <cstdio>
#include <iostream>

#include <CLI/CLI.hpp>
#include <spdlog/spdlog.h>

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
extern "C" void OnSignal(int) { g_stop.store(true); }

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

}  // namespace

int main(int argc, char** argv) {
  using namespace vdyn;
  // Recording takes DDS samples and writes chunks at a high rate: keep freed memory rather than
  // fault it back in (base/memory.h; a quarter less CPU at 128 vehicles).
  (void)base::KeepFreedMemory();
  CLI::App app{"vdyn-recorder: record vdyn sessions to MCAP; info, export, plot, play, verify, takeover, recover"};
  app.require_subcommand(1);
  const limits::Range time_range = limits::kRecordingTimeS;

  // record
  recorder::RecordOptions ro;
  std::uint32_t domain = 0;
  std::vector<std::string> topic_names;
  std::vector<std::uint32_t> vehicles;
  std::string compression = "zstd";
  double chunk_kb = 1024, queue_mb = 256, split_mb = 0, split_s = 0;
  bool status = false, no_status = false;
  auto* rec = app.add_subcommand("record", "Record every vdyn topic of a domain into an MCAP file");
  rec->add_option("out", ro.out, "The recording, e.g. out/session.mcap")->required();
  rec->add_option("--domain", domain, "DDS domain id")->check(cli::WholeInRange(limits::kDomainId))->capture_default_str();
  rec->add_option("--duration", ro.duration_s, "Stop after this many seconds (default: at Ctrl-C / SIGTERM)")
      ->check(cli::InRange(limits::kDurationS));
  rec->add_option("--topics", topic_names, "Only these topics, e.g. state,events,world,params")
      ->delimiter(',')->check(TopicNames());
  rec->add_option("--vehicles", vehicles, "Only these vehicles, e.g. 1,2 (events are kept for all)")->delimiter(',')->check(cli::VehicleId());
  rec->add_option("--split-mb", split_mb, "Start a new file after this many MiB")->check(cli::InRange(limits::kSplitMb));
  rec->add_option("--split-s", split_s, "Start a new file after this many seconds")->check(cli::InRange(limits::kSplitS));
  rec->add_option("--compression", compression, "Chunk compression: zstd, lz4 or none")
      ->check(CLI::IsMember({"zstd", "lz4", "none"}))->capture_default_str();
  rec->add_option("--chunk-kb", chunk_kb, "Close a chunk at this size (or after 250 ms)")
      ->check(cli::InRange(limits::kChunkKb))->capture_default_str();
  rec->add_option("--queue-mb", queue_mb, "Memory for samples waiting to be written; beyond it they are dropped and counted")
      ->check(cli::InRange(limits::kRecorderQueueMb))->capture_default_str();
  rec->add_flag("--status", status, "Print the status line (default: on a terminal)");
  rec->add_flag("--no-status", no_status, "No status line");

  // info
  std::filesystem::path file;
  auto* info = app.add_subcommand("info", "Channels, counts, time range, vehicles, world, gaps; whether it re-simulates");
  info->add_option("file", file, "A recording")->required();

  // export
  recorder::ExportOptions eo;
  std::uint32_t vehicle = 0;
  auto* exp = app.add_subcommand(
      "export",
      "States to CSV (columns as vdyn-server --batch --csv), or a copy with Foxglove's scene");
  exp->add_option("file", eo.file, "A recording")->required();
  recorder::FoxgloveExportOptions fo;
  auto* exp_csv = exp->add_option("--csv", eo.csv, "The CSV file");
  auto* exp_fox = exp->add_option("--foxglove", fo.out,
                                  "A copy of the recording with Foxglove's scene added (MCAP)");
  exp_csv->excludes(exp_fox);
  exp->add_option("--scene-hz", fo.scene_hz, "--foxglove: scenes per second of log time")
      ->check(cli::InRange(limits::kFoxgloveSceneHz))
      ->capture_default_str();
  exp->add_option("--arrow-scale", fo.arrow_m_per_kn, "--foxglove: force arrows, m per kN")
      ->check(cli::InRange(limits::kArrowScale))
      ->capture_default_str();
  auto* exp_vehicle = exp->add_option("--vehicle", vehicle, "Only this vehicle")->check(cli::VehicleId());
  exp->add_flag("--each", eo.each, "Every vehicle to its own file: OUT-v<ID>.csv");
  exp->add_option("--from", eo.from_s, "Start, s from the recording's start")->check(cli::InRange(time_range));
  exp->add_option("--to", eo.to_s, "End, s from the recording's start")->check(cli::InRange(time_range));
  exp->add_option("--every", eo.every, "Rows whose step is a multiple of N (as --csv-every)")
      ->check(cli::WholeInRange({1, 1e6, false, false, "--every"}));

  // plot
  recorder::PlotOptions po;
  auto* plot = app.add_subcommand("plot", "Figures (gnuplot, PNG or SVG) and one HTML page");
  plot->add_option("file", po.file, "A recording")->required();
  plot->add_option("--out", po.out_dir, "Folder for the figures (default: beside FILE, named after it: run.mcap -> run-plots)");
  auto* plot_vehicle = plot->add_option("--vehicle", vehicle, "The vehicle (default: the first)")->check(cli::VehicleId());
  plot->add_option("--format", po.format, "png or svg")->check(CLI::IsMember({"png", "svg"}))->capture_default_str();
  plot->add_option("--from", po.from_s, "Start, s from the recording's start")->check(cli::InRange(time_range));
  plot->add_option("--to", po.to_s, "End, s from the recording's start")->check(cli::InRange(time_range));

  // play
  recorder::PlayOptions pl;
  std::vector<std::string> play_topics;
  bool no_keys = false;
  auto* play = app.add_subcommand("play", "Republish a recording to DDS (world, params, states, inputs) at its recorded timing");
  play->add_option("file", pl.file, "A recording")->required();
  play->add_option("--domain", pl.domain, "DDS domain id")->check(cli::WholeInRange(limits::kDomainId))->capture_default_str();
  play->add_option("--rate", pl.rate, "Playback speed, 1 = real time")->check(cli::InRange(limits::kPlaybackRate))->capture_default_str();
  play->add_flag("--loop", pl.loop, "Start again at the end");
  play->add_flag("--paused", pl.paused, "Start paused (space or a resume request starts it)");
  play->add_option("--from", pl.from_s, "Start, s from the recording's start")->check(cli::InRange(time_range));
  play->add_option("--to", pl.to_s, "End, s from the recording's start")->check(cli::InRange(time_range));
  play->add_option("--topics", play_topics, "Topics to republish (default: world,params,state,input)")
      ->delimiter(',')->check(TopicNames());
  auto* play_vehicle = play->add_option("--vehicle", vehicle, "Only this vehicle")->check(cli::VehicleId());
  play->add_option("--server-id", pl.server_id, "The id control requests address the player by")->check(cli::Id("server id"))->capture_default_str();
  play->add_flag("--no-keys", no_keys, "Ignore the keyboard");
  play->add_flag("--force", pl.force, "Play even where a live server runs");
  play->add_flag("--status", status, "Print the status line (default: on a terminal)");
  play->add_flag("--no-status", no_status, "No status line");

  // verify
  recorder::VerifyOptions vo;
  auto* ver = app.add_subcommand("verify", "Re-simulate from the recorded events; compare every recorded state hash");
  ver->add_option("file", vo.file, "A recording")->required();
  auto* ver_vehicle = ver->add_option("--vehicle", vehicle, "Only this vehicle")->check(cli::VehicleId());

  // takeover
  recorder::TakeoverOptions to;
  std::uint32_t as_vehicle = 0;
  auto* take = app.add_subcommand("takeover", "A live server resumes from the recorded state at --at; the new recording names this one");
  take->add_option("file", to.file, "A recording")->required();
  take->add_option("--at", to.at_s, "Seconds from the recording's start")->required()->check(cli::InRange(time_range));
  take->add_option("--domain", to.domain, "DDS domain id of the live server")->check(cli::WholeInRange(limits::kDomainId))->capture_default_str();
  auto* take_vehicle = take->add_option("--vehicle", vehicle, "The recorded vehicle (default: the first)")->check(cli::VehicleId());
  auto* take_as = take->add_option("--as", as_vehicle, "The live vehicle id to restore into (default: the same)")->check(cli::VehicleId());
  take->add_option("--out", to.out, "The new recording (default: FILE-takeover.mcap)");
  take->add_option("--duration", to.duration_s, "Stop after this many seconds (default: at Ctrl-C)")->check(cli::InRange(limits::kDurationS));
  take->add_option("--wait", to.wait_s, "Seconds to wait for the live server")->check(cli::InRange(limits::kWaitS))->capture_default_str();
  take->add_flag("--status", status, "Print the status line (default: on a terminal)");
  take->add_flag("--no-status", no_status, "No status line");

  // recover
  recorder::RecoverOptions co;
  auto* recov = app.add_subcommand("recover", "Salvage a truncated or damaged recording into a closed, indexed copy");
  recov->add_option("file", co.file, "The damaged recording")->required();
  recov->add_option("-o,--out", co.out, "The copy (default: FILE-recovered.mcap)");

  if (const int code = cli::Parse(app, argc, argv); code >= 0) return code;
  std::signal(SIGINT, OnSignal);
  std::signal(SIGTERM, OnSignal);
  if (!rec->parsed() && !play->parsed() && !take->parsed()) {
    // The commands that only read a file stop at the next record on a signal (record, play
    // and takeover stop on g_stop themselves).
    mcap::StopReadsWhen(&g_stop);
  }
  const bool tty = isatty(STDERR_FILENO) == 1;
  const bool show_status = status || (!no_status && tty);
  try {
    if (rec->parsed()) {
      ro.command_line = CommandLine(argc, argv);
      for (const std::string& t : topic_names) ro.topics.insert(*TopicByName(t));
      ro.vehicles.insert(vehicles.begin(), vehicles.end());
      ro.writer.compression = compression == "zstd" ? mcap::Compression::kZstd
                              : compression == "lz4" ? mcap::Compression::kLz4
                                                     : mcap::Compression::kNone;
      ro.writer.chunk_bytes = static_cast<std::size_t>(chunk_kb * 1024);
      ro.queue_bytes = static_cast<std::size_t>(queue_mb * 1024 * 1024);
      ro.split_bytes = static_cast<std::uint64_t>(split_mb * 1024 * 1024);
      ro.split_s = split_s;
      ro.status_line = show_status;
      ro.status_tty = tty;
      transport::Participant participant(domain, limits::kRecorderReceiveBufferBytes);
      recorder::Capture capture(participant, ro);
      spdlog::info("vdyn-recorder: recording domain {} to {}{}", domain, ro.out.string(),
                   ro.duration_s > 0 ? " for " + base::FormatNumber(ro.duration_s) + " s" : "; Ctrl-C ends");
      const recorder::CaptureSummary s = capture.Run(g_stop);
      std::string files;
      for (const auto& f : s.files) files += (files.empty() ? "" : ", ") + f.string();
      std::cout << "recorded " << s.messages << " messages in " << recorder::FormatDuration(s.seconds) << " to "
                << files << " (" << recorder::FormatBytes(static_cast<double>(s.bytes_on_disk)) << ")";
      std::cout << "; lost " << s.total_lost() << ", dropped " << s.total_dropped() << s.dropped_by_topic();
      std::printf("; CPU %.2f s (%.1f%% of one core); buffer peak %s\n", s.cpu_seconds,
                  s.seconds > 0 ? 100.0 * s.cpu_seconds / s.seconds : 0.0,
                  recorder::FormatBytes(static_cast<double>(s.queue_peak_bytes)).c_str());
      return 0;
    }
    if (info->parsed()) return recorder::RunInfo(file, std::cout);
    if (exp->parsed()) {
      if (*exp_fox) {
        fo.file = eo.file;
        return recorder::RunExportFoxglove(fo, std::cout);
      }
      if (!*exp_csv) {
        std::cerr << "vdyn-recorder export: give --csv OUT.csv or --foxglove OUT.mcap\n";
        return 2;
      }
      if (*exp_vehicle) eo.vehicle = vehicle;
      return recorder::RunExport(eo, std::cout);
    }
    if (plot->parsed()) {
      if (*plot_vehicle) po.vehicle = vehicle;
      return recorder::RunPlot(po, std::cout);
    }
    if (play->parsed()) {
      if (*play_vehicle) pl.vehicle = vehicle;
      if (!play_topics.empty()) {
        pl.topics.clear();
        for (const std::string& t : play_topics) pl.topics.insert(transport::Spec(*TopicByName(t)).name);
      }
      pl.keyboard = !no_keys;
      pl.status_line = show_status;
      return recorder::RunPlay(pl, g_stop, std::cout);
    }
    if (ver->parsed()) {
      if (*ver_vehicle) vo.vehicle = vehicle;
      return recorder::RunVerify(vo, std::cout);
    }
    if (take->parsed()) {
      if (*take_vehicle) to.vehicle = vehicle;
      if (*take_as) to.as_vehicle = as_vehicle;
      to.command_line = CommandLine(argc, argv);
      to.status_line = show_status;
      to.status_tty = tty;
      return recorder::RunTakeover(to, g_stop, std::cout);
    }
    if (recov->parsed()) return recorder::RunRecover(co, std::cout);
  } catch (const mcap::Interrupted& e) {
    std::cerr << "vdyn-recorder: " << e.what() << ": stopped before the end; no output was completed (an unfinished file is removed)\n";
    return 1;
  } catch (const mcap::McapError& e) {
    std::cerr << "vdyn-recorder: " << e.what() << "\n";
    return 2;
  } catch (const recorder::OutputError& e) {  // an output that is an input, or a folder
    std::cerr << "vdyn-recorder: " << e.what() << "\n";
    return 2;
  } catch (const transport::TransportError& e) {
    std::cerr << "vdyn-recorder: " << e.what() << "\n";
    return 1;
  } catch (const std::exception& e) {
    std::cerr << "vdyn-recorder: " << e.what() << "\n";
    return 1;
  }
  return 2;
}
