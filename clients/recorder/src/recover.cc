// `vdyn-recorder recover FILE`: salvages a recording that was not closed (a killed recorder, a
// full disk) or is damaged: every whole record and every chunk that decompresses and passes its
// CRC is kept, in order, and the file is closed properly again - data end, summary with
// statistics, chunk and message indexes, footer - under a new name. Chunks are re-compressed
// as the writer does; nothing is re-encoded.
#include <map>

#include "vdyn/recorder/commands.h"
#include "vdyn/recorder/recording.h"

namespace vdyn::recorder {

int RunRecover(const RecoverOptions& o, std::ostream& out) {
  std::filesystem::path dest = o.out;
  if (dest.empty()) {
    dest = o.file;
    dest.replace_filename(o.file.stem().string() + "-recovered" + o.file.extension().string());
  }
  if (std::filesystem::exists(dest) && std::filesystem::equivalent(dest, o.file)) {
    out << "vdyn-recorder recover: the output must be another file than " << o.file.string() << "\n";
    return 2;
  }
  mcap::Reader reader(o.file);
  // What the damaged file used, so the copy looks the same (compression, library).
  mcap::WriterOptions wo;
  wo.library = reader.header_library().empty() ? "vdyn-recorder" : reader.header_library();
  wo.library += " (recovered)";
  std::map<std::string, int> compressions;
  for (const mcap::ChunkIndex& c : reader.Chunks()) ++compressions[c.compression];
  wo.compression = compressions.count("lz4") > compressions.count("zstd") ? mcap::Compression::kLz4
                                                                          : mcap::Compression::kZstd;
  mcap::Writer writer(dest, wo);
  std::map<std::uint16_t, std::uint16_t> schema_ids, channel_ids;
  std::map<std::uint16_t, mcap::Channel> pending_channels;
  std::uint64_t kept = 0;
  mcap::Visitor v;
  v.on_schema = [&](const mcap::Schema& s) {
    if (schema_ids.count(s.id) == 0) schema_ids[s.id] = writer.AddSchema(s.name, s.encoding, s.data);
  };
  v.on_channel = [&](const mcap::Channel& c) {
    if (channel_ids.count(c.id) != 0) return;
    const std::uint16_t schema = c.schema_id == 0 ? 0 : schema_ids.at(c.schema_id);
    channel_ids[c.id] = writer.AddChannel(schema, c.topic, c.message_encoding, c.metadata);
  };
  v.on_message = [&](const mcap::Message& m, std::uint64_t) {
    writer.WriteMessage(channel_ids.at(m.channel_id), m.sequence, m.log_time, m.publish_time, m.data);
    ++kept;
  };
  v.on_metadata = [&](const mcap::Metadata& m, std::uint64_t) { writer.WriteMetadata(m.name, m.values); };
  Progress progress("recover");
  v.on_progress = [&](std::uint64_t at) { progress.Update(static_cast<double>(at) / static_cast<double>(reader.size())); };
  const mcap::ScanResult r = reader.Scan(v, /*lenient=*/true);
  progress.Finish();
  writer.WriteMetadata("vdyn.recovered", {{"from", o.file.filename().string()},
                                          {"good_until", std::to_string(r.good_until)},
                                          {"file_size", std::to_string(reader.size())},
                                          {"problem", r.problem},
                                          {"problem_offset", std::to_string(r.problem_offset)},
                                          {"chunks_skipped", std::to_string(r.chunks_skipped)}});
  writer.Close();
  if (r.complete && r.chunks_skipped == 0) {
    out << o.file.string() << " was whole (" << kept << " messages); a fresh copy is in "
        << dest.string() << "\n";
    return 0;
  }
  out << o.file.string() << ": " << r.problem << " (offset " << r.problem_offset << ")\n";
  out << "recovered " << kept << " messages in " << r.chunks << " chunks";
  if (r.chunks_skipped > 0) out << "; " << r.chunks_skipped << " damaged chunks dropped";
  if (!r.complete) {
    out << "; lost the last " << (reader.size() - r.good_until) << " bytes (from offset "
        << r.good_until << ")";
  }
  out << "\nwritten, closed and indexed: " << dest.string() << "\n";
  return 0;
}

}  // namespace vdyn::recorder
