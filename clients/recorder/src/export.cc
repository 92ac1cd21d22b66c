// `vdyn-recorder export FILE --csv OUT.csv`: the recorded states as the batch CSV (io's
// CsvWriter over VehicleState: the same columns, units and order as `vdyn-server --batch --csv`,
// so one analysis script reads both).
#include <unistd.h>

#include <iostream>
#include <map>
#include <memory>
#include <set>

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
  // Each CSV is written beside its name and renamed when whole; never over the recording.
  std::map<std::uint32_t, std::unique_ptr<OutputFile>> files;
  std::map<std::uint32_t, std::unique_ptr<CsvWriter>> writers;
  for (std::uint32_t id : chosen) {
    auto& f = files[id] = std::make_unique<OutputFile>(o.each ? VehiclePath(o.csv, id) : o.csv,
                                                       std::vector<std::filesystem::path>{o.file});
    // The CSV writer opens the temporary file itself; a stream (a FIFO, /dev/stdout) stays
    // open here until the end, so its reader sees one writer from the first row to the last.
    if (!f->stream()) ::close(f->Release());
    writers[id] = std::make_unique<CsvWriter>(f->temp());
  }
  // With the CSV on the standard output, what export says goes to the standard error.
  std::ostream& report = NamesStandardOutput(o.csv) ? std::cerr : out;
  const std::uint64_t start = FirstLogTime(reader);
  const auto from = start + static_cast<std::uint64_t>(base::FromSeconds(o.from_s).ns);
  const auto to =
      o.to_s ? start + static_cast<std::uint64_t>(base::FromSeconds(*o.to_s).ns) : ~0ull;
  const auto every = static_cast<std::uint64_t>(std::max(1, o.every));
  pb::VehicleState state;
  std::uint64_t malformed = 0, unchecked = 0;
  std::vector<mcap::Metadata> meta;
  Progress progress("export");
  RecordingVisitor v;
  v.wants = [](transport::TopicId t) { return t == transport::TopicId::kState; };
  v.on_progress = [&](double f) { progress.Update(f); };
  v.on_metadata = [&](const mcap::Metadata& m) { meta.push_back(m); };
  v.on_message = [&](const RecordedMessage& m) {
    if (m.log_time < from || m.log_time > to) return;
    const auto w = writers.find(m.key);
    if (w == writers.end()) return;
    // The step first, without parsing: decimation skips most states cheaply.
    if (every > 1 && wire::Number(m.data, 3).value_or(0) % every != 0) return;
    if (!state.ParseFromArray(m.data.data(), static_cast<int>(m.data.size()))) {
      ++malformed;
      return;
    }
    w->second->WriteRow(state);
    unchecked += m.unchecked ? 1 : 0;
  };
  const mcap::ScanResult scan = ScanRecording(reader, v);
  progress.Finish();
  for (auto& [id, w] : writers) {
    try {
      w->Close();
    } catch (const std::runtime_error& e) {
      throw OutputError(files[id]->dest().string() + ": " + e.what());
    }
    files[id]->Commit();
    report << "vehicle " << id << ": " << w->rows() << " rows, " << CsvColumns().size()
           << " columns -> " << files[id]->dest().string() << "\n";
  }
  // No more integrity than the recording has.
  for (const std::string& line : IntegrityNotes(meta, scan, unchecked, "rows")) {
    report << "vdyn-recorder export: " << line << "\n";
  }
  if (malformed > 0) {
    report << "vdyn-recorder export: " << malformed
           << " state messages did not parse and were skipped\n";
    return 1;
  }
  return 0;
}

}  // namespace vdyn::recorder
