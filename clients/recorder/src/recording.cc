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
#include "vdyn/session.pb.h"
#include "vdyn/state.pb.h"
#include "vdyn/vehicle_params.pb.h"
#include "vdyn/world.pb.h"

namespace vdyn::recorder {

using transport::TopicId;

std::string FileDescriptorSetOf(const google::protobuf::Descriptor* d) {
  google::protobuf::FileDescriptorSet set;
  std::set<std::string> done;
  std::function<void(const google::protobuf::FileDescriptor*)> add =
      [&](const google::protobuf::FileDescriptor* f) {
        if (!done.insert(f->name()).second) return;
        for (int i = 0; i < f->dependency_count(); ++i) add(f->dependency(i));
        f->CopyTo(set.add_file());
      };
  add(d->file());
  return set.SerializeAsString();
}

const google::protobuf::Descriptor* PayloadDescriptor(TopicId topic) {
  switch (topic) {
    case TopicId::kState: return pb::VehicleState::descriptor();
    case TopicId::kInput: return pb::DriverInput::descriptor();
    case TopicId::kControl: return pb::ControlRequest::descriptor();
    case TopicId::kControlReply: return pb::ControlReply::descriptor();
    case TopicId::kParams: return pb::VehicleParams::descriptor();
    case TopicId::kWorld: return pb::WorldDescription::descriptor();
    case TopicId::kEvents: return pb::SessionEvent::descriptor();
    case TopicId::kDiagnostics: return pb::Diagnostics::descriptor();
  }
  return nullptr;
}

bool ServerKeyed(TopicId topic) {
  return topic == TopicId::kWorld || topic == TopicId::kDiagnostics;
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

std::optional<ChannelInfo> ParseChannelInfo(const mcap::Channel& c) {
  const auto topic = c.metadata.find("dds_topic");
  const auto key = c.metadata.find("key");
  if (topic == c.metadata.end() || key == c.metadata.end()) return std::nullopt;
  const transport::TopicSpec* spec = transport::SpecByName(topic->second);
  if (spec == nullptr) return std::nullopt;
  char* end = nullptr;
  const unsigned long long k = std::strtoull(key->second.c_str(), &end, 10);
  if (key->second.empty() || *end != '\0' || k > 0xffffffffull) return std::nullopt;
  return ChannelInfo{spec->id, static_cast<std::uint32_t>(k)};
}

mcap::ScanResult ScanRecording(const mcap::Reader& reader, const RecordingVisitor& v) {
  std::vector<std::optional<ChannelInfo>> channels(65536);
  mcap::Visitor mv;
  mv.on_channel = [&](const mcap::Channel& c) { channels[c.id] = ParseChannelInfo(c); };
  mv.on_message = [&](const mcap::Message& m, std::uint64_t) {
    const auto& info = channels[m.channel_id];
    if (!info || !v.on_message) return;
    if (v.wants && !v.wants(info->topic)) return;
    v.on_message({info->topic, info->key, m.log_time, m.publish_time, m.data});
  };
  mv.on_metadata = [&](const mcap::Metadata& m, std::uint64_t) {
    if (v.on_metadata) v.on_metadata(m);
  };
  if (v.on_progress) {
    const double size = static_cast<double>(reader.size());
    mv.on_progress = [&v, size](std::uint64_t at) { v.on_progress(static_cast<double>(at) / size); };
  }
  return reader.Scan(mv);
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
    std::snprintf(b, sizeof b, "%d min %.1f s", static_cast<int>(s / 60.0), s - 60.0 * std::floor(s / 60.0));
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

}  // namespace vdyn::recorder
