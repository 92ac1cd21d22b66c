#include "vdyn/recorder/export_foxglove.h"

#include <map>
#include <set>

#include "foxglove/FrameTransforms.pb.h"
#include "foxglove/SceneUpdate.pb.h"
#include "vdyn/foxglove/scene.h"
#include "vdyn/recorder/commands.h"
#include "vdyn/recorder/mcap.h"
#include "vdyn/recorder/recording.h"
#include "vdyn/state.pb.h"
#include "vdyn/vehicle_params.pb.h"
#include "vdyn/world.pb.h"

namespace vdyn::recorder {
namespace {

namespace fg = ::foxglove;
using transport::TopicId;

// The scene channels of the copy, made as their first message is written.
class SceneChannels {
 public:
  explicit SceneChannels(mcap::Writer& w) : w_(w) {}
  std::uint16_t Get(const std::string& topic, const google::protobuf::Descriptor* d) {
    const auto it = channels_.find(topic);
    if (it != channels_.end()) return it->second;
    auto s = schemas_.find(d->full_name());
    if (s == schemas_.end()) {
      s = schemas_
              .emplace(d->full_name(),
                       w_.AddSchema(d->full_name(), "protobuf", FileDescriptorSetOf(d)))
              .first;
    }
    return channels_[topic] =
               w_.AddChannel(s->second, topic, "protobuf", {{"vdyn", "foxglove scene"}});
  }

 private:
  mcap::Writer& w_;
  std::map<std::string, std::uint16_t> schemas_;
  std::map<std::string, std::uint16_t> channels_;
};

}  // namespace

int RunExportFoxglove(const FoxgloveExportOptions& o, std::ostream& out) {
  mcap::Reader reader(o.file);
  mcap::WriterOptions wo;
  wo.inputs = {o.file};
  mcap::Writer w(o.out, wo);
  SceneChannels scene_channels(w);
  foxglove::SceneOptions so;
  so.arrow_m_per_kn = o.arrow_m_per_kn;
  const auto period = static_cast<std::uint64_t>(1e9 / o.scene_hz);

  std::map<std::uint16_t, std::uint16_t> schema_ids, channel_ids;  // the recording's -> the copy's
  std::map<std::uint16_t, mcap::Schema> schemas;
  std::map<std::uint16_t, ChannelInfo> vdyn_channels;
  std::map<std::string, pb::WorldDescription> worlds;  // by server id
  std::map<std::uint32_t, pb::VehicleParams> params;
  std::map<std::uint32_t, std::uint64_t> last_scene;  // vehicle -> log time of its last scene
  std::set<std::uint64_t> terrains;                   // terrain hashes written
  std::uint64_t copied = 0, scenes = 0, malformed = 0, undrawable = 0, orphans = 0, replaced = 0;
  std::set<std::uint16_t> earlier_scene;  // channels of a scene an earlier export added
  pb::VehicleState state;
  fg::SceneUpdate scene;
  fg::FrameTransforms transforms;
  std::string bytes;
  auto write = [&](std::uint16_t channel, std::uint64_t log_time,
                   const google::protobuf::Message& m) {
    bytes.clear();
    (void)m.SerializeToString(&bytes);
    w.WriteMessage(channel, 0, log_time, log_time,
                   {reinterpret_cast<const std::uint8_t*>(bytes.data()), bytes.size()});
  };

  Progress progress("export");
  mcap::Visitor v;
  v.on_progress = [&](std::uint64_t at) {
    progress.Update(static_cast<double>(at) / static_cast<double>(reader.size()));
  };
  v.on_schema = [&](const mcap::Schema& s) {
    schemas[s.id] = s;
    schema_ids[s.id] = w.AddSchema(s.name, s.encoding, s.data);
  };
  v.on_channel = [&](const mcap::Channel& c) {
    // A scene an earlier export added (a copy of a copy): replaced by this one, not doubled.
    if (const auto tag = c.metadata.find("vdyn");
        tag != c.metadata.end() && tag->second == "foxglove scene") {
      earlier_scene.insert(c.id);
      return;
    }
    const auto s = schemas.find(c.schema_id);
    channel_ids[c.id] = w.AddChannel(c.schema_id == 0 ? 0 : schema_ids[c.schema_id], c.topic,
                                     c.message_encoding, c.metadata);
    if (auto info = ParseChannelInfo(c, s == schemas.end() ? nullptr : &s->second)) {
      vdyn_channels[c.id] = *info;
    }
  };
  v.on_metadata = [&](const mcap::Metadata& m, std::uint64_t) {
    w.WriteMetadata(m.name, m.values);
  };
  v.on_message = [&](const mcap::Message& m, std::uint64_t) {
    if (earlier_scene.count(m.channel_id) != 0) {
      ++replaced;
      return;
    }
    const auto id = channel_ids.find(m.channel_id);
    if (id == channel_ids.end()) {
      ++orphans;
      return;
    }
    w.WriteMessage(id->second, m.sequence, m.log_time, m.publish_time, m.data);
    ++copied;
    const auto info = vdyn_channels.find(m.channel_id);
    if (info == vdyn_channels.end() || info->second.repeat) return;
    const int size = static_cast<int>(m.data.size());
    switch (info->second.topic) {
      case TopicId::kWorld: {
        pb::WorldDescription world;
        if (!world.ParseFromArray(m.data.data(), size)) return void(++malformed);
        if (terrains.insert(world.terrain_hash()).second) {
          foxglove::BuildWorldScene(world, static_cast<std::int64_t>(m.log_time), scene);
          write(scene_channels.Get("/vdyn/world", fg::SceneUpdate::descriptor()), m.log_time,
                scene);
        }
        worlds[world.server_id()] = std::move(world);
        return;
      }
      case TopicId::kParams:
        if (!params[info->second.key].ParseFromArray(m.data.data(), size)) ++malformed;
        return;
      case TopicId::kState: {
        const std::uint32_t vehicle = info->second.key;
        // One scene per 1/scene_hz of log time: the first state of each slot.
        const auto last = last_scene.find(vehicle);
        if (last != last_scene.end() && m.log_time / period == last->second / period) return;
        if (!state.ParseFromArray(m.data.data(), size)) return void(++malformed);
        if (state.vehicle_id() != vehicle || !foxglove::CheckState(state).empty())
          return void(++undrawable);
        last_scene[vehicle] = m.log_time;
        const auto world = worlds.find(state.server_id());
        const auto p = params.find(vehicle);
        const foxglove::Geometry g =
            foxglove::GeometryFor(vehicle, world == worlds.end() ? nullptr : &world->second,
                                  p == params.end() ? nullptr : &p->second);
        const std::string prefix = "/vehicle/" + std::to_string(vehicle);
        const auto stamp = static_cast<std::int64_t>(m.log_time);
        foxglove::BuildTransforms(state, g, stamp, transforms);
        write(scene_channels.Get(prefix + "/tf", fg::FrameTransforms::descriptor()), m.log_time,
              transforms);
        foxglove::BuildVehicleScene(state, g, so, stamp, scene);
        write(scene_channels.Get(prefix + "/scene", fg::SceneUpdate::descriptor()), m.log_time,
              scene);
        ++scenes;
        return;
      }
      default:
        return;
    }
  };
  const mcap::ScanResult scan = reader.Scan(v);
  progress.Finish();
  w.Close();
  out << "copied " << copied << " messages of " << o.file.string() << " and added " << scenes
      << " scenes with their transforms (" << last_scene.size() << " vehicles, " << o.scene_hz
      << " Hz) and " << terrains.size() << " terrain" << (terrains.size() == 1 ? "" : "s") << " -> "
      << o.out.string() << "\n";
  if (scan.messages_unchecked > 0) {
    out << "vdyn-recorder export: " << scan.messages_unchecked
        << " messages came from chunks no CRC checked; they are copied as they are\n";
  }
  if (orphans > 0)
    out << "vdyn-recorder export: " << orphans << " messages on undefined channels were left out\n";
  if (!earlier_scene.empty()) {
    out << "vdyn-recorder export: the file had a Foxglove scene of an earlier export (" << replaced
        << " messages on " << earlier_scene.size() << " channels): replaced by this one\n";
  }
  if (undrawable > 0)
    out << "vdyn-recorder export: " << undrawable
        << " states could not be drawn (no scene for them)\n";
  if (malformed > 0) {
    out << "vdyn-recorder export: " << malformed
        << " messages did not parse (copied, no scene from them)\n";
    return 1;
  }
  return 0;
}

}  // namespace vdyn::recorder
