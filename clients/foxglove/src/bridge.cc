#include "vdyn/foxglove/bridge.h"
#include "vdyn/foxglove/clock.h"

#include <google/protobuf/util/json_util.h>

#include <algorithm>
#include <cmath>
#include <condition_variable>
#include <deque>
#include <limits>
#include <map>
#include <mutex>
#include <set>
#include <thread>

#include "foxglove/FrameTransforms.pb.h"
#include "foxglove/SceneUpdate.pb.h"
#include "vdyn/base/limits.h"
#include "vdyn/client/driver_input.h"
#include "vdyn/client/state_reader.h"
#include "vdyn/diagnostics.pb.h"
#include "vdyn/foxglove/params.h"
#include "vdyn/foxglove/protocol.h"
#include "vdyn/messages/descriptor_set.h"
#include "vdyn/messages/input_checks.h"
#include "vdyn/session.pb.h"
#include "vdyn/transport/control_client.h"

namespace vdyn::foxglove {
namespace {

namespace fg = ::foxglove;
using protocol::StatusLevel;
using protocol::WsOpcode;

// The input channels one client may advertise at once (one DDS writer each).
constexpr std::size_t kMaxClientChannels = 16;

enum class Kind { kState, kTransforms, kScene, kWorld, kDiagnostics, kEvents };

struct Subscriber {
  ClientId client = 0;
  std::uint32_t subscription = 0;
  std::shared_ptr<Outbox> outbox;
};

struct ChannelState {
  protocol::Channel channel;
  Kind kind = Kind::kState;
  std::uint32_t vehicle = 0;
  bool advertised = false;
  std::vector<Subscriber> subscribers;
};

struct ClientPublish {
  std::uint32_t vehicle = 0;
  bool json = true;
  std::unique_ptr<client::InputPublisher> publisher;
};

struct ClientState {
  std::shared_ptr<Outbox> outbox;
  std::string name;                                      // "client 3 (127.0.0.1, foxglove.sdk.v1)"
  std::map<std::uint32_t, std::uint32_t> subscriptions;  // subscription id -> channel id
  bool all_params = false;
  std::set<std::string> param_names;                 // parameter updates subscribed to
  std::map<std::uint32_t, ClientPublish> publishes;  // the client's channel id -> its input
  base::MonoTime last_input_error{};
};

// A vehicle as the source thread keeps it.
struct SourceVehicle {
  std::uint32_t state_channel = 0, tf_channel = 0, scene_channel = 0;
  std::shared_ptr<const std::string> latest;  // the newest state, serialised (scene wanted)
  bool fresh = false;                         // newer than the last scene built
  std::int64_t last_forwarded_ns = std::numeric_limits<std::int64_t>::min();
  base::MonoTime last_seen;
  std::string server_id;
};

struct SetRequest {
  ClientId client = 0;
  std::uint32_t vehicle = 0;
  pb::VehicleParams change;
  std::vector<protocol::Parameter> asked;
  std::optional<std::string> id;
};

std::string Schema(const google::protobuf::Descriptor* d) {
  return messages::FileDescriptorSetOf(d);
}

}  // namespace

struct Bridge::Impl {
  transport::Participant& participant;
  BridgeConfig cfg;
  std::string session_id;
  std::function<void(ClientId, const std::string&)> close;
  std::function<void(const std::string&)> log = [](const std::string&) {};
  std::string schema_state = Schema(pb::VehicleState::descriptor());
  std::string schema_tf = Schema(fg::FrameTransforms::descriptor());
  std::string schema_scene = Schema(fg::SceneUpdate::descriptor());
  std::uint32_t world_channel = 0, diagnostics_channel = 0, events_channel = 0;

  // Shared by the source thread, the server's thread and the requests thread.
  mutable std::mutex mu;
  std::map<std::uint32_t, ChannelState> channels;
  std::map<std::string, std::uint32_t> channel_ids;  // by topic: a returning vehicle keeps its ids
  std::uint32_t next_channel = 1;
  std::map<ClientId, ClientState> clients;
  std::map<std::string, std::shared_ptr<const std::string>> world_scenes;  // by server id
  std::map<std::uint32_t, pb::VehicleParams> params;  // written by the source thread only
  std::map<std::uint32_t, std::string> vehicle_servers;
  BridgeClock clock{cfg.vehicle_timeout};  // the time source of `time` and every log time
  Bridge::Counters counters;
  std::uint64_t closed_dropped_messages = 0, closed_dropped_bytes = 0;  // of clients gone
  std::atomic<std::uint64_t> dds_lost{0};

  // The source thread's.
  transport::DropCounters drops;
  transport::Waitset waitset{participant, &drops};
  client::StateReader states{participant, drops, std::nullopt,
                             client::StateReader::History::kEvery};
  transport::Reader<pb::VehicleParams> params_reader{participant, transport::TopicId::kParams,
                                                     &drops};
  transport::Reader<pb::WorldDescription> world_reader{participant, transport::TopicId::kWorld,
                                                       &drops};
  transport::Reader<pb::Diagnostics> diagnostics_reader{participant,
                                                        transport::TopicId::kDiagnostics, &drops};
  transport::Reader<pb::SessionEvent> events_reader{participant, transport::TopicId::kEvents,
                                                    &drops};
  std::map<std::uint32_t, SourceVehicle> vehicles;
  std::map<std::string, pb::WorldDescription> worlds;
  pb::VehicleState scratch;
  fg::SceneUpdate scene;
  fg::FrameTransforms transforms;

  // The requests thread's.
  transport::ControlClient control{participant, "vdyn-foxglove"};
  std::mutex request_mu;
  std::condition_variable request_cv;
  std::deque<SetRequest> requests;
  bool requests_stop = false;
  std::thread request_thread;

  Impl(transport::Participant& p, BridgeConfig c) : participant(p), cfg(std::move(c)) {}

  // --- channels (mu held)
  // -------------------------------------------------------------------------
  std::uint32_t ChannelFor(const std::string& topic, Kind kind, std::uint32_t vehicle,
                           const std::string& schema_name, const std::string& schema) {
    auto [it, fresh] = channel_ids.emplace(topic, next_channel);
    if (fresh) {
      ChannelState& c = channels[next_channel];
      c.channel = {next_channel, topic, "protobuf", schema_name, "protobuf", schema};
      c.kind = kind;
      c.vehicle = vehicle;
      ++next_channel;
    }
    return it->second;
  }

  void PushControl(ClientId id, ClientState& c, std::string_view json) {
    if (!c.outbox->PushControl(WsOpcode::kText, json) && close) {
      close(id, "vdyn-foxglove: this client has fallen too far behind (control queue full)");
    }
  }

  void Status(ClientId id, ClientState& c, StatusLevel level, const std::string& text) {
    PushControl(id, c, protocol::StatusJson(level, text));
  }

  void Advertise(const std::vector<std::uint32_t>& ids) {
    std::vector<const protocol::Channel*> list;
    for (std::uint32_t id : ids) {
      channels[id].advertised = true;
      list.push_back(&channels[id].channel);
    }
    const std::string json = protocol::AdvertiseJson(list);
    for (auto& [cid, c] : clients) PushControl(cid, c, json);
  }

  void Unadvertise(const std::vector<std::uint32_t>& ids) {
    for (std::uint32_t id : ids) {
      ChannelState& ch = channels[id];
      std::map<ClientId, std::vector<std::uint32_t>> gone;
      for (const Subscriber& s : ch.subscribers) gone[s.client].push_back(s.subscription);
      for (auto& [cid, subs] : gone) {
        const auto c = clients.find(cid);
        if (c == clients.end()) continue;
        for (std::uint32_t sub : subs) c->second.subscriptions.erase(sub);
        c->second.outbox->Purge(subs);
      }
      ch.subscribers.clear();
      ch.advertised = false;
    }
    const std::string json = protocol::UnadvertiseJson(ids);
    for (auto& [cid, c] : clients) PushControl(cid, c, json);
  }

  void Deliver(std::uint32_t channel, std::uint64_t log_time,
               const std::shared_ptr<const std::string>& payload, base::MonoTime now,
               std::int64_t source_ns, bool latest_only) {
    for (const Subscriber& s : channels[channel].subscribers) {
      s.outbox->PushData(s.subscription, log_time, payload, now, source_ns, latest_only);
      ++counters.messages_out;
    }
  }

  bool Subscribed(std::uint32_t channel) { return !channels[channel].subscribers.empty(); }

  // --- the source thread
  // --------------------------------------------------------------------------
  SourceVehicle& VehicleFor(const pb::VehicleState& s) {
    const std::uint32_t id = s.vehicle_id();
    auto it = vehicles.find(id);
    if (it != vehicles.end()) return it->second;
    SourceVehicle& v = vehicles[id];
    const std::string prefix = "/vehicle/" + std::to_string(id);
    {
      std::lock_guard lock(mu);
      v.state_channel = ChannelFor(prefix + "/state", Kind::kState, id,
                                   pb::VehicleState::descriptor()->full_name(), schema_state);
      v.tf_channel = ChannelFor(prefix + "/tf", Kind::kTransforms, id,
                                fg::FrameTransforms::descriptor()->full_name(), schema_tf);
      v.scene_channel = ChannelFor(prefix + "/scene", Kind::kScene, id,
                                   fg::SceneUpdate::descriptor()->full_name(), schema_scene);
      vehicle_servers[id] = s.server_id();
      Advertise({v.state_channel, v.tf_channel, v.scene_channel});
      ++counters.vehicles;
    }
    v.server_id = s.server_id();
    log("vehicle " + std::to_string(id) + " of server '" + s.server_id() + "': advertised " +
        prefix + "/state, /tf, /scene");
    return v;
  }

  void RemoveVehicle(std::uint32_t id, const std::string& why) {
    const auto it = vehicles.find(id);
    if (it == vehicles.end()) return;
    {
      std::lock_guard lock(mu);
      Unadvertise({it->second.state_channel, it->second.tf_channel, it->second.scene_channel});
      vehicle_servers.erase(id);
      --counters.vehicles;
    }
    vehicles.erase(it);
    log("vehicle " + std::to_string(id) + " " + why + ": its channels are unadvertised");
  }

  void TakeStates(base::MonoTime now) {
    const std::int64_t period =
        cfg.state_hz > 0 ? static_cast<std::int64_t>(1e9 / cfg.state_hz) : 0;
    (void)states.Take([&](const pb::VehicleState& s, const transport::SampleInfo& info) {
      if (std::string why = CheckState(s); !why.empty()) {
        std::lock_guard lock(mu);
        ++counters.states_in;
        ++counters.states_refused;
        counters.last_refusal = why;
        return;
      }
      SourceVehicle& v = VehicleFor(s);
      v.last_seen = now;
      std::lock_guard lock(mu);
      ++counters.states_in;
      bool clock_changed = false;
      const std::uint64_t stamp =
          clock.OnState(s.server_id(), s.incarnation(), s.sim_time_ns(), now, &clock_changed);
      if (clock_changed) {
        log("clock: the simulation time of server '" + s.server_id() +
            "' (its first state, or a new start of it); other servers' messages get its time");
      }
      // A reset vehicle's clock does not go back: forward again from its new time.
      if (s.sim_time_ns() < v.last_forwarded_ns)
        v.last_forwarded_ns = std::numeric_limits<std::int64_t>::min();
      const bool want_state =
          Subscribed(v.state_channel) &&
          (period == 0 || v.last_forwarded_ns == std::numeric_limits<std::int64_t>::min() ||
           s.sim_time_ns() - v.last_forwarded_ns >= period - s.step_ns() / 2);
      const bool want_scene = Subscribed(v.tf_channel) || Subscribed(v.scene_channel);
      if (!want_state && !want_scene) return;
      auto payload = std::make_shared<std::string>();
      (void)s.SerializeToString(payload.get());
      if (want_state) {
        Deliver(v.state_channel, stamp, payload, now, info.source_timestamp_ns, false);
        v.last_forwarded_ns = s.sim_time_ns();
      }
      if (want_scene) {
        v.latest = std::move(payload);
        v.fresh = true;
      }
    });
  }

  void SceneTick(base::MonoTime now);
  void TakeOthers(base::MonoTime now);
  void SendParameterUpdates(std::uint32_t vehicle);
  void RequestLoop();
  void HandleSubscribe(ClientId id, ClientState& c, const protocol::Subscribe& m);
  void HandleUnsubscribe(ClientId id, ClientState& c, const protocol::Unsubscribe& m);
  void HandleAdvertise(ClientId id, ClientState& c, const protocol::ClientAdvertise& m);
  void HandleGetParameters(ClientId id, ClientState& c, const protocol::GetParameters& m);
  void HandleSetParameters(ClientId id, ClientState& c, const protocol::SetParameters& m);
  std::vector<protocol::Parameter> CurrentValues(const std::vector<std::string>& names);
};

void Bridge::Impl::SceneTick(base::MonoTime now) {
  for (auto it = vehicles.begin(); it != vehicles.end();) {
    const std::uint32_t id = it->first;
    SourceVehicle& v = it->second;
    ++it;
    if (now - v.last_seen > cfg.vehicle_timeout) {
      RemoveVehicle(id, "sent no state for " +
                            std::to_string(cfg.vehicle_timeout.seconds()).substr(0, 4) + " s");
      continue;
    }
    if (!v.fresh || !v.latest) continue;
    v.fresh = false;
    if (!scratch.ParseFromString(*v.latest)) continue;
    const auto world = worlds.find(v.server_id);
    const auto p = params.find(id);
    const Geometry g = GeometryFor(id, world == worlds.end() ? nullptr : &world->second,
                                   p == params.end() ? nullptr : &p->second);
    std::lock_guard lock(mu);
    // The message's own timestamps are its log time: the clock's (another server's vehicle gets
    // the clock's time, so that a panel looking up transforms at the clock's time finds them).
    const std::uint64_t log_time = clock.StampOf(scratch.server_id(), scratch.sim_time_ns());
    const auto stamp = static_cast<std::int64_t>(log_time);
    if (Subscribed(v.tf_channel)) {
      BuildTransforms(scratch, g, stamp, transforms);
      Deliver(v.tf_channel, log_time, std::make_shared<std::string>(transforms.SerializeAsString()),
              now, 0, true);
    }
    if (Subscribed(v.scene_channel)) {
      BuildVehicleScene(scratch, g, cfg.scene, stamp, scene);
      Deliver(v.scene_channel, log_time, std::make_shared<std::string>(scene.SerializeAsString()),
              now, 0, true);
    }
  }
  std::lock_guard lock(mu);
  if (!clock.set()) return;
  for (auto& [cid, c] : clients) c.outbox->PushTime(clock.now_ns());
}

void Bridge::Impl::TakeOthers(base::MonoTime now) {
  (void)world_reader.Take([&](const pb::WorldDescription& w, const transport::SampleInfo&) {
    worlds[w.server_id()] = w;
    BuildWorldScene(w, 0, scene);
    auto payload = std::make_shared<const std::string>(scene.SerializeAsString());
    std::lock_guard lock(mu);
    world_scenes[w.server_id()] = payload;
    for (const Subscriber& s : channels[world_channel].subscribers) {
      if (!s.outbox->PushControlData(s.subscription, clock.now_ns(), payload) && close) {
        close(s.client,
              "vdyn-foxglove: this client has fallen too far behind (control queue full)");
      }
    }
    log("world '" + w.name() + "' of server '" + w.server_id() +
        "': " + std::to_string(w.meshes_size()) + " meshes, " +
        std::to_string(payload->size() / 1024) + " KiB as a SceneUpdate on /vdyn/world");
  });
  std::set<std::uint32_t> changed;
  (void)params_reader.Take([&](const pb::VehicleParams& p, const transport::SampleInfo& info) {
    std::lock_guard lock(mu);
    params[info.key] = p;
    changed.insert(info.key);
  });
  for (std::uint32_t v : changed) SendParameterUpdates(v);
  (void)diagnostics_reader.Take([&](const pb::Diagnostics& d, const transport::SampleInfo&) {
    std::lock_guard lock(mu);
    if (!Subscribed(diagnostics_channel)) return;
    Deliver(diagnostics_channel, clock.StampOf(d.server_id(), d.sim_time_ns()),
            std::make_shared<const std::string>(d.SerializeAsString()), now, 0, false);
  });
  std::vector<std::uint32_t> removed;
  (void)events_reader.Take([&](const pb::SessionEvent& e, const transport::SampleInfo&) {
    if (e.has_removed()) removed.push_back(e.vehicle_id());
    std::lock_guard lock(mu);
    if (!Subscribed(events_channel)) return;
    Deliver(events_channel, clock.now_ns(),
            std::make_shared<const std::string>(e.SerializeAsString()), now, 0, false);
  });
  for (std::uint32_t v : removed) RemoveVehicle(v, "was removed by its server");
}

void Bridge::Impl::SendParameterUpdates(std::uint32_t vehicle) {
  std::lock_guard lock(mu);
  const auto p = params.find(vehicle);
  if (p == params.end()) return;
  const std::vector<protocol::Parameter> all = ParametersOf(vehicle, p->second);
  for (auto& [cid, c] : clients) {
    if (!c.all_params && c.param_names.empty()) continue;
    std::vector<protocol::Parameter> some;
    for (const protocol::Parameter& q : all) {
      if (c.all_params || c.param_names.count(q.name)) some.push_back(q);
    }
    if (!some.empty()) PushControl(cid, c, protocol::ParameterValuesJson(some, std::nullopt));
  }
}

std::vector<protocol::Parameter> Bridge::Impl::CurrentValues(
    const std::vector<std::string>& names) {
  std::vector<protocol::Parameter> out;
  if (names.empty()) {
    for (const auto& [v, p] : params) {
      for (protocol::Parameter& q : ParametersOf(v, p)) out.push_back(std::move(q));
    }
    return out;
  }
  for (const std::string& name : names) {
    protocol::Parameter q{name, std::nullopt};
    if (const auto n = ParseParameterName(name)) {
      const auto p = params.find(n->vehicle_id);
      if (p != params.end()) {
        for (protocol::Parameter& have : ParametersOf(n->vehicle_id, p->second)) {
          if (have.name == name) q.value = have.value;
        }
      }
    }
    out.push_back(std::move(q));
  }
  return out;
}

// --- the server's thread ------------------------------------------------------------------------

void Bridge::Impl::HandleSubscribe(ClientId id, ClientState& c, const protocol::Subscribe& m) {
  for (const auto& [sub, channel] : m.subscriptions) {
    const auto ch = channels.find(channel);
    if (c.subscriptions.count(sub)) {
      Status(id, c, StatusLevel::kError,
             "subscribe: subscription id " + std::to_string(sub) + " is in use already");
      continue;
    }
    if (ch == channels.end() || !ch->second.advertised) {
      Status(id, c, StatusLevel::kError,
             "subscribe: no channel " + std::to_string(channel) + " is advertised");
      continue;
    }
    c.subscriptions[sub] = channel;
    ch->second.subscribers.push_back({id, sub, c.outbox});
    if (ch->second.kind == Kind::kWorld) {
      // The protocol has no latching: every new subscriber gets the terrain once.
      for (const auto& [server, payload] : world_scenes) {
        if (!c.outbox->PushControlData(sub, clock.now_ns(), payload) && close) {
          close(id, "vdyn-foxglove: this client has fallen too far behind (control queue full)");
        }
      }
    }
  }
}

void Bridge::Impl::HandleUnsubscribe(ClientId id, ClientState& c, const protocol::Unsubscribe& m) {
  std::vector<std::uint32_t> gone;
  for (std::uint32_t sub : m.subscription_ids) {
    const auto it = c.subscriptions.find(sub);
    if (it == c.subscriptions.end()) {
      Status(id, c, StatusLevel::kWarning, "unsubscribe: no subscription " + std::to_string(sub));
      continue;
    }
    auto& subs = channels[it->second].subscribers;
    subs.erase(std::remove_if(
                   subs.begin(), subs.end(),
                   [&](const Subscriber& s) { return s.client == id && s.subscription == sub; }),
               subs.end());
    c.subscriptions.erase(it);
    gone.push_back(sub);
  }
  if (!gone.empty()) c.outbox->Purge(gone);
}

void Bridge::Impl::HandleAdvertise(ClientId id, ClientState& c,
                                   const protocol::ClientAdvertise& m) {
  if (!cfg.allow_input) {
    ++counters.input_refused;
    Status(id, c, StatusLevel::kError,
           "client publish is off: this vdyn-foxglove was started without --allow-input, so no "
           "client drives a vehicle through it");
    return;
  }
  for (const protocol::ClientChannel& ch : m.channels) {
    static constexpr std::string_view kPrefix = "/vehicle/", kSuffix = "/input";
    const std::string& t = ch.topic;
    std::uint32_t vehicle = 0;
    bool ok = t.size() > kPrefix.size() + kSuffix.size() &&
              t.compare(0, kPrefix.size(), kPrefix) == 0 &&
              t.compare(t.size() - kSuffix.size(), kSuffix.size(), kSuffix) == 0;
    if (ok) {
      const std::string digits =
          t.substr(kPrefix.size(), t.size() - kPrefix.size() - kSuffix.size());
      ok = !digits.empty() && digits.size() <= 9 &&
           digits.find_first_not_of("0123456789") == std::string::npos;
      if (ok) vehicle = static_cast<std::uint32_t>(std::stoul(digits));
    }
    // Each refusal is said to the client and counted (bad client messages).
    auto refuse = [&](const std::string& why) {
      ++counters.bad_messages;
      Status(id, c, StatusLevel::kError, "advertise: " + why);
    };
    if (!ok) {
      refuse("topic '" + t + "': driver input goes to /vehicle/<id>/input");
      continue;
    }
    if (const std::string why = limits::Check(limits::kVehicleId, vehicle); !why.empty()) {
      refuse(t + ": " + why);  // vehicle 0 was taken, and drove nothing
      continue;
    }
    if (ch.encoding != "json" && ch.encoding != "protobuf") {
      refuse(t + ": encoding '" + ch.encoding + "', expected json or protobuf");
      continue;
    }
    if (!ch.schema_name.empty() && ch.schema_name != "vdyn.pb.DriverInput") {
      refuse(t + ": schema '" + ch.schema_name + "', expected vdyn.pb.DriverInput");
      continue;
    }
    // One writer on vdyn/input per channel: a bounded number a client (2000 in one message made
    // 2000 DDS writers).
    if (c.publishes.size() >= kMaxClientChannels && c.publishes.count(ch.id) == 0) {
      refuse(t + ": this client advertises " + std::to_string(c.publishes.size()) +
             " channels already, the most one may (" + std::to_string(kMaxClientChannels) + ")");
      continue;
    }
    ClientPublish p;
    p.vehicle = vehicle;
    p.json = ch.encoding == "json";
    p.publisher = std::make_unique<client::InputPublisher>(
        participant, vehicle, "foxglove-" + std::to_string(id), cfg.input_strength);
    c.publishes[ch.id] = std::move(p);
    log(c.name + " drives vehicle " + std::to_string(vehicle) + " (source 'foxglove-" +
        std::to_string(id) + "', strength " + std::to_string(cfg.input_strength) + ")");
  }
}

void Bridge::Impl::HandleGetParameters(ClientId id, ClientState& c,
                                       const protocol::GetParameters& m) {
  PushControl(id, c, protocol::ParameterValuesJson(CurrentValues(m.names), m.id));
}

void Bridge::Impl::HandleSetParameters(ClientId id, ClientState& c,
                                       const protocol::SetParameters& m) {
  std::map<std::uint32_t, SetRequest> by_vehicle;
  std::vector<std::string> refused;
  for (const protocol::Parameter& p : m.parameters) {
    const auto name = ParseParameterName(p.name);
    std::string why;
    if (!name) {
      why = "'" + p.name + "' is not a vehicle parameter (vehicle/<id>/<field>)";
    } else if (!p.value) {
      why = p.name + ": a vehicle parameter cannot be unset";
    } else if (!vehicle_servers.count(name->vehicle_id)) {
      why = p.name + ": no vehicle " + std::to_string(name->vehicle_id) + " is sending states";
    } else {
      SetRequest& r = by_vehicle[name->vehicle_id];
      why = SetParameter(r.change, name->path, *p.value);
      if (!why.empty()) why = p.name + ": " + why;  // the full name, not only its field's
      if (why.empty()) {
        // One value a name: the last (as the change holds it); both were echoed back.
        std::erase_if(r.asked, [&](const protocol::Parameter& q) { return q.name == p.name; });
        r.asked.push_back(p);
      }
    }
    if (!why.empty()) {
      Status(id, c, StatusLevel::kError, "setParameters: " + why);
      refused.push_back(p.name);
    }
  }
  if (!refused.empty())
    PushControl(id, c, protocol::ParameterValuesJson(CurrentValues(refused), m.id));
  std::lock_guard lock(request_mu);
  for (auto& [vehicle, r] : by_vehicle) {
    if (r.asked.empty()) continue;
    r.client = id;
    r.vehicle = vehicle;
    r.id = m.id;
    requests.push_back(std::move(r));
  }
  request_cv.notify_one();
}

// --- the requests thread ------------------------------------------------------------------------

void Bridge::Impl::RequestLoop() {
  for (;;) {
    SetRequest r;
    {
      std::unique_lock lock(request_mu);
      request_cv.wait(lock, [&] { return requests_stop || !requests.empty(); });
      if (requests_stop) return;
      r = std::move(requests.front());
      requests.pop_front();
    }
    pb::ControlRequest req;
    req.set_vehicle_id(r.vehicle);
    {
      std::lock_guard lock(mu);
      const auto s = vehicle_servers.find(r.vehicle);
      if (s != vehicle_servers.end()) req.set_server_id(s->second);
    }
    *req.mutable_set_params()->mutable_params() = r.change;
    const auto reply = control.CallGreeted(req, cfg.request_timeout);
    std::string names;
    for (const protocol::Parameter& p : r.asked) names += (names.empty() ? "" : ", ") + p.name;
    std::lock_guard lock(mu);
    const auto c = clients.find(r.client);
    if (c == clients.end()) continue;
    if (reply && reply->accepted()) {
      ++counters.params_accepted;
      // The values as the vehicle holds them, typed (an integer given for a float64 parameter
      // was echoed as the client wrote it, without its type).
      PushControl(c->first, c->second,
                  protocol::ParameterValuesJson(ParametersOf(r.vehicle, r.change), r.id));
      Status(c->first, c->second, StatusLevel::kInfo,
             names + ": accepted by server '" + reply->server_id() + "' at step " +
                 std::to_string(reply->applied_step()));
      continue;
    }
    ++counters.params_refused;
    std::vector<std::string> asked;
    for (const protocol::Parameter& p : r.asked) asked.push_back(p.name);
    Status(c->first, c->second, StatusLevel::kError,
           reply ? names + ": refused by server '" + reply->server_id() + "': " + reply->reason()
                 : names + ": no reply from the vehicle's server: " + control.last_error());
    PushControl(c->first, c->second, protocol::ParameterValuesJson(CurrentValues(asked), r.id));
  }
}

// --- Bridge
// ---------------------------------------------------------------------------------------

Bridge::Bridge(transport::Participant& participant, BridgeConfig config)
    : impl_(std::make_unique<Impl>(participant, std::move(config))) {
  Impl& m = *impl_;
  m.session_id = std::to_string(base::WallNow().ns);
  m.states.AttachTo(m.waitset);
  m.waitset.Attach(m.params_reader);
  m.waitset.Attach(m.world_reader);
  m.waitset.Attach(m.diagnostics_reader);
  m.waitset.Attach(m.events_reader);
  std::lock_guard lock(m.mu);
  m.world_channel = m.ChannelFor("/vdyn/world", Kind::kWorld, 0,
                                 fg::SceneUpdate::descriptor()->full_name(), m.schema_scene);
  m.diagnostics_channel = m.ChannelFor("/vdyn/diagnostics", Kind::kDiagnostics, 0,
                                       pb::Diagnostics::descriptor()->full_name(),
                                       Schema(pb::Diagnostics::descriptor()));
  m.events_channel =
      m.ChannelFor("/vdyn/events", Kind::kEvents, 0, pb::SessionEvent::descriptor()->full_name(),
                   Schema(pb::SessionEvent::descriptor()));
  m.Advertise({m.world_channel, m.diagnostics_channel, m.events_channel});
  m.request_thread = std::thread([&m] { m.RequestLoop(); });
}

Bridge::~Bridge() {
  {
    std::lock_guard lock(impl_->request_mu);
    impl_->requests_stop = true;
  }
  impl_->request_cv.notify_all();
  impl_->request_thread.join();
}

void Bridge::SetCloser(std::function<void(ClientId, const std::string&)> close) {
  std::lock_guard lock(impl_->mu);
  impl_->close = std::move(close);
}

void Bridge::SetLog(std::function<void(const std::string&)> log) {
  impl_->log = std::move(log);
}

void Bridge::Run(const std::atomic<bool>& stop) {
  Impl& m = *impl_;
  const base::Nanos tick = base::FromSeconds(1.0 / m.cfg.scene_hz);
  base::MonoTime next_tick = base::MonotonicNow();
  while (!stop.load()) {
    const base::Nanos wait =
        std::clamp(next_tick - base::MonotonicNow(), base::Nanos{0}, base::Milliseconds(20));
    (void)m.waitset.Wait(std::chrono::nanoseconds(wait.ns));
    const base::MonoTime now = base::MonotonicNow();
    m.TakeOthers(now);
    m.TakeStates(now);
    m.dds_lost = m.states.SamplesLost();
    if (now >= next_tick) {
      m.SceneTick(now);
      next_tick = next_tick + tick;
      if (next_tick < now) next_tick = now + tick;  // busy: the present, not a burst
    }
  }
}

Bridge::Counters Bridge::counters() const {
  std::lock_guard lock(impl_->mu);
  Counters c = impl_->counters;
  c.dds_lost = impl_->dds_lost.load();
  c.clients = static_cast<int>(impl_->clients.size());
  c.subscriptions = 0;
  c.dropped_messages = c.dropped_bytes = 0;
  for (const auto& [id, cl] : impl_->clients) {
    c.subscriptions += static_cast<int>(cl.subscriptions.size());
    const Outbox::Counters o = cl.outbox->counters();
    c.dropped_messages += o.dropped_messages;
    c.dropped_bytes += o.dropped_bytes;
  }
  c.dropped_messages += impl_->closed_dropped_messages;
  c.dropped_bytes += impl_->closed_dropped_bytes;
  return c;
}

void Bridge::CloseAll() {
  std::lock_guard lock(impl_->mu);
  for (auto& [id, ch] : impl_->channels) ch.subscribers.clear();
  impl_->clients.clear();
}

void Bridge::OnOpen(ClientId id, const std::shared_ptr<Outbox>& outbox,
                    const std::string& subprotocol, const std::string& peer) {
  Impl& m = *impl_;
  const std::string name = "client " + std::to_string(id) + " (" + peer + ", " + subprotocol + ")";
  {
    std::lock_guard lock(m.mu);
    ClientState& c = m.clients[id];
    c.outbox = outbox;
    c.name = name;
    protocol::ServerInfo info;
    info.name = m.cfg.name;
    info.capabilities = {"time", "parameters", "parametersSubscribe"};
    if (m.cfg.allow_input) {
      info.capabilities.push_back("clientPublish");
      info.supported_encodings = {"json", "protobuf"};
    }
    info.metadata = {{"domain", std::to_string(m.participant.domain_id())},
                     {"subprotocol", subprotocol}};
    info.session_id = m.session_id;
    m.PushControl(id, c, protocol::ServerInfoJson(info));
    std::vector<const protocol::Channel*> list;
    for (const auto& [cid, ch] : m.channels) {
      if (ch.advertised) list.push_back(&ch.channel);
    }
    m.PushControl(id, c, protocol::AdvertiseJson(list));
  }
  m.log(name + " connected");
}

void Bridge::OnText(ClientId id, std::string_view text) {
  Impl& m = *impl_;
  std::lock_guard lock(m.mu);
  const auto it = m.clients.find(id);
  if (it == m.clients.end()) return;
  ClientState& c = it->second;
  try {
    const protocol::ClientMessage msg = protocol::ParseClientText(text);
    if (const auto* s = std::get_if<protocol::Subscribe>(&msg)) {
      m.HandleSubscribe(id, c, *s);
    } else if (const auto* u = std::get_if<protocol::Unsubscribe>(&msg)) {
      m.HandleUnsubscribe(id, c, *u);
    } else if (const auto* a = std::get_if<protocol::ClientAdvertise>(&msg)) {
      m.HandleAdvertise(id, c, *a);
    } else if (const auto* ua = std::get_if<protocol::ClientUnadvertise>(&msg)) {
      for (std::uint32_t ch : ua->channel_ids) c.publishes.erase(ch);
    } else if (const auto* g = std::get_if<protocol::GetParameters>(&msg)) {
      m.HandleGetParameters(id, c, *g);
    } else if (const auto* sp = std::get_if<protocol::SetParameters>(&msg)) {
      m.HandleSetParameters(id, c, *sp);
    } else if (const auto* su = std::get_if<protocol::SubscribeParameterUpdates>(&msg)) {
      if (su->names.empty()) c.all_params = true;
      c.param_names.insert(su->names.begin(), su->names.end());
    } else if (const auto* uu = std::get_if<protocol::UnsubscribeParameterUpdates>(&msg)) {
      if (uu->names.empty()) {
        c.all_params = false;
        c.param_names.clear();
      }
      for (const std::string& n : uu->names) c.param_names.erase(n);
    } else if (const auto* x = std::get_if<protocol::Unsupported>(&msg)) {
      m.Status(id, c, StatusLevel::kError, "op '" + x->op + "' is not offered by vdyn-foxglove");
    }
  } catch (const protocol::ProtocolError& e) {
    ++m.counters.bad_messages;
    m.Status(id, c, StatusLevel::kError, std::string("vdyn-foxglove: bad message: ") + e.what());
  }
}

namespace {
// The first number of a driver input that is not finite, named ("throttle is nan"); empty when
// all are finite.
std::string NonFiniteInput(const pb::DriverInput& in) {
  const std::pair<const char*, double> fields[] = {
      {"steer", in.steer()},         {"throttle", in.throttle()}, {"brake", in.brake()},
      {"cruise_set_kmh", in.cruise_set_kmh()}, {"clutch", in.clutch()},
      {"handbrake", in.handbrake()}};
  for (const auto& [name, v] : fields) {
    if (!std::isfinite(v)) return std::string(name) + " is " + (std::isnan(v) ? "NaN" : "infinite");
  }
  return {};
}
}  // namespace

void Bridge::OnBinary(ClientId id, std::span<const std::uint8_t> message) {
  Impl& m = *impl_;
  std::lock_guard lock(m.mu);
  const auto it = m.clients.find(id);
  if (it == m.clients.end()) return;
  ClientState& c = it->second;
  std::string error;
  try {
    const protocol::ClientMessageData d = protocol::ParseClientBinary(message);
    const auto p = c.publishes.find(d.channel_id);
    if (!m.cfg.allow_input) {
      error = "client publish is off (vdyn-foxglove runs without --allow-input): input ignored";
    } else if (p == c.publishes.end()) {
      error = "message data on channel " + std::to_string(d.channel_id) +
              ", which this client did not advertise";
    } else {
      pb::DriverInput in;
      const std::string_view bytes(reinterpret_cast<const char*>(d.payload.data()),
                                   d.payload.size());
      const bool parsed =
          p->second.json ? google::protobuf::util::JsonStringToMessage(bytes, &in).ok()
                         : in.ParseFromArray(d.payload.data(), static_cast<int>(d.payload.size()));
      if (!parsed) {
        error = std::string("driver input for vehicle ") + std::to_string(p->second.vehicle) +
                " is not a vdyn.pb.DriverInput (" + (p->second.json ? "JSON" : "protobuf") + ")";
      } else if (const std::string nonfinite = NonFiniteInput(in); !nonfinite.empty()) {
        // Not made a 0 by the clamp below (NaN clamps to 0): refused, as a server refuses it.
        error = "driver input for vehicle " + std::to_string(p->second.vehicle) +
                " refused: " + nonfinite;
      } else {
        // Numbers past their limits are clamped, as every client's are, and the client is told.
        const std::string past = messages::CheckInputRanges(in);
        client::ClampToLimits(in);
        if (!p->second.publisher->Publish(in))
          error = "input not sent: " + p->second.publisher->last_error();
        ++m.counters.inputs;
        if (!past.empty() && error.empty()) {
          ++m.counters.input_clamped;
          const base::MonoTime now = base::MonotonicNow();
          if (now - c.last_input_error >= base::Seconds(1)) {
            c.last_input_error = now;
            m.Status(id, c, StatusLevel::kWarning,
                     "vdyn-foxglove: driver input for vehicle " +
                         std::to_string(p->second.vehicle) + ": " + past +
                         ": clamped to the limit (and any such value)");
          }
        }
      }
    }
  } catch (const protocol::ProtocolError& e) {
    error = std::string("bad binary message: ") + e.what();
  }
  if (error.empty()) return;
  ++m.counters.input_refused;
  // Said at most once a second: a client sends input at its own rate.
  const base::MonoTime now = base::MonotonicNow();
  if (now - c.last_input_error < base::Seconds(1)) return;
  c.last_input_error = now;
  m.Status(id, c, StatusLevel::kError, "vdyn-foxglove: " + error);
}

void Bridge::OnClose(ClientId id, const std::string& why) {
  Impl& m = *impl_;
  std::string name;
  {
    std::lock_guard lock(m.mu);
    const auto it = m.clients.find(id);
    if (it == m.clients.end()) return;
    for (const auto& [sub, channel] : it->second.subscriptions) {
      auto& subs = m.channels[channel].subscribers;
      subs.erase(std::remove_if(subs.begin(), subs.end(),
                                [&](const Subscriber& s) { return s.client == id; }),
                 subs.end());
    }
    const Outbox::Counters o = it->second.outbox->counters();
    m.closed_dropped_messages += o.dropped_messages;
    m.closed_dropped_bytes += o.dropped_bytes;
    name = it->second.name;
    m.clients.erase(it);
  }
  m.log(name + " gone: " + why);
}

}  // namespace vdyn::foxglove
