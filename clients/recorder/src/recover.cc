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

}  // namespace

int RunRecover(const RecoverOptions& o, std::ostream& out) {
  std::filesystem::path dest = o.out;
  if (dest.empty()) {
    dest = o.file;
    dest.replace_filename(o.file.stem().string() + "-recovered" + o.file.extension().string());
  }
  CheckNotAnInput(dest, {o.file});
  mcap::Reader reader(o.file, mcap::Reader::Open::kSalvage);
  // First, without decompressing anything (cheap): the chunks' compression, and whether the
  // data section's CRC holds - then it vouches for the chunks that carry none of their own.
  std::map<std::string, int> compressions;
  mcap::Visitor probe;
  probe.on_chunk = [&](const mcap::ChunkIndex& c) {
    ++compressions[c.compression];
    return false;
  };
  const mcap::ScanResult layout = reader.Scan(probe, /*lenient=*/true);
  const bool data_crc_holds = layout.data_crc == mcap::ScanResult::DataCrc::kMatched;
  // The summary, only as a second copy of schema and channel records whose data-section copy is
  // damaged (and only when its own CRC holds).
  std::optional<mcap::Reader::Summary> summary;
  std::string summary_state = layout.summary ? "read" : "absent";
  try {
    summary = reader.ReadSummary();
  } catch (const mcap::McapError& e) {
    summary_state = "damaged (" + e.reason() + ")";
  }

  mcap::WriterOptions wo;
  wo.library = reader.header_library().empty() ? "vdyn-recorder" : reader.header_library();
  wo.library += " (recovered)";
  wo.compression = compressions["lz4"] > compressions["zstd"] ? mcap::Compression::kLz4
                                                              : mcap::Compression::kZstd;
  wo.inputs = {o.file};
  mcap::Writer writer(dest, wo);
  std::map<std::uint16_t, mcap::Schema> source_schemas;
  std::map<std::uint16_t, std::uint16_t> schema_ids, channel_ids;
  std::vector<std::string> notes;  // schemas and channels taken from elsewhere, or missing
  std::map<std::uint16_t, std::uint64_t> orphans;  // messages on a channel no record defines
  std::uint64_t kept = 0, unchecked = 0, first_log = 0;
  Ranges unchecked_ranges;
  bool last_unchecked = false;
  auto summary_schema = [&](std::uint16_t id) -> const mcap::Schema* {
    if (!summary) return nullptr;
    for (const mcap::Schema& s : summary->schemas) {
      if (s.id == id) return &s;
    }
    return nullptr;
  };
  // The copy's id of a source schema: from its record, else the summary's copy, else (a vdyn
  // channel) this build's descriptor of the topic's type; 0 when there is none.
  auto schema_for = [&](const mcap::Channel& c) -> std::uint16_t {
    if (c.schema_id == 0) return 0;
    if (const auto it = schema_ids.find(c.schema_id); it != schema_ids.end()) return it->second;
    const mcap::Schema* s = nullptr;
    if (const auto it = source_schemas.find(c.schema_id); it != source_schemas.end())
      s = &it->second;
    if (s == nullptr && (s = summary_schema(c.schema_id)) != nullptr) {
      notes.push_back("schema " + std::to_string(c.schema_id) + " ('" + s->name +
                      "') from the summary: its record in the data section is damaged");
    }
    if (s != nullptr) {
      return schema_ids[c.schema_id] = writer.AddSchema(s->name, s->encoding, s->data);
    }
    const auto info = ParseChannelInfo(c);
    if (info && PayloadDescriptor(info->topic) != nullptr) {
      const auto* d = PayloadDescriptor(info->topic);
      notes.push_back("schema " + std::to_string(c.schema_id) + " of " + c.topic +
                      " rebuilt from this build's descriptor of " + d->full_name() +
                      ": its records are damaged");
      return schema_ids[c.schema_id] =
                 writer.AddSchema(d->full_name(), "protobuf", FileDescriptorSetOf(d));
    }
    notes.push_back("channel " + c.topic + " names schema " + std::to_string(c.schema_id) +
                    ", which is damaged: its messages are kept without a schema");
    return 0;
  };
  auto add_channel = [&](const mcap::Channel& c) {
    channel_ids[c.id] = writer.AddChannel(schema_for(c), c.topic, c.message_encoding, c.metadata);
  };
  mcap::Visitor v;
  v.on_schema = [&](const mcap::Schema& s) {
    source_schemas.try_emplace(s.id, s);
    if (schema_ids.count(s.id) == 0)
      schema_ids[s.id] = writer.AddSchema(s.name, s.encoding, s.data);
  };
  v.on_channel = [&](const mcap::Channel& c) {
    if (channel_ids.count(c.id) == 0) add_channel(c);
  };
  v.on_message = [&](const mcap::Message& m, std::uint64_t) {
    if (channel_ids.count(m.channel_id) == 0) {
      // Its channel record is damaged: the summary's copy, else the message is lost.
      const mcap::Channel* copy = nullptr;
      if (summary) {
        for (const mcap::Channel& c : summary->channels) {
          if (c.id == m.channel_id) copy = &c;
        }
      }
      if (copy == nullptr) {
        ++orphans[m.channel_id];
        return;
      }
      notes.push_back("channel " + std::to_string(copy->id) + " (" + copy->topic +
                      ") from the summary: its record in the data section is damaged");
      add_channel(*copy);
    }
    const bool no_crc = m.unchecked && !data_crc_holds;
    writer.SetChunkCrc(!no_crc);
    writer.WriteMessage(channel_ids.at(m.channel_id), m.sequence, m.log_time, m.publish_time,
                        m.data);
    if (first_log == 0 || m.log_time < first_log) first_log = m.log_time;
    if (no_crc) {
      ++unchecked;
      unchecked_ranges.Add(m.log_time, m.log_time, last_unchecked);
    }
    last_unchecked = no_crc;
    ++kept;
  };
  v.on_metadata = [&](const mcap::Metadata& m, std::uint64_t) {
    writer.WriteMetadata(m.name, m.values);
  };
  Progress progress("recover");
  v.on_progress = [&](std::uint64_t at) {
    progress.Update(static_cast<double>(at) / static_cast<double>(reader.size()));
  };
  const mcap::ScanResult r = reader.Scan(v, /*lenient=*/true);
  progress.Finish();

  // What was left out, and what no CRC vouches for.
  std::uint64_t lost_messages = 0, lost_bytes = 0;
  Ranges lost_ranges;
  for (const mcap::Damage& d : r.damage) {
    lost_bytes += d.length;
    lost_messages += d.messages;
    if (d.chunk && d.chunk->message_end_time >= d.chunk->message_start_time) {
      lost_ranges.Add(d.chunk->message_start_time, d.chunk->message_end_time);
    }
  }
  std::uint64_t orphaned = 0;
  for (const auto& [ch, n] : orphans) {
    orphaned += n;
    notes.push_back(std::to_string(n) + " messages on channel " + std::to_string(ch) +
                    ", whose channel record is damaged (no copy in a summary): left out");
  }
  const bool closed = r.data_crc != mcap::ScanResult::DataCrc::kNotReached;
  mcap::StringMap meta = {{"from", o.file.filename().string()},
                          {"file_size", std::to_string(reader.size())},
                          {"good_until", std::to_string(r.good_until)},
                          {"closed", closed ? "yes" : "no"},
                          {"data_crc", DataCrcText(r.data_crc)},
                          {"summary", summary_state},
                          {"problem", r.problem},
                          {"problem_offset", std::to_string(r.problem_offset)},
                          {"messages", std::to_string(kept)},
                          {"chunks_skipped", std::to_string(r.chunks_skipped)},
                          {"chunks_duplicated", std::to_string(r.chunks_duplicated)},
                          {"records_skipped", std::to_string(r.records_skipped)},
                          {"bytes_left_out", std::to_string(lost_bytes)},
                          {"messages_lost", std::to_string(lost_messages + orphaned)},
                          {"lost_log_ns", lost_ranges.Text()},
                          {"unchecked_messages", std::to_string(unchecked)},
                          {"unchecked_log_ns", unchecked_ranges.Text()}};
  constexpr std::size_t kListed = 200;
  for (std::size_t i = 0; i < r.damage.size() && i < kListed; ++i) {
    const mcap::Damage& d = r.damage[i];
    char key[32];
    std::snprintf(key, sizeof key, "damage.%03zu", i);
    meta[key] = "offset " + std::to_string(d.offset) + ", " + std::to_string(d.length) +
                " bytes: " + d.what;
  }
  if (r.damage.size() > kListed) meta["damage.more"] = std::to_string(r.damage.size() - kListed);
  for (std::size_t i = 0; i < notes.size() && i < kListed; ++i) {
    char key[32];
    std::snprintf(key, sizeof key, "note.%03zu", i);
    meta[key] = notes[i];
  }
  writer.SetChunkCrc(true);
  writer.WriteMetadata("vdyn.recovered", meta);
  writer.Close();

  const bool whole = r.complete && r.damage.empty() && notes.empty() && unchecked == 0;
  if (whole) {
    out << o.file.string() << " was whole (" << kept << " messages); a fresh copy is in "
        << dest.string() << "\n";
    return 0;
  }
  auto at = [&](std::uint64_t ns) {
    char b[32];
    // Signed: a lost chunk may lie before the first message kept.
    std::snprintf(b, sizeof b, "%.3f s",
                  (static_cast<double>(ns) - static_cast<double>(first_log)) * 1e-9);
    return std::string(b);
  };
  // The copy's chunks are counted as `info` counts them (the writer packs them anew).
  out << o.file.string() << ": recovered " << Count(kept, "message", "messages") << " from "
      << Count(r.chunks, "chunk", "chunks") << " of the source, written in "
      << Count(writer.chunks(), "chunk", "chunks");
  if (r.chunks_skipped > 0)
    out << "; " << Count(r.chunks_skipped, "damaged chunk", "damaged chunks") << " dropped";
  if (r.chunks_duplicated > 0)
    out << "; " << Count(r.chunks_duplicated, "copy of a chunk", "copies of a chunk") << " dropped";
  if (r.records_skipped > 0)
    out << "; "
        << Count(r.records_skipped, "damaged record or run of bytes",
                 "damaged records or runs of bytes")
        << " skipped";
  if (!closed) out << " (the file was not closed: no data end record)";
  out << "\n";
  if (!r.damage.empty()) out << "  damage found (" << r.damage.size() << "):\n";
  for (std::size_t i = 0; i < r.damage.size() && i < 20; ++i) {
    const mcap::Damage& d = r.damage[i];
    out << "    offset " << d.offset;
    if (d.length > 0) out << ", " << d.length << " bytes";
    out << ": " << d.what;
    if (d.messages > 0) out << "; " << Count(d.messages, "message", "messages");
    if (d.chunk && d.chunk->message_end_time >= d.chunk->message_start_time) {
      out << " (log time " << at(d.chunk->message_start_time) << " .. "
          << at(d.chunk->message_end_time) << ")";
    }
    out << "\n";
  }
  if (r.damage.size() > 20)
    out << "    ... " << (r.damage.size() - 20) << " more (in the copy's metadata)\n";
  for (const std::string& n : notes) out << "  " << n << "\n";
  if (summary_state != "read" && summary_state != "absent") {
    out << "  the source's summary is " << summary_state
        << ": not used; the copy's is rebuilt from the data section\n";
  }
  if (unchecked > 0) {
    out << "  unchecked: " << unchecked << " messages lie in chunks without a CRC and the source's "
        << "data-section CRC "
        << (r.data_crc == mcap::ScanResult::DataCrc::kMismatched
                ? "does not match"
                : "is " + std::string(DataCrcText(r.data_crc)))
        << ": nothing can tell whether they are intact; the copy keeps them in chunks without a "
           "CRC "
           "and says so (`vdyn-recorder info`)\n";
  }
  out << "written, closed and indexed: " << dest.string() << "\n";
  return 0;
}

}  // namespace vdyn::recorder
