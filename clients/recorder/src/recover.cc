// `vdyn-recorder recover FILE`: salvages a recording that was not closed (a killed recorder, a
// full disk) or is damaged. It never relies on the summary or the footer: it scans the data
// section (mcap::Reader::Scan, lenient), keeps every whole record and every chunk that
// decompresses and passes its CRC, leaves out only what is damaged - a chunk, a record whose
// fields do not read, a run of bytes up to the next valid record, an exact copy of a chunk -
// and closes the copy properly again: data end, summary with statistics, chunk and message
// indexes, footer, under a new name. Chunks are re-compressed as the writer does; nothing is
// re-encoded.
//
// Nothing is laundered: a message no CRC vouched for in the source (a chunk whose CRC is 0, in a
// file whose data-section CRC does not hold) goes into a chunk whose CRC is 0 again, and the
// copy's "vdyn.recovered" metadata lists what was left out and what is unchecked, which `info`
// prints.
#include <algorithm>
#include <cstdio>
#include <map>
#include <optional>
#include <set>

#include "vdyn/recorder/commands.h"
#include "vdyn/recorder/output_file.h"
#include "vdyn/recorder/recording.h"

namespace vdyn::recorder {

namespace {

// Log-time ranges (a run of chunks, of unchecked messages).
class Ranges {
 public:
  // A new range, or (`extend`) the last one grown to hold [a, b].
  void Add(std::uint64_t a, std::uint64_t b, bool extend = false) {
    if (extend && !r_.empty()) {
      r_.back().first = std::min(r_.back().first, a);
      r_.back().second = std::max(r_.back().second, b);
    } else {
      r_.emplace_back(a, b);
    }
  }
  // "a-b,c-d" in ns (docs/formats.md, vdyn.recovered).
  std::string Text() const {
    std::string s;
    for (const auto& [a, b] : r_) {
      if (!s.empty()) s += ',';
      s += std::to_string(a);
      s += '-';
      s += std::to_string(b);
    }
    return s;
  }

 private:
  std::vector<std::pair<std::uint64_t, std::uint64_t>> r_;
};

const char* DataCrcText(mcap::ScanResult::DataCrc c) {
  switch (c) {
    case mcap::ScanResult::DataCrc::kMatched:
      return "matched";
    case mcap::ScanResult::DataCrc::kAbsent:
      return "absent";
    case mcap::ScanResult::DataCrc::kMismatched:
      return "mismatched";
    case mcap::ScanResult::DataCrc::kNotReached:
      return "not reached";
  }
  return "";
}

// `recover` as its stages: probe the source (its chunks' compression, whether its data-section
// CRC holds, its summary as a second copy), copy every whole record into a new writer, sum up what
// was left out and what no CRC vouches for into the copy's metadata, close it, and report.
class Recovery {
 public:
  Recovery(const RecoverOptions& o, std::filesystem::path dest)
      : o_(o), dest_(std::move(dest)), reader_(o.file, mcap::Reader::Open::kSalvage) {}

  int Run(std::ostream& out) {
    Probe();
    OpenCopy();
    CopyRecords();
    // Nothing read (a file of its magic alone, or all damage): refused as a file with nothing in
    // it (exit 2; the unwinding abandons the copy), rather than an empty recording under the name.
    if (kept_ == 0) {
      throw mcap::McapError(o_.file, 8, "nothing to recover: no message in it reads; nothing written");
    }
    const Losses losses = Tally();
    WriteMetadata(losses);
    writer_->Close();
    Report(out);
    return 0;
  }

 private:
  struct Losses {
    std::uint64_t messages = 0, bytes = 0, orphaned = 0;
    Ranges ranges;
  };

  // Without decompressing anything (cheap): the chunks' compression, and whether the data
  // section's CRC holds - then it vouches for the chunks that carry none of their own. The
  // summary, only as a second copy of schema and channel records whose data-section copy is
  // damaged (and only when its own CRC holds).
  void Probe() {
    mcap::Visitor probe;
    probe.on_chunk = [&](const mcap::ChunkIndex& c) {
      ++compressions_[c.compression];
      return false;
    };
    const mcap::ScanResult layout = reader_.Scan(probe, /*lenient=*/true);
    data_crc_holds_ = layout.data_crc == mcap::ScanResult::DataCrc::kMatched;
    summary_state_ = layout.summary ? "read" : "absent";
    try {
      summary_ = reader_.ReadSummary();
    } catch (const mcap::McapError& e) {
      summary_state_ = "damaged (" + e.reason() + ")";
    }
  }

  void OpenCopy() {
    mcap::WriterOptions wo;
    wo.library = reader_.header_library().empty() ? "vdyn-recorder" : reader_.header_library();
    wo.library += " (recovered)";
    wo.compression = compressions_["lz4"] > compressions_["zstd"] ? mcap::Compression::kLz4
                                                                  : mcap::Compression::kZstd;
    wo.inputs = {o_.file};
    writer_.emplace(dest_, wo);
  }

  void CopyRecords() {
    mcap::Visitor v;
    v.on_schema = [&](const mcap::Schema& s) {
      source_schemas_.try_emplace(s.id, s);
      if (schema_ids_.count(s.id) == 0)
        schema_ids_[s.id] = writer_->AddSchema(s.name, s.encoding, s.data);
    };
    v.on_channel = [&](const mcap::Channel& c) {
      if (channel_ids_.count(c.id) == 0) AddChannel(c);
    };
    v.on_message = [&](const mcap::Message& m, std::uint64_t) { CopyMessage(m); };
    v.on_metadata = [&](const mcap::Metadata& m, std::uint64_t) {
      writer_->WriteMetadata(m.name, m.values);
    };
    Progress progress("recover");
    v.on_progress = [&](std::uint64_t at) {
      progress.Update(static_cast<double>(at) / static_cast<double>(reader_.size()));
    };
    scan_ = reader_.Scan(v, /*lenient=*/true);
    progress.Finish();
  }

  const mcap::Schema* SummarySchema(std::uint16_t id) const {
    if (!summary_) return nullptr;
    for (const mcap::Schema& s : summary_->schemas) {
      if (s.id == id) return &s;
    }
    return nullptr;
  }

  // The copy's id of a source schema: from its record, else the summary's copy, else (a vdyn
  // channel) this build's descriptor of the topic's type; 0 when there is none.
  std::uint16_t SchemaFor(const mcap::Channel& c) {
    if (c.schema_id == 0) return 0;
    if (const auto it = schema_ids_.find(c.schema_id); it != schema_ids_.end()) return it->second;
    const mcap::Schema* s = nullptr;
    if (const auto it = source_schemas_.find(c.schema_id); it != source_schemas_.end())
      s = &it->second;
    if (s == nullptr && (s = SummarySchema(c.schema_id)) != nullptr) {
      notes_.push_back("schema " + std::to_string(c.schema_id) + " ('" + s->name +
                       "') from the summary: its record in the data section is damaged");
    }
    if (s != nullptr) {
      return schema_ids_[c.schema_id] = writer_->AddSchema(s->name, s->encoding, s->data);
    }
    const auto info = ParseChannelInfo(c);
    if (info && PayloadDescriptor(info->topic) != nullptr) {
      const auto* d = PayloadDescriptor(info->topic);
      notes_.push_back("schema " + std::to_string(c.schema_id) + " of " + c.topic +
                       " rebuilt from this build's descriptor of " + d->full_name() +
                       ": its records are damaged");
      return schema_ids_[c.schema_id] =
                 writer_->AddSchema(d->full_name(), "protobuf", FileDescriptorSetOf(d));
    }
    notes_.push_back("channel " + c.topic + " names schema " + std::to_string(c.schema_id) +
                     ", which is damaged: its messages are kept without a schema");
    return 0;
  }

  void AddChannel(const mcap::Channel& c) {
    channel_ids_[c.id] = writer_->AddChannel(SchemaFor(c), c.topic, c.message_encoding, c.metadata);
  }

  void CopyMessage(const mcap::Message& m) {
    if (channel_ids_.count(m.channel_id) == 0) {
      // Its channel record is damaged: the summary's copy, else the message is lost.
      const mcap::Channel* copy = nullptr;
      if (summary_) {
        for (const mcap::Channel& c : summary_->channels) {
          if (c.id == m.channel_id) copy = &c;
        }
      }
      if (copy == nullptr) {
        ++orphans_[m.channel_id];
        return;
      }
      notes_.push_back("channel " + std::to_string(copy->id) + " (" + copy->topic +
                       ") from the summary: its record in the data section is damaged");
      AddChannel(*copy);
    }
    const bool no_crc = m.unchecked && !data_crc_holds_;
    writer_->SetChunkCrc(!no_crc);
    writer_->WriteMessage(channel_ids_.at(m.channel_id), m.sequence, m.log_time, m.publish_time,
                          m.data);
    if (first_log_ == 0 || m.log_time < first_log_) first_log_ = m.log_time;
    if (no_crc) {
      ++unchecked_;
      unchecked_ranges_.Add(m.log_time, m.log_time, last_unchecked_);
    }
    last_unchecked_ = no_crc;
    ++kept_;
  }

  // What was left out: damaged bytes and chunks, and messages whose channel nothing defines.
  Losses Tally() {
    Losses l;
    for (const mcap::Damage& d : scan_.damage) {
      l.bytes += d.length;
      l.messages += d.messages;
      if (d.chunk && d.chunk->message_end_time >= d.chunk->message_start_time) {
        l.ranges.Add(d.chunk->message_start_time, d.chunk->message_end_time);
      }
    }
    for (const auto& [ch, n] : orphans_) {
      l.orphaned += n;
      notes_.push_back(std::to_string(n) + " messages on channel " + std::to_string(ch) +
                       ", whose channel record is damaged (no copy in a summary): left out");
    }
    return l;
  }

  bool Closed() const { return scan_.data_crc != mcap::ScanResult::DataCrc::kNotReached; }

  // The copy's "vdyn.recovered" metadata (docs/formats.md): what was left out and what no CRC
  // vouches for, which `info` prints.
  void WriteMetadata(const Losses& l) {
    const mcap::ScanResult& r = scan_;
    mcap::StringMap meta = {{"from", o_.file.filename().string()},
                            {"file_size", std::to_string(reader_.size())},
                            {"good_until", std::to_string(r.good_until)},
                            {"closed", Closed() ? "yes" : "no"},
                            {"data_crc", DataCrcText(r.data_crc)},
                            {"summary", summary_state_},
                            {"problem", r.problem},
                            {"problem_offset", std::to_string(r.problem_offset)},
                            {"messages", std::to_string(kept_)},
                            {"chunks_skipped", std::to_string(r.chunks_skipped)},
                            {"chunks_duplicated", std::to_string(r.chunks_duplicated)},
                            {"records_skipped", std::to_string(r.records_skipped)},
                            {"bytes_left_out", std::to_string(l.bytes)},
                            {"messages_lost", std::to_string(l.messages + l.orphaned)},
                            {"lost_log_ns", l.ranges.Text()},
                            {"unchecked_messages", std::to_string(unchecked_)},
                            {"unchecked_log_ns", unchecked_ranges_.Text()}};
    constexpr std::size_t kListed = 200;
    for (std::size_t i = 0; i < r.damage.size() && i < kListed; ++i) {
      const mcap::Damage& d = r.damage[i];
      char key[32];
      std::snprintf(key, sizeof key, "damage.%03zu", i);
      meta[key] = "offset " + std::to_string(d.offset) + ", " + std::to_string(d.length) +
                  " bytes: " + d.what;
    }
    if (r.damage.size() > kListed) meta["damage.more"] = std::to_string(r.damage.size() - kListed);
    for (std::size_t i = 0; i < notes_.size() && i < kListed; ++i) {
      char key[32];
      std::snprintf(key, sizeof key, "note.%03zu", i);
      meta[key] = notes_[i];
    }
    writer_->SetChunkCrc(true);
    writer_->WriteMetadata("vdyn.recovered", meta);
  }

  // A log time as seconds after the first message kept (signed: a lost chunk may lie before it).
  std::string At(std::uint64_t ns) const {
    char b[32];
    std::snprintf(b, sizeof b, "%.3f s",
                  (static_cast<double>(ns) - static_cast<double>(first_log_)) * 1e-9);
    return b;
  }

  void Report(std::ostream& out) const {
    const mcap::ScanResult& r = scan_;
    const bool whole = r.complete && r.damage.empty() && notes_.empty() && unchecked_ == 0;
    if (whole) {
      out << o_.file.string() << " was whole (" << kept_ << " messages); a fresh copy is in "
          << dest_.string() << "\n";
      return;
    }
    ReportCounts(out);
    ReportDamage(out);
    for (const std::string& n : notes_) out << "  " << n << "\n";
    if (summary_state_ != "read" && summary_state_ != "absent") {
      out << "  the source's summary is " << summary_state_
          << ": not used; the copy's is rebuilt from the data section\n";
    }
    if (unchecked_ > 0) {
      out << "  unchecked: " << unchecked_
          << " messages lie in chunks without a CRC and the source's "
          << "data-section CRC "
          << (r.data_crc == mcap::ScanResult::DataCrc::kMismatched
                  ? "does not match"
                  : "is " + std::string(DataCrcText(r.data_crc)))
          << ": nothing can tell whether they are intact; the copy keeps them in chunks without a "
             "CRC "
             "and says so (`vdyn-recorder info`)\n";
    }
    out << "written, closed and indexed: " << dest_.string() << "\n";
  }

  // The copy's chunks are counted as `info` counts them (the writer packs them anew).
  void ReportCounts(std::ostream& out) const {
    const mcap::ScanResult& r = scan_;
    out << o_.file.string() << ": recovered " << Count(kept_, "message", "messages") << " from "
        << Count(r.chunks, "chunk", "chunks") << " of the source, written in "
        << Count(writer_->chunks(), "chunk", "chunks");
    if (r.chunks_skipped > 0)
      out << "; " << Count(r.chunks_skipped, "damaged chunk", "damaged chunks") << " dropped";
    if (r.chunks_duplicated > 0)
      out << "; " << Count(r.chunks_duplicated, "copy of a chunk", "copies of a chunk")
          << " dropped";
    if (r.records_skipped > 0)
      out << "; "
          << Count(r.records_skipped, "damaged record or run of bytes",
                   "damaged records or runs of bytes")
          << " skipped";
    if (!Closed()) out << " (the file was not closed: no data end record)";
    out << "\n";
  }

  void ReportDamage(std::ostream& out) const {
    const mcap::ScanResult& r = scan_;
    if (!r.damage.empty()) out << "  damage found (" << r.damage.size() << "):\n";
    for (std::size_t i = 0; i < r.damage.size() && i < 20; ++i) {
      const mcap::Damage& d = r.damage[i];
      out << "    offset " << d.offset;
      if (d.length > 0) out << ", " << d.length << " bytes";
      out << ": " << d.what;
      if (d.messages > 0) out << "; " << Count(d.messages, "message", "messages");
      if (d.chunk && d.chunk->message_end_time >= d.chunk->message_start_time) {
        out << " (log time " << At(d.chunk->message_start_time) << " .. "
            << At(d.chunk->message_end_time) << ")";
      }
      out << "\n";
    }
    if (r.damage.size() > 20)
      out << "    ... " << (r.damage.size() - 20) << " more (in the copy's metadata)\n";
  }

  const RecoverOptions& o_;
  const std::filesystem::path dest_;
  mcap::Reader reader_;
  // The source, probed.
  std::map<std::string, int> compressions_;
  bool data_crc_holds_ = false;
  std::optional<mcap::Reader::Summary> summary_;
  std::string summary_state_;
  // The copy.
  std::optional<mcap::Writer> writer_;
  std::map<std::uint16_t, mcap::Schema> source_schemas_;
  std::map<std::uint16_t, std::uint16_t> schema_ids_, channel_ids_;
  std::vector<std::string> notes_;  // schemas and channels taken from elsewhere, or missing
  std::map<std::uint16_t, std::uint64_t> orphans_;  // messages on a channel no record defines
  std::uint64_t kept_ = 0, unchecked_ = 0, first_log_ = 0;
  Ranges unchecked_ranges_;
  bool last_unchecked_ = false;
  mcap::ScanResult scan_;
};

}  // namespace

int RunRecover(const RecoverOptions& o, std::ostream& out) {
  std::filesystem::path dest = o.out;
  if (dest.empty()) {
    dest = o.file;
    dest.replace_filename(o.file.stem().string() + "-recovered" + o.file.extension().string());
  }
  CheckNotAnInput(dest, {o.file});
  return Recovery(o, dest).Run(out);
}

}  // namespace vdyn::recorder
