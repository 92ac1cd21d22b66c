// The subcommands of vdyn-recorder that need no physics: info, export, recover, plot, play.
// Each returns the process exit code (0 done, 1 the work failed, 2 bad input) and writes what a
// person reads to `out`; a bad file throws mcap::McapError (file, offset, reason).
#pragma once

#include <atomic>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <ostream>
#include <set>
#include <string>
#include <utility>

#include "vdyn/base/progress.h"
#include "vdyn/recorder/mcap.h"

namespace vdyn::recorder {

// The commands' progress bar (base::ProgressBar) clears its line when done.
class Progress : public base::ProgressBar {
 public:
  explicit Progress(std::string label) : base::ProgressBar(std::move(label), AtFinish::kClearLine) {}
};

// --- info -----------------------------------------------------------------------------------------
int RunInfo(const std::filesystem::path& file, std::ostream& out);

// --- export -------------------------------------------------------------------------------------
struct ExportOptions {
  std::filesystem::path file;
  std::filesystem::path csv;
  std::optional<std::uint32_t> vehicle;  // one vehicle
  bool each = false;                     // every vehicle to its own file (OUT-v<ID>.csv)
  double from_s = 0;                     // time range, s from the recording's start
  std::optional<double> to_s;
  int every = 1;                         // rows whose step is a multiple of this (as --csv-every)
};
int RunExport(const ExportOptions& o, std::ostream& out);

// --- recover ------------------------------------------------------------------------------------
struct RecoverOptions {
  std::filesystem::path file;
  std::filesystem::path out;             // default: FILE with "-recovered" before the extension
};
int RunRecover(const RecoverOptions& o, std::ostream& out);

// --- plot ---------------------------------------------------------------------------------------
struct PlotOptions {
  std::filesystem::path file;
  std::filesystem::path out_dir;         // default: FILE without extension + "-plots"
  std::optional<std::uint32_t> vehicle;  // default: the first vehicle
  std::string format = "png";            // png or svg
  double from_s = 0;
  std::optional<double> to_s;
  std::string gnuplot = "gnuplot";
};
int RunPlot(const PlotOptions& o, std::ostream& out);

// --- play ---------------------------------------------------------------------------------------
struct PlayOptions {
  std::filesystem::path file;
  std::uint32_t domain = 0;
  double rate = 1.0;
  bool loop = false;
  bool paused = false;                   // start paused
  double from_s = 0;
  std::optional<double> to_s;
  std::set<std::string> topics = {"vdyn/world", "vdyn/params", "vdyn/state", "vdyn/input"};
  std::optional<std::uint32_t> vehicle;
  std::string server_id = "play";        // the id control requests may address
  bool keyboard = true;                  // read keys when stdin is a terminal
  bool force = false;                    // play even where a live server runs
  bool status_line = false;
  double server_check_s = 1.5;           // how long to listen for a live server first
};
int RunPlay(const PlayOptions& o, const std::atomic<bool>& stop, std::ostream& out);

}  // namespace vdyn::recorder
