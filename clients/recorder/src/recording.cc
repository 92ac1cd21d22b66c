#include "vdyn/recorder/recording.h"

#include <cinttypes>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <set>

#include <google/protobuf/descriptor.pb.h>

#include "vdyn/control.pb.h"
#include "vdyn/diagnostics.pb.h"
#include "vdyn/input.pb.h"
#include "vdyn/recorder/commands.h"
#include "vdyn/session.pb.h"
#include "vdyn/state.pb.h"
#include "vdyn/vehicle_params.pb.h"
#include "vdyn/world.pb.h"

namespace vdyn::recorder {

using transport::TopicId;

const google::protobuf::Descriptor* PayloadDescriptor(TopicId topic) {
  switch (topic) {
    case TopicId::kState:
      return pb::VehicleState::descriptor();
    case TopicId::kInput:
      return pb::DriverInput::descriptor();
    case TopicId::kControl:
      return pb::ControlRequest::descriptor();
    case TopicId::kControlReply:
      return pb::ControlReply::descriptor();
    case TopicId::kParams:
      return pb::VehicleParams::descriptor();
    case TopicId::kWorld:
      return pb::WorldDescription::descriptor();
    case TopicId::kEvents:
      return pb::SessionEvent::descriptor();
    case TopicId::kDiagnostics:
      return pb::Diagnostics::descriptor();
    case TopicId::kStates:
      return pb::VehicleStates::descriptor();  // never recorded as such
  }
  return nullptr;
}

bool ServerKeyed(TopicId topic) {
  return topic == TopicId::kWorld || topic == TopicId::kDiagnostics || topic == TopicId::kStates;
}

namespace {
std::string KeyText(TopicId topic, std::uint32_t key) {
  if (!ServerKeyed(topic)) return std::to_string(key);
  char b[16];
  std::snprintf(b, sizeof b, "%08" PRIx32, key);
  return b;
}
}  // namespace

std::string ChannelTopic(TopicId topic, std::uint32_t key) {
  return std::string(transport::Spec(topic).name) + "/" + KeyText(topic, key);
}

mcap::StringMap ChannelMetadata(TopicId topic, std::uint32_t key) {
  mcap::StringMap m;
  m["dds_topic"] = transport::Spec(topic).name;
  m["key"] = std::to_string(key);
  m[ServerKeyed(topic) ? "server_key" : "vehicle_id"] = KeyText(topic, key);
  return m;
}

mcap::StringMap RepeatChannelMetadata(TopicId topic, std::uint32_t key) {
  mcap::StringMap m = ChannelMetadata(topic, key);
  m["repeat_of"] = ChannelTopic(topic, key);
  return m;
}

std::optional<ChannelInfo> ParseChannelInfo(const mcap::Channel& c, const mcap::Schema* schema) {
  const auto topic = c.metadata.find("dds_topic");
  const auto key = c.metadata.find("key");
  if (topic == c.metadata.end() || key == c.metadata.end()) return std::nullopt;
  const transport::TopicSpec* spec = transport::SpecByName(topic->second);
  if (spec == nullptr) return std::nullopt;
  char* end = nullptr;
  const unsigned long long k = std::strtoull(key->second.c_str(), &end, 10);
  if (key->second.empty() || *end != '\0' || k > 0xffffffffull) return std::nullopt;
  if (schema != nullptr) {
    // Our names on another type or encoding are not ours.
    const auto* d = PayloadDescriptor(spec->id);
    if (c.message_encoding != "protobuf" || schema->encoding != "protobuf" || d == nullptr ||
        schema->name != d->full_name()) {
      return std::nullopt;
    }
  }
  return ChannelInfo{spec->id, static_cast<std::uint32_t>(k), c.metadata.count("repeat_of") != 0};
}

std::map<std::uint16_t, ChannelInfo> VdynChannels(const mcap::Reader::Summary& s) {
  std::map<std::uint16_t, const mcap::Schema*> schemas;
  for (const mcap::Schema& sc : s.schemas) schemas[sc.id] = &sc;
  std::map<std::uint16_t, ChannelInfo> out;
  for (const mcap::Channel& c : s.channels) {
    const auto it = schemas.find(c.schema_id);
    if (it == schemas.end()) continue;
    if (const auto info = ParseChannelInfo(c, it->second)) out[c.id] = *info;
  }
  return out;
}

mcap::ScanResult ScanRecording(const mcap::Reader& reader, const RecordingVisitor& v) {
  std::vector<std::optional<ChannelInfo>> channels(65536);
  std::vector<std::optional<mcap::Channel>> foreign(v.on_foreign ? 65536 : 0);
  std::map<std::uint16_t, mcap::Schema> schemas;
  mcap::Visitor mv;
  mv.on_schema = [&](const mcap::Schema& s) { schemas[s.id] = s; };
  mv.on_channel = [&](const mcap::Channel& c) {
    const auto s = schemas.find(c.schema_id);
    channels[c.id] = s == schemas.end() ? std::nullopt : ParseChannelInfo(c, &s->second);
    if (v.on_foreign) {
      if (channels[c.id]) {
        foreign[c.id].reset();
      } else {
        foreign[c.id] = c;
      }
    }
  };
  mv.on_message = [&](const mcap::Message& m, std::uint64_t) {
    const auto& info = channels[m.channel_id];
    if (!info) {
      if (v.on_foreign && foreign[m.channel_id]) {
        const auto s = schemas.find(foreign[m.channel_id]->schema_id);
        v.on_foreign(*foreign[m.channel_id], s == schemas.end() ? nullptr : &s->second, m);
      }
      return;
    }
    if (!v.on_message) return;
    if (v.wants && !v.wants(info->topic)) return;
    v.on_message(
        {info->topic, info->key, m.log_time, m.publish_time, m.data, info->repeat, m.unchecked});
  };
  mv.on_metadata = [&](const mcap::Metadata& m, std::uint64_t) {
    if (v.on_metadata) v.on_metadata(m);
  };
  if (v.on_progress) {
    const double size = static_cast<double>(reader.size());
    mv.on_progress = [&v, size](std::uint64_t at) {
      v.on_progress(static_cast<double>(at) / size);
    };
  }
  return reader.Scan(mv);
}

std::optional<StateFields> ReadStateFields(std::span<const std::uint8_t> payload,
                                           std::uint32_t key) {
  StateFields f;
  std::uint64_t id = 0;
  const bool framed = wire::ForEachField(payload, [&](const wire::Field& w) {
    if (w.type == 0 && w.number == 1) id = w.value;
    if (w.type == 0 && w.number == 3) f.step = w.value;
    if (w.type == 0 && w.number == 5) f.step_ns = w.value;
    if (w.type == 1 && w.number == 21) f.state_hash = w.value;
    if (w.type == 1 && w.number == 27) f.incarnation = w.value;
    return true;
  });
  if (!framed || id != key) return std::nullopt;
  return f;
}

mcap::ScanResult CheckWholeFile(const mcap::Reader& reader, const std::string& label) {
  Progress progress(label);
  mcap::Visitor v;
  v.on_progress = [&](std::uint64_t at) {
    progress.Update(static_cast<double>(at) / static_cast<double>(reader.size()));
  };
  mcap::ScanResult r = reader.Scan(v);
  progress.Finish();
  return r;
}

std::vector<std::string> IntegrityNotes(const std::vector<mcap::Metadata>& meta,
                                        const mcap::ScanResult& scan, std::uint64_t unchecked,
                                        const std::string& what) {
  std::vector<std::string> out;
  for (const mcap::Metadata& m : meta) {
    if (m.name != "vdyn.recovered") continue;
    auto get = [&](const char* k) {
      const auto it = m.values.find(k);
      return it == m.values.end() ? std::string("0") : it->second;
    };
    const std::string lost = get("messages_lost"), left = get("bytes_left_out");
    const std::string no_crc = get("unchecked_messages");
    std::size_t parts = 0;
    for (const auto& [k, v] : m.values) parts += k.rfind("damage.", 0) == 0 ? 1 : 0;
    if (parts > 0 || lost != "0") {
      out.push_back("recovered from " + Printable(get("from")) +
                    ", which was damaged: " + Count(parts, "problem", "problems") + " found, " +
                    Count(std::strtoull(left.c_str(), nullptr, 10), "byte", "bytes") + " and " +
                    Count(std::strtoull(lost.c_str(), nullptr, 10), "message", "messages") +
                    " known lost (`vdyn-recorder info` lists them)");
    }
    if (no_crc != "0") {
      out.push_back(Count(std::strtoull(no_crc.c_str(), nullptr, 10), "message", "messages") +
                    " of " + Printable(get("from")) +
                    " had no CRC that held when it was recovered: they are unchecked");
    }
  }
  if (unchecked > 0 && scan.data_crc != mcap::ScanResult::DataCrc::kMatched) {
    out.push_back(std::to_string(unchecked) + " " + what +
                  " come from chunks without a CRC, and no data-section CRC covers them: "
                  "nothing checked their bytes");
  }
  return out;
}

std::vector<mcap::Metadata> ReadMetadata(const mcap::Reader& reader) {
  std::vector<mcap::Metadata> out;
  mcap::Visitor v;
  v.on_metadata = [&](const mcap::Metadata& m, std::uint64_t) { out.push_back(m); };
  v.on_chunk = [](const mcap::ChunkIndex&) { return false; };  // metadata live outside chunks
  reader.Scan(v);
  return out;
}

std::uint64_t FirstLogTime(const mcap::Reader& reader) {
  if (auto s = reader.ReadSummary(); s && s->statistics) return s->statistics->message_start_time;
  std::uint64_t first = 0;
  for (const mcap::ChunkIndex& c : reader.Chunks()) {
    if (first == 0 || c.message_start_time < first) first = c.message_start_time;
  }
  return first;
}

std::string FormatDuration(double s) {
  char b[64];
  if (s < 60.0) {
    std::snprintf(b, sizeof b, "%.3f s", s);
  } else if (s < 3600.0) {
    std::snprintf(b, sizeof b, "%d min %.1f s", static_cast<int>(s / 60.0),
                  s - 60.0 * std::floor(s / 60.0));
  } else {
    std::snprintf(b, sizeof b, "%d h %d min", static_cast<int>(s / 3600.0),
                  static_cast<int>((s - 3600.0 * std::floor(s / 3600.0)) / 60.0));
  }
  return b;
}

std::string FormatBytes(double bytes) {
  char b[32];
  if (bytes < 1e3) {
    std::snprintf(b, sizeof b, "%.0f B", bytes);
  } else if (bytes < 1e6) {
    std::snprintf(b, sizeof b, "%.1f kB", bytes / 1e3);
  } else if (bytes < 1e9) {
    std::snprintf(b, sizeof b, "%.1f MB", bytes / 1e6);
  } else {
    std::snprintf(b, sizeof b, "%.2f GB", bytes / 1e9);
  }
  return b;
}

std::string FormatUtc(std::uint64_t ns) {
  const std::time_t secs = static_cast<std::time_t>(ns / 1'000'000'000ull);
  std::tm tm{};
  gmtime_r(&secs, &tm);
  char b[64];
  std::snprintf(b, sizeof b, "%04d-%02d-%02d %02d:%02d:%02d.%03d UTC", tm.tm_year + 1900,
                tm.tm_mon + 1, tm.tm_mday, tm.tm_hour, tm.tm_min, tm.tm_sec,
                static_cast<int>((ns / 1'000'000ull) % 1000));
  return b;
}

std::string Count(std::uint64_t n, std::string_view one, std::string_view many) {
  return std::to_string(n) + " " + std::string(n == 1 ? one : many);
}

std::string Ordinal(std::uint64_t n) {
  const char* suffix = "th";
  if (n % 100 < 11 || n % 100 > 13) {
    suffix = n % 10 == 1 ? "st" : n % 10 == 2 ? "nd" : n % 10 == 3 ? "rd" : "th";
  }
  return std::to_string(n) + suffix;
}

std::string Printable(std::string_view text, std::size_t max) {
  std::string out;
  const std::size_t n = text.size();
  auto escape = [&](unsigned char c) {
    char b[8];
    std::snprintf(b, sizeof b, "\\x%02x", c);
    out += b;
  };
  std::size_t i = 0;
  for (; i < n && out.size() < max; ++i) {
    const auto c = static_cast<unsigned char>(text[i]);
    if (c < 0x20 || c == 0x7f) {
      escape(c);
      continue;
    }
    if (c < 0x80) {
      out += static_cast<char>(c);
      continue;
    }
    // A whole UTF-8 sequence (no overlong two-byte form, no C1 control characters U+0080..9F).
    const std::size_t len = c >= 0xc2 && c <= 0xdf   ? 2
                            : c >= 0xe0 && c <= 0xef ? 3
                            : c >= 0xf0 && c <= 0xf4 ? 4
                                                     : 0;
    bool whole = len > 0 && i + len <= n;
    for (std::size_t k = 1; whole && k < len; ++k) {
      whole = (static_cast<unsigned char>(text[i + k]) & 0xc0) == 0x80;
    }
    if (whole && c == 0xc2 && static_cast<unsigned char>(text[i + 1]) < 0xa0) whole = false;
    if (!whole) {
      escape(c);
      continue;
    }
    out.append(text.substr(i, len));
    i += len - 1;
  }
  if (i < n) out += "... (" + std::to_string(n) + " bytes)";
  return out;
}

}  // namespace vdyn::recorder
