// Batch real-time factor (simulated time / wall time) of vdyn::RunBatch: the demo maneuver on
// `facility` for its full length, without output and with the full-rate CSV (every step, to a
// temporary file, flushed and closed inside the timing; formatted and written on a second thread,
// which the stepping thread helps when it falls behind: the share is printed). Five runs of each,
// interleaved so both see the same machine; medians printed. All runs must end on the same state
// hash (determinism).
// Usage: batch_rtf [runs]   (default 5)
#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include <unistd.h>

#include "vdyn/runtime/batch.h"
#include "vdyn/io/csv.h"
#include "vdyn/io/maneuver.h"
#include "vdyn/bridge/params.h"
#include "vdyn/physics/simulator.h"
#include "vdyn/physics/world.h"

namespace {

struct Result {
  double rtf = 0;
  double stepper_share = 0;  // of the CSV rows, formatted on the stepping thread
  std::uint64_t hash = 0;
  std::uintmax_t csv_bytes = 0;
};

Result RunOnce(const std::shared_ptr<const vdyn::World>& world, const vdyn::Maneuver& maneuver,
               const std::filesystem::path* csv_path) {
  vdyn::Simulator sim(world, vdyn::ParamsFromProto(vdyn::DefaultVehicleParams()));
  vdyn::BatchOptions options;
  options.duration = maneuver.end_time();
  options.csv_every = 1;
  const auto t0 = std::chrono::steady_clock::now();
  std::unique_ptr<vdyn::CsvWriter> csv;
  if (csv_path != nullptr) csv = std::make_unique<vdyn::CsvWriter>(*csv_path);
  const vdyn::BatchSummary s = vdyn::RunBatch(sim, maneuver, options, csv.get());
  if (csv) csv->Close();
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (!s.ok) {
    std::fprintf(stderr, "batch_rtf: %s\n", s.error.c_str());
    std::exit(1);
  }
  Result r{s.sim_time / wall, 0, s.final_hash, 0};
  if (s.csv_rows > 0) {
    r.stepper_share = static_cast<double>(s.csv_rows_formatted_by_stepper) /
                      static_cast<double>(s.csv_rows);
  }
  if (csv_path != nullptr) r.csv_bytes = std::filesystem::file_size(*csv_path);
  return r;
}

double Median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  const std::size_t m = v.size() / 2;
  return v.size() % 2 == 1 ? v[m] : 0.5 * (v[m - 1] + v[m]);
}

}  // namespace

int main(int argc, char** argv) {
  const int runs = argc > 1 ? std::atoi(argv[1]) : 5;
  if (runs <= 0) {
    std::fprintf(stderr, "usage: batch_rtf [runs > 0]\n");
    return 2;
  }
  const std::shared_ptr<const vdyn::World> world = vdyn::BuildBuiltinWorld("facility");
  const vdyn::Maneuver maneuver = vdyn::Maneuver::Parse(vdyn::DemoManeuverCsv(), "demo");
  const std::filesystem::path csv_path = std::filesystem::temp_directory_path() /
                                         ("vdyn-batch-rtf-" + std::to_string(::getpid()) + ".csv");
  std::printf("demo maneuver on facility: %.1f s simulated per run (h = 1 ms), %d runs each\n",
              maneuver.end_time(), runs);
  std::vector<double> none, full, share;
  std::uint64_t hash = 0;
  bool deterministic = true;
  std::uintmax_t bytes = 0;
  for (int i = 0; i < runs; ++i) {
    const Result a = RunOnce(world, maneuver, nullptr);
    const Result b = RunOnce(world, maneuver, &csv_path);
    if (i == 0) hash = a.hash;
    deterministic = deterministic && a.hash == hash && b.hash == hash;
    bytes = b.csv_bytes;
    none.push_back(a.rtf);
    full.push_back(b.rtf);
    share.push_back(b.stepper_share);
    std::printf("run %d: no output %7.1fx   full-rate CSV %7.1fx (%2.0f %% of rows formatted on the "
                "stepping thread)\n",
                i + 1, a.rtf, b.rtf, 100.0 * b.stepper_share);
  }
  std::filesystem::remove(csv_path);
  std::printf(
      "median: no output %.1fx real time, full-rate CSV %.1fx real time (%.1f MB per run; %.0f %% "
      "of its rows formatted on the stepping thread)\n",
      Median(none), Median(full), static_cast<double>(bytes) / 1e6, 100.0 * Median(share));
  std::printf("targets: no output >= 300x %s, full-rate CSV >= 200x %s (issue 19)\n",
              Median(none) >= 300.0 ? "met" : "NOT met", Median(full) >= 200.0 ? "met" : "NOT met");
  std::printf("final state hash %016llx, %s\n", static_cast<unsigned long long>(hash),
              deterministic ? "identical in every run" : "DIFFERS between runs");
  return deterministic ? 0 : 1;
}
