// `vdyn-recorder export FILE --csv OUT.csv`: the recorded states as the batch CSV (io's
// CsvWriter over VehicleState: the same columns, units and order as `vdyn-server --batch --csv`,
// so one analysis script reads both).
#include <unistd.h>

#include <functional>
#include <iostream>
#include <map>
#include <memory>
#include <set>
#include <vector>

#include "vdyn/base/time.h"
#include "vdyn/io/csv.h"
#include "vdyn/recorder/commands.h"
#include "vdyn/recorder/output_file.h"
#include "vdyn/recorder/recording.h"
#include "vdyn/state.pb.h"

namespace vdyn::recorder {

namespace {

std::filesystem::path VehiclePath(const std::filesystem::path& csv, std::uint32_t id) {
  std::filesystem::path p = csv;
  p.replace_filename(csv.stem().string() + "-v" + std::to_string(id) + csv.extension().string());
  return p;
}

// CSV files open at once (export --each).
constexpr std::size_t kOpenAtOnce = 64;

// One pass over the recording that writes the CSV of some vehicles: each written beside its
// name and renamed when whole, never over the recording (OutputFile).
class ExportPass {
 public:
  struct Range {
    std::uint64_t from = 0, to = ~0ull, every = 1;
  };
  struct Totals {
    std::uint64_t malformed = 0, unchecked = 0;
    std::uint64_t last = 0;  // the last state's log time (any time range)
    std::vector<mcap::Metadata> meta;  // of the first pass
    mcap::ScanResult scan;
    bool first = true;
  };

  ExportPass(const ExportOptions& o, const std::vector<std::uint32_t>& vehicles) {
    for (std::uint32_t id : vehicles) {
      auto& f = files_[id] = std::make_unique<OutputFile>(
          o.each ? VehiclePath(o.csv, id) : o.csv, std::vector<std::filesystem::path>{o.file});
      // The CSV writer opens the temporary file itself; a stream (a FIFO, /dev/stdout) stays
      // open here until the end, so its reader sees one writer from the first row to the last.
      if (!f->stream()) ::close(f->Release());
      writers_[id] = std::make_unique<CsvWriter>(f->temp());
    }
  }

  void Scan(const mcap::Reader& reader, const Range& r, Totals& t,
            const std::function<void(double)>& progress) {
    RecordingVisitor v;
    v.wants = [](transport::TopicId topic) { return topic == transport::TopicId::kState; };
    v.on_progress = progress;
    const bool first = t.first;
    v.on_metadata = [&](const mcap::Metadata& m) {
      if (first) t.meta.push_back(m);
    };
    v.on_message = [&](const RecordedMessage& m) {
      t.last = std::max(t.last, m.log_time);
      if (m.log_time < r.from || m.log_time > r.to) return;
      const auto w = writers_.find(m.key);
      if (w == writers_.end()) return;
      // The step first, without parsing: decimation skips most states cheaply.
      if (r.every > 1 && wire::Number(m.data, 3).value_or(0) % r.every != 0) return;
      if (!state_.ParseFromArray(m.data.data(), static_cast<int>(m.data.size()))) {
        ++t.malformed;
        return;
      }
      w->second->WriteRow(state_);
      t.unchecked += m.unchecked ? 1 : 0;
    };
    const mcap::ScanResult scan = ScanRecording(reader, v);
    if (first) t.scan = scan;
    t.first = false;
  }

  // Each file with rows goes under its name; one without (no state of the vehicle in the time
  // range) is not written: said, and counted in `empty`.
  void Commit(std::ostream& report, std::size_t& written, std::size_t& empty) {
    for (auto& [id, w] : writers_) {
      try {
        w->Close();
      } catch (const std::runtime_error& e) {
        // The writer's message names its file already (the scratch file's name: the output's).
        const std::string what = e.what();
        const std::string dest = files_[id]->dest().string();
        throw OutputError(what.rfind(dest, 0) == 0 ? what : dest + ": " + what);
      }
      if (w->rows() == 0) {
        ++empty;
        report << "vehicle " << id << ": no states in the time range: "
               << files_[id]->dest().string() << " not written\n";
        continue;
      }
      files_[id]->Commit();
      ++written;
      report << "vehicle " << id << ": " << w->rows() << " rows, " << CsvColumns().size()
             << " columns -> " << files_[id]->dest().string() << "\n";
    }
  }

 private:
  std::map<std::uint32_t, std::unique_ptr<OutputFile>> files_;
  std::map<std::uint32_t, std::unique_ptr<CsvWriter>> writers_;
  pb::VehicleState state_;
};

}  // namespace

int RunExport(const ExportOptions& o, std::ostream& out) {
  mcap::Reader reader(o.file);
  // The vehicles first (from the summary's channels when there is one: no second full scan).
  std::set<std::uint32_t> vehicles;
  if (auto s = reader.ReadSummary()) {
    for (const auto& [id, info] : VdynChannels(*s)) {
      if (info.topic == transport::TopicId::kState) vehicles.insert(info.key);
    }
  } else {
    RecordingVisitor v;
    v.wants = [](transport::TopicId t) { return t == transport::TopicId::kState; };
    v.on_message = [&](const RecordedMessage& m) { vehicles.insert(m.key); };
    ScanRecording(reader, v);
  }
  if (vehicles.empty()) {
    out << "vdyn-recorder export: " << o.file.string() << " holds no vehicle states (vdyn/state)\n";
    return 1;
  }
  std::set<std::uint32_t> chosen;
  if (o.vehicle) {
    if (vehicles.count(*o.vehicle) == 0) {
      std::string have;
      for (std::uint32_t v : vehicles) have += (have.empty() ? "" : ", ") + std::to_string(v);
      out << "vdyn-recorder export: no states of vehicle " << *o.vehicle << " in "
          << o.file.string() << " (it has vehicle " << have << ")\n";
      return 2;
    }
    chosen = {*o.vehicle};
  } else if (o.each || vehicles.size() == 1) {
    chosen = vehicles;
  } else {
    std::string have;
    for (std::uint32_t v : vehicles) have += (have.empty() ? "" : ", ") + std::to_string(v);
    out << "vdyn-recorder export: " << o.file.string() << " holds vehicles " << have
        << ": choose one with --vehicle ID, or --each for a file per vehicle\n";
    return 2;
  }
  // --each names its files after --csv (NAME-v1.csv, ...): beside a stream that made regular
  // files such as /dev/stdout-v1 and wrote nothing to the stream.
  if (o.each && CheckOutputKind(o.csv) == OutputKind::kStream) {
    out << "vdyn-recorder export: --each writes a file per vehicle named after --csv ("
        << VehiclePath(o.csv, *chosen.begin()).filename().string() << ", ...); "
        << o.csv.string()
        << " is a stream: give a file name, or choose one vehicle with --vehicle ID\n";
    return 2;
  }
  // With the CSV on the standard output, what export says goes to the standard error.
  std::ostream& report = NamesStandardOutput(o.csv) ? std::cerr : out;
  const std::uint64_t start = FirstLogTime(reader);
  ExportPass::Range range;
  range.from = start + static_cast<std::uint64_t>(base::FromSeconds(o.from_s).ns);
  range.to = o.to_s ? start + static_cast<std::uint64_t>(base::FromSeconds(*o.to_s).ns) : ~0ull;
  range.every = static_cast<std::uint64_t>(std::max(1, o.every));
  // At most kOpenAtOnce files open (each with its 1 MiB buffer): a file of many vehicles
  // (--each) is read once per batch of them, so memory and descriptors stay bounded whatever
  // the file holds.
  ExportPass::Totals totals;
  std::size_t written = 0, empty = 0;
  Progress progress("export");
  const std::vector<std::uint32_t> all(chosen.begin(), chosen.end());
  for (std::size_t at = 0; at < all.size(); at += kOpenAtOnce) {
    const std::size_t n = std::min(kOpenAtOnce, all.size() - at);
    ExportPass pass(o, {all.begin() + static_cast<std::ptrdiff_t>(at),
                        all.begin() + static_cast<std::ptrdiff_t>(at + n)});
    pass.Scan(reader, range, totals, [&](double f) {
      progress.Update((static_cast<double>(at) + f * static_cast<double>(n)) /
                      static_cast<double>(all.size()));
    });
    pass.Commit(report, written, empty);
  }
  progress.Finish();
  const mcap::ScanResult& scan = totals.scan;
  const std::vector<mcap::Metadata>& meta = totals.meta;
  const std::uint64_t unchecked = totals.unchecked, malformed = totals.malformed;
  // No more integrity than the recording has.
  for (const std::string& line : IntegrityNotes(meta, scan, unchecked, "rows")) {
    report << "vdyn-recorder export: " << line << "\n";
  }
  if (malformed > 0) {
    report << "vdyn-recorder export: " << malformed
           << " state messages did not parse and were skipped\n";
    return 1;
  }
  if (written == 0) {
    char span[64];
    std::snprintf(span, sizeof span, "%.3f",
                  static_cast<double>(totals.last > start ? totals.last - start : 0) * 1e-9);
    report << "vdyn-recorder export: nothing written: no states in the time range (the "
           << "recording's states end at " << span << " s)\n";
    return 1;
  }
  return 0;
}

}  // namespace vdyn::recorder
