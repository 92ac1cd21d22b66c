// verify and takeover: the recorder's only code that re-simulates (vdyn_replay, by name; the
// physics stays behind its interface).
#include "vdyn/recorder/verify.h"

#include <algorithm>
#include <chrono>
#include <cinttypes>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <memory>
#include <set>
#include <stdexcept>
#include <thread>

#include <google/protobuf/descriptor.h>
#include <google/protobuf/message.h>
#include <google/protobuf/reflection.h>

#include "vdyn/base/deadline.h"
#include "vdyn/base/text.h"
#include "vdyn/base/time.h"
#include "vdyn/recorder/capture.h"
#include "vdyn/recorder/commands.h"
#include "vdyn/recorder/output_file.h"
#include "vdyn/recorder/recording.h"
#include "vdyn/replay/resim.h"
#include "vdyn/transport/control_client.h"

namespace vdyn::recorder {

using transport::TopicId;

namespace {

// A run of a server's events that never reached the recording: the sequence numbers between
// `before` and `after`.
struct Hole {
  std::uint64_t before = 0, after = 0;
  std::string Text() const {
    const std::uint64_t n = after - before - 1;
    return std::to_string(n) + (n == 1 ? " event is" : " events are") + " missing (sequence " +
           std::to_string(before + 1) + (n == 1 ? "" : ".." + std::to_string(after - 1)) + ")";
  }
};

// A server's start: a server restarted with the same id counts steps and event sequence numbers
// afresh, so each start is replayed on its own (SessionEvent.incarnation; 0 in recordings made
// before servers stamped it).
struct ServerStart {
  std::string id;
  std::uint64_t incarnation = 0;
  auto operator<=>(const ServerStart&) const = default;
};

// One vehicle of one server start.
struct RunKey {
  std::uint32_t vehicle = 0;
  std::uint64_t incarnation = 0;
  auto operator<=>(const RunKey&) const = default;
};

struct Server {
  // Which of its id's starts in the recording, in time order from 1; 0 when there is one.
  std::uint32_t start = 0;
  std::optional<pb::WorldDescription> world;
  std::vector<pb::SessionEvent> events;  // by sequence, each once
  std::vector<Hole> holes;
};

// Every server's world and events (the small part of a recording), in one pass. A world may come
// from a copy (the first one's chunk lost).
std::map<ServerStart, Server> CollectEvents(const mcap::Reader& reader,
                                            const std::function<void(double)>& progress) {
  std::map<ServerStart, Server> servers;
  RecordingVisitor v;
  v.wants = [](TopicId t) { return t == TopicId::kEvents || t == TopicId::kWorld; };
  v.on_progress = progress;
  v.on_message = [&](const RecordedMessage& m) {
    if (m.topic == TopicId::kEvents) {
      pb::SessionEvent e;
      if (e.ParseFromArray(m.data.data(), static_cast<int>(m.data.size()))) {
        // A sequence no server reaches is damage or a foreign writer: not an event, and not the
        // end of a hole of 2^64 events.
        if (e.sequence() >= kImpossibleSequence) return;
        servers[{e.server_id(), e.incarnation()}].events.push_back(std::move(e));
      }
    } else {
      pb::WorldDescription w;
      if (w.ParseFromArray(m.data.data(), static_cast<int>(m.data.size()))) {
        const ServerStart key{w.server_id(), w.incarnation()};
        servers[key].world = std::move(w);
      }
    }
  };
  ScanRecording(reader, v);
  // A start's number among its id's (incarnations are start times: the map's order is time
  // order), where the id started more than once.
  std::map<std::string, std::uint32_t> starts_of;
  for (const auto& [key, s] : servers) ++starts_of[key.id];
  const std::string* last_id = nullptr;
  std::uint32_t n = 0;
  for (auto& [key, s] : servers) {
    n = last_id != nullptr && *last_id == key.id ? n + 1 : 1;
    last_id = &key.id;
    s.start = starts_of[key.id] > 1 ? n : 0;
  }
  for (auto& [id, s] : servers) {
    std::stable_sort(s.events.begin(), s.events.end(),
                     [](const auto& a, const auto& b) { return a.sequence() < b.sequence(); });
    // The same event twice (a copy in a split part or a recovered file) is one event.
    s.events.erase(
        std::unique(s.events.begin(), s.events.end(),
                    [](const auto& a, const auto& b) { return a.sequence() == b.sequence(); }),
        s.events.end());
    for (std::size_t i = 1; i < s.events.size(); ++i) {
      const std::uint64_t a = s.events[i - 1].sequence(), b = s.events[i].sequence();
      if (b > a + 1) s.holes.push_back({a, b});
    }
  }
  return servers;
}

// Why a server's events cannot be re-simulated at all, or empty (a hole in its events stops only
// the stretch it touches).
// "server 'vdyn'", or "server 'vdyn' (its start 2)" when it was restarted in the recording.
std::string ServerName(const std::string& id, std::uint32_t start) {
  return "server '" + Printable(id) + "'" +
         (start == 0 ? "" : " (its start " + std::to_string(start) + ")");
}

// "vehicle 1", or "vehicle 1 of the server's start 2" when its server was restarted.
std::string VehicleName(std::uint32_t vehicle, std::uint32_t start) {
  return "vehicle " + std::to_string(vehicle) +
         (start == 0 ? "" : " of the server's start " + std::to_string(start));
}

std::string CheckServer(const ServerStart& key, const Server& s) {
  if (!s.world) {
    return "no world description of " + ServerName(key.id, s.start) + " was recorded (vdyn/world)";
  }
  return {};
}

// The leaf fields in which two messages differ, in field order ("wheels[2].fy").
void Diff(const google::protobuf::Message& a, const google::protobuf::Message& b,
          const std::string& prefix, std::vector<FieldDiff>& out) {
  using FD = google::protobuf::FieldDescriptor;
  const auto* d = a.GetDescriptor();
  const auto* ra = a.GetReflection();
  const auto* rb = b.GetReflection();
  auto num = [](double v) {
    char s[40];
    std::snprintf(s, sizeof s, "%.17g", v);
    return std::string(s);
  };
  for (int i = 0; i < d->field_count(); ++i) {
    const FD* f = d->field(i);
    const std::string name = prefix + f->name();
    if (f->is_repeated()) {
      const int na = ra->FieldSize(a, f), nb = rb->FieldSize(b, f);
      if (na != nb) {
        out.push_back({name + ".size", std::to_string(na), std::to_string(nb)});
        continue;
      }
      for (int k = 0; k < na; ++k) {
        const std::string item = name + "[" + std::to_string(k) + "]";
        if (f->cpp_type() == FD::CPPTYPE_MESSAGE) {
          Diff(ra->GetRepeatedMessage(a, f, k), rb->GetRepeatedMessage(b, f, k), item + ".", out);
        } else if (f->cpp_type() == FD::CPPTYPE_DOUBLE) {
          const double x = ra->GetRepeatedDouble(a, f, k), y = rb->GetRepeatedDouble(b, f, k);
          if (std::memcmp(&x, &y, sizeof x) != 0) out.push_back({item, num(x), num(y)});
        }
      }
      continue;
    }
    switch (f->cpp_type()) {
      case FD::CPPTYPE_MESSAGE:
        Diff(ra->GetMessage(a, f), rb->GetMessage(b, f), name + ".", out);
        break;
      case FD::CPPTYPE_DOUBLE: {
        const double x = ra->GetDouble(a, f), y = rb->GetDouble(b, f);
        if (std::memcmp(&x, &y, sizeof x) != 0) out.push_back({name, num(x), num(y)});
        break;
      }
      case FD::CPPTYPE_FLOAT: {
        const float x = ra->GetFloat(a, f), y = rb->GetFloat(b, f);
        if (std::memcmp(&x, &y, sizeof x) != 0)
          out.push_back({name, num(static_cast<double>(x)), num(static_cast<double>(y))});
        break;
      }
      case FD::CPPTYPE_BOOL:
        if (ra->GetBool(a, f) != rb->GetBool(b, f)) {
          out.push_back(
              {name, ra->GetBool(a, f) ? "true" : "false", rb->GetBool(b, f) ? "true" : "false"});
        }
        break;
      case FD::CPPTYPE_UINT64:
        if (ra->GetUInt64(a, f) != rb->GetUInt64(b, f)) {
          const bool hash = f->type() == FD::TYPE_FIXED64;
          out.push_back({name,
                         hash ? base::FormatHex(ra->GetUInt64(a, f), 16)
                              : std::to_string(ra->GetUInt64(a, f)),
                         hash ? base::FormatHex(rb->GetUInt64(b, f), 16)
                              : std::to_string(rb->GetUInt64(b, f))});
        }
        break;
      case FD::CPPTYPE_INT64:
        if (ra->GetInt64(a, f) != rb->GetInt64(b, f)) {
          out.push_back(
              {name, std::to_string(ra->GetInt64(a, f)), std::to_string(rb->GetInt64(b, f))});
        }
        break;
      case FD::CPPTYPE_UINT32:
        if (ra->GetUInt32(a, f) != rb->GetUInt32(b, f)) {
          out.push_back(
              {name, std::to_string(ra->GetUInt32(a, f)), std::to_string(rb->GetUInt32(b, f))});
        }
        break;
      case FD::CPPTYPE_INT32:
      case FD::CPPTYPE_ENUM:
        break;  // ids and modes, not physics
      case FD::CPPTYPE_STRING:
        break;  // ids (server, source), not physics
    }
  }
}

// The step at which an event's last action takes effect (an input batch: its last sample's).
std::uint64_t LastActionStep(const pb::SessionEvent& e) {
  const auto& samples = e.input_batch().samples();
  return e.has_input_batch() && !samples.empty() ? samples.rbegin()->step() : e.step();
}

// A stretch of one vehicle's replay: from a spawn or checkpoint to the next restart. When events
// were lost after its start, its replay may lack them from `uncertain_from` on: a hash that
// differs there is that loss, not a divergence, and the stretch is lost until the next one
// starts (at the first checkpoint after the hole).
struct Segment {
  std::size_t first_event = 0;  // its spawn or checkpoint, in VehicleRun::events
  std::uint64_t start_step = 0;
  std::uint64_t uncertain_from = ~0ull;
  std::string hole;  // what is missing, and where the replay goes on
  std::unique_ptr<VehicleReplayer> replayer;
  std::uint64_t replayed_to = 0;  // steps below this have been asked for
  bool lost = false;
  std::string why;
  void Lose(std::uint64_t step, const std::string& reason) {
    lost = true;
    why = reason + " (not verified from step " + std::to_string(step) + ")";
  }
};

// One vehicle's replay: streams forward as states arrive, keeps recent hashes for states that
// arrive a little out of order; restarts at a checkpoint after a hole in the events.
// How far past a vehicle's last event its states may be re-simulated (a minute at 1 kHz; the
// server sends a checkpoint each second).
constexpr std::uint64_t kAheadSteps = 60'000;

// How the list of stretches names compared states that are not verified.
constexpr const char* kDivergedWhy = "DIFFER from the re-simulation (their state hashes)";
constexpr const char* kDamagedWhy =
    "DAMAGED: the hashes match, other fields of the recorded messages do not";
constexpr const char* kHashDamagedWhy =
    "DAMAGED: every field matches and so does the next state; the recorded hash does not";
constexpr const char* kStateDamagedWhy =
    "DAMAGED: the state differs from its re-simulation, the next state matches it again";

struct VehicleRun {
  static constexpr std::size_t kRing = 1 << 14;
  ServerStart server;
  std::uint32_t start = 0;  // Server::start
  ReplayWorld world;
  std::vector<const pb::SessionEvent*> events;  // by sequence
  std::vector<Segment> segments;                // by start step
  std::vector<std::pair<std::uint64_t, std::uint64_t>> ring =
      std::vector<std::pair<std::uint64_t, std::uint64_t>>(kRing, {~0ull, 0});
  std::uint64_t matched = 0;
  std::int64_t step_ns = 0;
  std::uint64_t last_event_step = 0;
  std::string error;

  void AddSegment(std::size_t first_event) {
    segments.emplace_back();
    segments.back().first_event = first_event;
    segments.back().start_step = events[first_event]->step();
  }

  // Cuts the replay into segments at the server's holes.
  void Plan(const std::vector<Hole>& holes) {
    auto starts = [&](std::size_t i) {
      return events[i]->has_spawned() || events[i]->has_checkpoint();
    };
    std::size_t first = 0;
    while (first < events.size() && !starts(first)) ++first;
    if (first == events.size()) return;
    AddSegment(first);
    for (const Hole& h : holes) {
      Segment& seg = segments.back();
      if (h.before < events[seg.first_event]->sequence()) continue;  // before it started
      // The last action of this vehicle known before the hole: a lost event acts at or after it.
      std::uint64_t from = seg.start_step;
      std::size_t next = seg.first_event;
      while (next < events.size() && events[next]->sequence() <= h.before) {
        from = std::max(from, LastActionStep(*events[next]));
        ++next;
      }
      while (next < events.size() && !starts(next)) ++next;
      const bool restarts = next < events.size();
      if (from < seg.uncertain_from) {
        seg.uncertain_from = from;
        seg.hole = "events of " + ServerName(server.id, start) + " were lost: " + h.Text() + "; " +
                   (restarts ? "re-simulated again from the checkpoint at step " +
                                   std::to_string(events[next]->step())
                             : "no checkpoint after them");
      }
      if (!restarts) break;
      AddSegment(next);
    }
  }

  Segment* SegmentAt(std::uint64_t step) {
    Segment* found = nullptr;
    for (Segment& s : segments) {
      if (s.start_step <= step) found = &s;
    }
    return found;
  }

  // A replayer of the events from `first_event` on (a spawn or checkpoint).
  std::unique_ptr<VehicleReplayer> Fresh(std::uint32_t id, std::size_t first_event,
                                         std::string* why) const {
    auto r = std::make_unique<VehicleReplayer>(world, id);
    for (std::size_t i = first_event; i < events.size(); ++i) {
      if (!r->Add(*events[i], why)) return nullptr;
    }
    return r;
  }
};

// `verify` as its stages: collect each server's world and events, plan each vehicle's replay (its
// stretches between holes in the events), start a replayer per stretch, then stream the recorded
// states and compare each with its re-simulation.
class Verifier {
 public:
  explicit Verifier(const VerifyOptions& o) : o_(o), reader_(o.file) {}

  VerifyResult Run() {
    servers_ = CollectEvents(reader_, Progress(0.0, 0.1));
    if (servers_.empty()) {
      res_.cannot = "no session events were recorded (vdyn/events): nothing to re-simulate from";
      return std::move(res_);
    }
    if (!CollectRuns() || !StartReplays()) return std::move(res_);
    CompareStates();
    res_.resimulated = res_.cannot.empty();
    res_.wall_seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - wall_start_).count();
    return std::move(res_);
  }

 private:
  // A recorded state being compared: where it belongs.
  struct StateAt {
    const RecordedMessage& m;
    std::uint64_t step = 0;
    std::uint64_t hash = 0;
    RunKey key;
    std::uint32_t start = 0;  // its server's start (Server::start)
  };

  std::function<void(double)> Progress(double lo, double hi) const {
    return [this, lo, hi](double f) {
      if (o_.on_progress) o_.on_progress(lo + (hi - lo) * f);
    };
  }

  // Each vehicle of each server start replays on its own: a restarted server's vehicle 1 starts
  // again from step 0 (its states say which start stepped them). False: res_.cannot says why.
  bool CollectRuns() {
    for (auto& [id, s] : servers_) {
      if (std::string why = CheckServer(id, s); !why.empty()) {
        res_.cannot = why;
        return false;
      }
      ReplayWorld world;
      try {
        world = ReplayWorldFrom(*s.world);
      } catch (const std::exception& e) {
        res_.cannot = std::string("the recorded world cannot be rebuilt: ") + e.what();
        return false;
      }
      for (const Hole& h : s.holes)
        res_.holes.push_back(ServerName(id.id, s.start) + ": " + h.Text());
      for (const pb::SessionEvent& e : s.events) {
        if (o_.vehicle && e.vehicle_id() != *o_.vehicle) continue;
        VehicleRun& run = runs_[{e.vehicle_id(), id.incarnation}];
        run.server = id;
        run.start = s.start;
        run.world = world;
        run.events.push_back(&e);
        run.last_event_step = std::max(run.last_event_step, LastActionStep(e));
        if (e.has_spawned()) run.step_ns = e.spawned().step_ns();
        if (e.has_checkpoint()) run.step_ns = e.checkpoint().step_ns();
      }
    }
    // The starts of the servers, by incarnation (a state names its own).
    for (const auto& [key, s] : servers_) start_of_[key.incarnation] = s.start;
    return true;
  }

  // A replayer per stretch of each vehicle's events. False: res_.cannot says why.
  bool StartReplays() {
    std::size_t startable = 0;
    for (auto& [key, run] : runs_) {
      run.Plan(servers_.at(run.server).holes);
      if (run.segments.empty()) {
        run.error =
            VehicleName(key.vehicle, run.start) + ": no spawn or checkpoint event was recorded";
        continue;
      }
      for (Segment& seg : run.segments) {
        seg.replayer = run.Fresh(key.vehicle, seg.first_event, &run.error);
        if (!seg.replayer) break;
      }
      if (!run.error.empty()) {
        res_.cannot = run.error;
        return false;
      }
      ++startable;
    }
    if (startable == 0) {
      res_.cannot = runs_.empty() ? "no session events of the chosen vehicle were recorded"
                                  : runs_.begin()->second.error;
      return false;
    }
    return true;
  }

  // Streams the states: replays each vehicle up to the step of its next state and compares.
  void CompareStates() {
    RecordingVisitor v;
    v.wants = [](TopicId t) { return t == TopicId::kState; };
    v.on_progress = Progress(0.1, 1.0);
    v.on_message = [this](const RecordedMessage& m) { OnState(m); };
    const mcap::ScanResult scan = ScanRecording(reader_, v);
    res_.data_crc_checked = scan.data_crc == mcap::ScanResult::DataCrc::kMatched;
  }

  void OnState(const RecordedMessage& m) {
    if (o_.vehicle && m.key != *o_.vehicle) return;
    const std::optional<StateFields> read = ReadStateFields(m.data, m.key);
    if (!read) {
      ++res_.malformed;  // not a state of this vehicle: no step to place it at
      return;
    }
    const auto known = start_of_.find(read->incarnation);
    const StateAt at{m, read->step, read->state_hash, RunKey{m.key, read->incarnation},
                     known == start_of_.end() ? 0 : known->second};
    VehicleRun* run = nullptr;
    Segment* seg = Place(at, run);
    if (seg == nullptr) return;
    bool fresh_step = false;
    if (!ReplayTo(at, *run, *seg, fresh_step)) return;
    const auto& slot = run->ring[at.step % VehicleRun::kRing];
    if (!Comparable(at, *run, *seg, slot, fresh_step)) return;
    ++res_.compared;
    if (compare_next_ && compare_next_->first == at.key && compare_next_->second == at.step) {
      compare_next_.reset();
      DiffFresh(at, *run, *seg, res_.first->next_fields);
    }
    if (slot.second == at.hash) {
      Matched(at, *run, *seg, fresh_step);
    } else {
      Diverged(at, *run, *seg, slot.second, fresh_step);
    }
  }

  // The stretch of its vehicle's replay a state falls in; nullptr (and why, in res_) for a state
  // that no replay reaches.
  Segment* Place(const StateAt& at, VehicleRun*& run_out) {
    const RecordedMessage& m = at.m;
    auto it = runs_.find(at.key);
    if (it == runs_.end() || it->second.segments.empty()) {
      ++res_.not_resimulated;  // no spawn or checkpoint of this vehicle at all
      if (it != runs_.end()) res_.Unverified(m.key, at.start, at.step, it->second.error, false);
      return nullptr;
    }
    VehicleRun& run = it->second;
    Segment* seg = run.SegmentAt(at.step);
    if (seg == nullptr) {
      // Before the vehicle's first spawn or checkpoint: a recorder that joined late (or lost it).
      ++res_.not_resimulated;
      res_.Unverified(m.key, at.start, at.step,
                      "before its first spawn or checkpoint in the recording", false);
      return nullptr;
    }
    if (seg->lost) {
      res_.Unverified(m.key, at.start, at.step, seg->why);
      return nullptr;
    }
    if (at.step > run.last_event_step + kAheadSteps) {
      // Far beyond every event of the vehicle (a checkpoint comes each second): not a step to
      // simulate towards (a damaged step would cost hours).
      res_.Unverified(m.key, at.start, at.step,
                      "beyond the vehicle's last recorded event (step " +
                          std::to_string(run.last_event_step) + "): not re-simulated");
      return nullptr;
    }
    run_out = &run;
    return seg;
  }

  // Runs the stretch's replay up to the state's step, keeping each step's hash in the ring.
  // False when the replay stopped (the stretch is lost); `fresh_step` when this state's step was
  // the last one run.
  bool ReplayTo(const StateAt& at, VehicleRun& run, Segment& seg, bool& fresh_step) {
    if (at.step + 1 <= seg.replayed_to) return true;
    const double h = static_cast<double>(run.step_ns) * 1e-9;
    std::string why;
    if (!seg.replayer->Run(
            at.step + 1,
            [&](std::uint64_t s, std::uint64_t hh) {
              run.ring[s % VehicleRun::kRing] = {s, hh};
              res_.sim_seconds += h;
            },
            &why)) {
      seg.Lose(at.step, "the re-simulation stopped: " + why);
      res_.Unverified(at.m.key, at.start, at.step, seg.why);
      return false;
    }
    seg.replayed_to = at.step + 1;
    fresh_step = true;
    return true;
  }

  // Whether a re-simulated hash can be held against the state: not when the ring no longer holds
  // its step, nor when a difference is explained by events the recording lost.
  bool Comparable(const StateAt& at, const VehicleRun& run, Segment& seg,
                  const std::pair<std::uint64_t, std::uint64_t>& slot, bool fresh_step) {
    const RecordedMessage& m = at.m;
    if (slot.first != at.step) {
      ++res_.not_resimulated;  // not re-simulated (a state older than the ring holds)
      res_.Unverified(m.key, at.start, at.step,
                      "not re-simulated (it arrived too late in the file)", false);
      return false;
    }
    if (slot.second == at.hash) return true;
    if (at.step >= seg.uncertain_from) {
      // Events of this stretch are missing: the replay lacks them, it has not diverged. It goes
      // on from the next checkpoint after the hole.
      seg.Lose(at.step, seg.hole);
      res_.Unverified(m.key, at.start, at.step, seg.why);
      return false;
    }
    if (at.step > run.last_event_step && fresh_step && InputNotRecorded(at, seg)) {
      // Past the vehicle's last recorded event, the server applied an input that no recorded
      // event gives: the recording's last events never reached it (the server or the recorder
      // stopped first, or they were lost at the end, where no later sequence number shows the
      // hole). The replay lacks them; it has not diverged.
      seg.Lose(at.step, "the recording's events end at step " +
                            std::to_string(run.last_event_step) +
                            " and this state's input is in none of them (the last events never "
                            "reached the recording)");
      res_.Unverified(m.key, at.start, at.step, seg.why);
      return false;
    }
    return true;
  }

  // The recorded state, read whole into recorded_.
  bool ParseRecorded(const RecordedMessage& m) {
    return recorded_.ParseFromArray(m.data.data(), static_cast<int>(m.data.size()));
  }

  // The fields of the recorded state that differ from the replay's message of the step it just
  // ran (that step being the state's); false when there is no such message to compare with.
  bool DiffJustRun(const StateAt& at, const VehicleReplayer& r, std::vector<FieldDiff>& out) {
    if (r.last_step() != at.step || !ParseRecorded(at.m)) return false;
    const std::optional<pb::VehicleState> resimulated = r.StateMessage(recorded_);
    if (!resimulated) return false;
    // The same bytes are the same fields (the usual case; field by field costs 3x as much).
    resimulated->SerializeToString(&bytes_);
    if (bytes_.size() == at.m.data.size() &&
        std::equal(bytes_.begin(), bytes_.end(),
                   reinterpret_cast<const char*>(at.m.data.data()))) {
      return true;
    }
    Diff(recorded_, *resimulated, "", out);
    return true;
  }

  // The state's input is not the replay's: the server had an input the recording lacks.
  bool InputNotRecorded(const StateAt& at, const Segment& seg) {
    std::vector<FieldDiff> fields;
    if (!DiffJustRun(at, *seg.replayer, fields)) return false;
    return std::any_of(fields.begin(), fields.end(),
                       [](const FieldDiff& f) { return f.field.rfind("input.", 0) == 0; });
  }

  // The fields in which the state differs from its stretch replayed afresh up to its step (the
  // running replay has moved on); nothing when that replay cannot be had.
  void DiffFresh(const StateAt& at, const VehicleRun& run, const Segment& seg,
                 std::vector<FieldDiff>& out) {
    std::string why;
    auto fresh = run.Fresh(at.m.key, seg.first_event, &why);
    if (!fresh || !fresh->Run(at.step + 1, {}, &why) || !fresh->last_step() ||
        !ParseRecorded(at.m)) {
      return;
    }
    if (const auto resimulated = fresh->StateMessage(recorded_))
      Diff(recorded_, *resimulated, "", out);
  }

  // A state whose hash matched: verified, unless other fields differ where no CRC vouched for
  // the bytes (damaged). The hash covers the state, not every field of the message: each is
  // compared with the re-simulation (it just ran this very step). Where a CRC held, a field that
  // differs is said (another version's writer, or an edit with its CRCs written anew) but the
  // state stays verified: its hash, the simulation's, matched.
  void Matched(const StateAt& at, VehicleRun& run, const Segment& seg, bool fresh_step) {
    ++run.matched;
    if (at.m.unchecked) ++res_.unchecked;
    MismatchHealed(at);
    bool damaged = false;
    std::vector<FieldDiff> fields;
    if (fresh_step && DiffJustRun(at, *seg.replayer, fields) && !fields.empty()) {
      if (at.m.unchecked) {
        damaged = true;
        ++res_.damaged;
        if (!res_.first_damaged) res_.first_damaged = Damaged{at.m.key, at.start, at.step, fields};
      } else {
        ++res_.field_differences;
        if (!res_.first_field_difference)
          res_.first_field_difference = Damaged{at.m.key, at.start, at.step, fields};
      }
    }
    if (damaged) {
      res_.Unverified(at.m.key, at.start, at.step, kDamagedWhy, false);
    } else {
      res_.Verified(at.m.key, at.start, at.step);
    }
  }

  // The state before `at` differed from the re-simulation and `at` matches it: the re-simulation
  // was at the recorded state after all (a step's state follows from the one before it alone), so
  // the recorded message is what is wrong (damaged bytes), not the simulation, which never finds
  // its way back once it has diverged. Counted as damaged instead of diverged.
  void MismatchHealed(const StateAt& at) {
    const auto it = mismatch_.find(at.key);
    if (it == mismatch_.end()) return;
    const Mismatch m = std::move(it->second);
    mismatch_.erase(it);
    const std::uint64_t step = m.step;
    if (step + 1 != at.step) return;
    const bool hash_alone =
        m.fields_known && std::all_of(m.fields.begin(), m.fields.end(), [](const FieldDiff& f) {
          return f.field == "state_hash";
        });
    const char* why = hash_alone ? kHashDamagedWhy : kStateDamagedWhy;
    std::vector<StepRun>& runs = res_.runs[at.m.key];
    if (runs.empty() || runs.back().why != kDivergedWhy || runs.back().last != step) return;
    StepRun& r = runs.back();
    if (r.first == step) {
      r.why = why;
    } else {  // the diverged run held earlier steps too: the last one is split off
      --r.last;
      --r.count;
      runs.push_back({r.start, step, step, 1, why});
    }
    --res_.mismatched;
    ++res_.damaged;
    if (!res_.first_damaged) {
      std::vector<FieldDiff> fields;
      for (const FieldDiff& f : m.fields) {
        fields.push_back(f.field == "state_hash" ? FieldDiff{"state_hash (the hash after the step)",
                                                            f.recorded, f.resimulated}
                                                 : f);
      }
      res_.first_damaged = Damaged{at.m.key, at.start, step, std::move(fields)};
    }
    if (res_.first && res_.first->vehicle == at.m.key && res_.first->step == step) {
      res_.first.reset();
      compare_next_.reset();
    }
  }

  // A state whose hash differs: counted, and the first one described field by field.
  void Diverged(const StateAt& at, const VehicleRun& run, const Segment& seg,
                std::uint64_t resimulated_hash, bool fresh_step) {
    ++res_.mismatched;
    res_.Unverified(at.m.key, at.start, at.step, kDivergedWhy, false);
    // Diverged, or a damaged message: the next state decides (MismatchHealed).
    Mismatch& m = mismatch_[at.key];
    m.step = at.step;
    m.fields.clear();
    m.fields_known = fresh_step && DiffJustRun(at, *seg.replayer, m.fields);
    if (res_.first) return;
    Divergence d;
    d.vehicle = at.m.key;
    d.start = at.start;
    d.step = at.step;
    d.t = static_cast<double>(at.step) * static_cast<double>(run.step_ns) * 1e-9;
    d.recorded_hash = at.hash;
    d.resimulated_hash = resimulated_hash;
    d.matched_before = run.matched;
    DiffFresh(at, run, seg, d.fields);
    // Causes first: the input and controls applied over the step, then what they moved.
    std::stable_partition(d.fields.begin(), d.fields.end(), [](const FieldDiff& f) {
      return f.field.rfind("input.", 0) == 0 || f.field.rfind("control.", 0) == 0;
    });
    // Only the hash differs: the step's start agrees, so look at the state after it.
    if (d.fields.size() <= 1) compare_next_ = std::make_pair(at.key, at.step + 1);
    res_.first = std::move(d);
  }

  const VerifyOptions& o_;
  const std::chrono::steady_clock::time_point wall_start_ = std::chrono::steady_clock::now();
  mcap::Reader reader_;
  VerifyResult res_;
  std::map<ServerStart, Server> servers_;
  std::map<RunKey, VehicleRun> runs_;
  std::map<std::uint64_t, std::uint32_t> start_of_;               // server start by incarnation
  std::optional<std::pair<RunKey, std::uint64_t>> compare_next_;  // divergence: next state
  struct Mismatch {
    std::uint64_t step = 0;
    bool fields_known = false;
    std::vector<FieldDiff> fields;  // recorded, re-simulated (the hash included)
  };
  std::map<RunKey, Mismatch> mismatch_;  // each run's last state that differed
  pb::VehicleState recorded_;
  std::string bytes_;  // the re-simulated state message, serialized
};

}  // namespace

VerifyResult Verify(const VerifyOptions& o) {
  return Verifier(o).Run();
}

void VerifyResult::Verified(std::uint32_t vehicle, std::uint32_t start, std::uint64_t step) {
  auto& range = vehicles[vehicle];
  if (range.count == 0) range.first = step;
  range.first = std::min(range.first, step);
  range.last = std::max(range.last, step);
  ++range.count;
  std::vector<StepRun>& r = runs[vehicle];
  if (r.empty() || !r.back().why.empty() || r.back().start != start)
    r.push_back({start, step, step, 0, {}});
  r.back().last = std::max(r.back().last, step);
  ++r.back().count;
}

void VerifyResult::Unverified(std::uint32_t vehicle, std::uint32_t start, std::uint64_t step,
                              const std::string& why, bool counts) {
  if (counts) ++unverified;
  std::vector<StepRun>& r = runs[vehicle];
  if (r.empty() || r.back().why != why || r.back().start != start)
    r.push_back({start, step, step, 0, why});
  r.back().last = std::max(r.back().last, step);
  ++r.back().count;
}

namespace {

// What `verify` found, as a person reads it: a divergence, nothing compared, or the verified
// stretches; then what was not verified and the recording's own integrity notes.
class VerifyReport {
 public:
  VerifyReport(const VerifyOptions& o, const VerifyResult& r, std::ostream& out)
      : o_(o), r_(r), out_(out) {}

  int Print() {
    // A recovered file says what its source lost and what no CRC checked: said here too, never
    // a bit-exact claim on its own.
    recovered_ = IntegrityNotes(ReadMetadata(mcap::Reader(o_.file)), {}, 0, "");
    if (!r_.resimulated) {
      // The reason may quote the file (a world's name): shown as text, cut to a line.
      out_ << o_.file.string() << ": cannot re-simulate: " << Printable(r_.cannot, 600) << "\n";
      return 1;
    }
    if (r_.first) {
      PrintDivergence(*r_.first);
      Unverified();
      Notes();
      return 1;
    }
    if (r_.compared == 0) {
      out_ << o_.file.string()
           << ": nothing compared: no recorded state falls after a spawn or checkpoint";
      out_ << (r_.unverified > 0 ? "" : "\n");
      if (r_.unverified > 0) out_ << " that the recording kept whole\n";
      Unverified();
      Notes();
      return 1;
    }
    PrintVerified();
    PrintDamage();
    PrintFieldDifferences();
    if (!r_.holes.empty()) {
      out_ << "  events lost from the recording:";
      for (const std::string& h : r_.holes) out_ << " " << h << ";";
      out_ << (r_.unverified == 0 ? " every recorded state still matched its re-simulation\n"
                                  : "\n");
    }
    Unverified();
    if (r_.unchecked > 0 && !r_.data_crc_checked) {
      out_ << "  " << r_.unchecked << " of the compared states come from chunks without a CRC: "
           << "like every state, each field was compared with the re-simulation"
           << (r_.damaged > 0 ? "" : " (all equal)") << "\n";
    }
    Notes();
    return r_.ok() ? 0 : 1;
  }

 private:
  void Notes() {
    for (const std::string& n : recovered_) out_ << "  " << n << "\n";
  }

  // Up to 12 differing fields (the hash itself left out); how many.
  std::size_t Fields(const std::vector<FieldDiff>& fields) {
    std::size_t shown = 0;
    char line[256];
    for (const FieldDiff& f : fields) {
      if (f.field == "state_hash") continue;
      if (++shown > 12) {
        out_ << "    ... " << (fields.size() - 12) << " more\n";
        break;
      }
      std::snprintf(line, sizeof line, "    %-22s %-26s %s\n", f.field.c_str(), f.recorded.c_str(),
                    f.resimulated.c_str());
      out_ << line;
    }
    return shown;
  }

  // What could not be verified, per vehicle: the stretches and why.
  void Unverified() {
    if (r_.malformed > 0) {
      out_ << "  NOT verified: " << r_.malformed
           << " recorded state messages do not read as states "
           << "of their vehicle (damaged or foreign payloads)\n";
    }
    bool all_verified = true;
    for (const auto& [id, rs] : r_.runs) {
      for (const StepRun& run : rs) all_verified = all_verified && run.why.empty();
    }
    if (all_verified) return;
    if (r_.unverified > 0) out_ << "  NOT verified: " << r_.unverified << " recorded states\n";
    if (r_.unverified == 0) out_ << "  steps:\n";
    for (const auto& [id, rs] : r_.runs) {
      for (const StepRun& run : rs) {
        out_ << "    " << VehicleName(id, run.start) << ", steps " << run.first << ".." << run.last
             << " (" << run.count
             << " states): " << (run.why.empty() ? "verified bit for bit" : Printable(run.why, 600))
             << "\n";
      }
    }
  }

  void PrintDivergence(const Divergence& d) {
    char line[256];
    std::snprintf(line, sizeof line, "DIVERGES at %s, step %" PRIu64 " (t = %.3f s of simulation)",
                  VehicleName(d.vehicle, d.start).c_str(), d.step, d.t);
    out_ << o_.file.string() << ": " << line << ": the state hash after the step was "
         << base::FormatHex(d.recorded_hash, 16) << " in the recording, "
         << base::FormatHex(d.resimulated_hash, 16) << " re-simulated\n";
    out_ << "  state fields that differ at that step (recorded, re-simulated):\n";
    if (Fields(d.fields) == 0) {
      out_ << "    none: the step started from the same state with the same input; the state "
              "after it\n"
              "    differs";
      if (!d.next_fields.empty()) {
        out_ << " (the next recorded state, recorded vs re-simulated):\n";
        Fields(d.next_fields);
      } else {
        out_ << "\n";
      }
    }
    out_ << "  " << d.matched_before << " steps of " << VehicleName(d.vehicle, d.start)
         << " matched bit for bit before it; " << r_.mismatched << " of " << r_.compared
         << " compared steps differ\n";
  }

  // Per vehicle (and server start) the verified stretches: "vehicle 1: steps 0..999, 2000..2999".
  void PrintVerified() {
    std::string ranges;
    for (const auto& [id, rs] : r_.runs) {
      std::map<std::uint32_t, std::string> verified;  // by start
      for (const StepRun& run : rs) {
        if (!run.why.empty()) continue;
        std::string& v = verified[run.start];
        v += (v.empty() ? "" : ", ") + std::to_string(run.first) + ".." + std::to_string(run.last);
      }
      for (const auto& [start, steps] : verified) {
        ranges += (ranges.empty() ? "" : "; ") + VehicleName(id, start) + ": steps " + steps;
      }
    }
    char line[256];
    std::snprintf(line, sizeof line, "bit-exact over %" PRIu64 " steps",
                  r_.compared - r_.damaged);  // as the stretches listed
    // Not "bit-exact" alone where a state was damaged: the line's first words say it.
    out_ << o_.file.string() << ": "
         << (r_.damaged > 0           ? "DAMAGED, PARTLY verified: "
             : r_.unverified > 0      ? "PARTLY verified: "
                                      : "")
         << line
         << " (" << ranges << ")";
    if (r_.not_resimulated > 0)
      out_ << "; " << r_.not_resimulated << " states before a spawn or checkpoint not compared";
    std::snprintf(line, sizeof line, "; %.1f s simulated in %.1f s, %.0fx real time\n",
                  r_.sim_seconds, r_.wall_seconds,
                  r_.wall_seconds > 0 ? r_.sim_seconds / r_.wall_seconds : 0.0);
    out_ << line;
  }

  void PrintFieldDifferences() {
    if (r_.field_differences == 0) return;
    const Damaged& d = *r_.first_field_difference;
    out_ << "  note: " << r_.field_differences
         << " recorded state message(s) match their re-simulation's hash but differ from what "
            "this build writes in other fields: written by another version of vdyn, or changed "
            "with their chunks' CRCs written anew; the first, "
         << VehicleName(d.vehicle, d.start) << " at step " << d.step << " (recorded, re-simulated):\n";
    Fields(d.fields);
  }

  void PrintDamage() {
    if (r_.damaged == 0) return;
    const Damaged& d = *r_.first_damaged;
    out_ << "  DAMAGED: " << r_.damaged
         << " recorded state(s) differ from their re-simulation in one part only (fields where "
         << "no CRC covered them, or the hash alone, the state after them matching): their bytes "
         << "were changed after the server wrote them; "
         << "the first, " << VehicleName(d.vehicle, d.start) << " at step " << d.step
         << " (recorded, re-simulated):\n";
    Fields(d.fields);
  }

  const VerifyOptions& o_;
  const VerifyResult& r_;
  std::ostream& out_;
  std::vector<std::string> recovered_;
};

}  // namespace

int RunVerify(const VerifyOptions& o, std::ostream& out) {
  // A vehicle the file has no states of: said as export and plot say it (a bad command line).
  if (o.vehicle) {
    const mcap::Reader reader(o.file);
    if (const auto summary = reader.ReadSummary()) {
      std::set<std::uint32_t> vehicles;
      for (const auto& [id, info] : VdynChannels(*summary)) {
        if (info.topic == TopicId::kState) vehicles.insert(info.key);
      }
      if (!vehicles.empty() && vehicles.count(*o.vehicle) == 0) {
        std::string have;
        for (std::uint32_t v : vehicles) have += (have.empty() ? "" : ", ") + std::to_string(v);
        out << "vdyn-recorder verify: no states of vehicle " << *o.vehicle << " in "
            << o.file.string() << " (it has vehicle " << have << ")\n";
        return 2;
      }
    }
  }
  Progress bar("verify");
  VerifyOptions with = o;
  with.on_progress = [&bar](double f) { bar.Update(f); };
  const VerifyResult r = Verify(with);
  bar.Finish();
  return VerifyReport(o, r, out).Print();
}

// --- takeover -----------------------------------------------------------------------------------

namespace {

// The recorded state at or after log time `at`: its vehicle (`vehicle`, or the first recorded),
// its step and server start, the recorded hash of the step before, and the last log time.
struct StateAtTime {
  std::optional<std::uint32_t> chosen;
  std::optional<std::uint64_t> step;
  std::optional<std::uint64_t> hash_before;
  std::uint64_t incarnation = 0;  // the server start that stepped the chosen state
  std::uint64_t last_time = 0;
};
StateAtTime FindStateAt(const mcap::Reader& reader, std::uint64_t at,
                        std::optional<std::uint32_t> vehicle) {
  StateAtTime r;
  r.chosen = vehicle;
  std::map<std::pair<std::uint32_t, std::uint64_t>, std::pair<std::uint64_t, std::uint64_t>>
      last;  // (vehicle, server start) -> (step, hash)
  RecordingVisitor v;
  v.wants = [](TopicId t) { return t == TopicId::kState; };
  v.on_message = [&](const RecordedMessage& m) {
    r.last_time = std::max(r.last_time, m.log_time);
    if (r.step) return;
    if (!r.chosen) r.chosen = m.key;
    if (m.key != *r.chosen) return;
    const std::optional<StateFields> fields = ReadStateFields(m.data, m.key);
    if (!fields) return;  // not a state of this vehicle
    const std::uint64_t s = fields->step;
    const std::uint64_t h = fields->state_hash;
    if (m.log_time >= at) {
      r.step = s;
      r.incarnation = fields->incarnation;
      if (auto it = last.find({m.key, r.incarnation});
          it != last.end() && it->second.first + 1 == s)
        r.hash_before = it->second.second;
    }
    last[{m.key, fields->incarnation}] = {s, h};
  };
  ScanRecording(reader, v);
  return r;
}

}  // namespace

BranchPoint FindBranchPoint(const std::filesystem::path& file, double at_s,
                            std::optional<std::uint32_t> vehicle) {
  mcap::Reader reader(file);
  const std::uint64_t first = FirstLogTime(reader);
  const auto at = first + static_cast<std::uint64_t>(base::FromSeconds(at_s).ns);
  // The vehicle and its step at that time, and the recorded hash of the step before.
  const StateAtTime found = FindStateAt(reader, at, vehicle);
  const std::optional<std::uint32_t>& chosen = found.chosen;
  const std::optional<std::uint64_t>& step = found.step;
  const std::optional<std::uint64_t>& hash_before = found.hash_before;
  const std::uint64_t incarnation = found.incarnation;
  const std::uint64_t last_time = found.last_time;
  if (!chosen) throw std::runtime_error(file.string() + " holds no vehicle states");
  if (!step) {
    char b[160];
    std::snprintf(b, sizeof b,
                  "no state of vehicle %u at or after %.3f s: the recording ends at %.3f s",
                  *chosen, at_s, static_cast<double>(last_time - first) * 1e-9);
    throw std::runtime_error(b);
  }
  std::map<ServerStart, Server> servers = CollectEvents(reader, {});
  const Server* server = nullptr;
  ServerStart server_id;
  for (const auto& [id, s] : servers) {
    if (id.incarnation != incarnation) continue;
    for (const auto& e : s.events) {
      if (e.vehicle_id() == *chosen) {
        server = &s;
        server_id = id;
      }
    }
  }
  if (server == nullptr)
    throw std::runtime_error("no session events of vehicle " + std::to_string(*chosen) +
                             " were recorded");
  if (std::string why = CheckServer(server_id, *server); !why.empty())
    throw std::runtime_error(why);
  if (!server->holes.empty()) {
    throw std::runtime_error("events of " + ServerName(server_id.id, server->start) +
                             " were lost: " + server->holes.front().Text() +
                             ": the exact state of a moment cannot be rebuilt across them");
  }
  VehicleReplayer replayer(ReplayWorldFrom(*server->world), *chosen);
  BranchPoint bp;
  std::string why;
  for (const auto& e : server->events) {
    if (e.vehicle_id() != *chosen) continue;
    if (!replayer.Add(e, &why)) throw std::runtime_error(why);
    if (e.step() > *step) continue;
    if (e.has_spawned()) bp.params = e.spawned().params();
    if (e.has_checkpoint()) bp.params = e.checkpoint().params();
    if (e.has_params_changed()) bp.params = e.params_changed().params();
  }
  std::optional<std::uint64_t> replayed_before;
  if (!replayer.Run(
          *step,
          [&](std::uint64_t s, std::uint64_t h) {
            if (s + 1 == *step) replayed_before = h;
          },
          &why)) {
    throw std::runtime_error(why);
  }
  const std::optional<VehicleReplayer::Exact> exact = replayer.ExactAt(*step);
  if (!exact) {
    // Where a takeover can start: the vehicle's first spawn or checkpoint, said as the --at of
    // the first state recorded at or after it.
    std::optional<std::uint64_t> first_start;
    for (const auto& e : server->events) {
      if (e.vehicle_id() == *chosen && (e.has_spawned() || e.has_checkpoint()) &&
          (!first_start || e.step() < *first_start))
        first_start = e.step();
    }
    std::string hint = " (no spawn or checkpoint of it before that step is recorded)";
    if (first_start && *first_start > *step) {
      std::optional<std::uint64_t> log_time;
      RecordingVisitor v;
      v.wants = [](TopicId t) { return t == TopicId::kState; };
      v.on_message = [&](const RecordedMessage& m) {
        if (log_time || m.key != *chosen) return;
        const std::optional<StateFields> f = ReadStateFields(m.data, m.key);
        if (f && f->incarnation == incarnation && f->step >= *first_start) log_time = m.log_time;
      };
      ScanRecording(reader, v);
      char b[200];
      if (log_time) {
        std::snprintf(b, sizeof b,
                      ": its first spawn or checkpoint in the recording is at step %" PRIu64
                      ", recorded at %.3f s: give --at %.3f or later",
                      *first_start, static_cast<double>(*log_time - first) * 1e-9,
                      std::ceil(static_cast<double>(*log_time - first) * 1e-6) * 1e-3);
      } else {
        std::snprintf(b, sizeof b,
                      ": its first spawn or checkpoint in the recording is at step %" PRIu64
                      ", after its last recorded state",
                      *first_start);
      }
      hint = b;
    }
    throw std::runtime_error("vehicle " + std::to_string(*chosen) +
                             " cannot be re-simulated to step " + std::to_string(*step) + hint);
  }
  if (hash_before && replayed_before && *hash_before != *replayed_before) {
    throw std::runtime_error(
        "the recording does not re-simulate up to step " + std::to_string(*step) +
        " (its hash differs before it): run `vdyn-recorder verify` to see where");
  }
  bp.checked = hash_before && replayed_before;
  bp.vehicle = *chosen;
  bp.step = *step;
  bp.at_s = at_s;
  bp.state = exact->state;
  bp.input = exact->input;
  bp.server_id = server_id.id;
  bp.world_name = server->world->name();
  bp.terrain_hash = server->world->terrain_hash();
  char label[256];
  std::snprintf(label, sizeof label, "%.180s@%.3fs (vehicle %u, step %" PRIu64 ")",
                file.filename().string().c_str(), at_s, bp.vehicle, bp.step);
  bp.label = label;
  return bp;
}

namespace {

// The world of a live server on terrain `terrain_hash`, waited for up to `wait_s`; the worlds seen
// on other terrains go to `others` ("'name' of server 'id'").
std::optional<pb::WorldDescription> FindLiveWorld(transport::Participant& participant,
                                                  std::uint64_t terrain_hash, double wait_s,
                                                  const std::atomic<bool>& stop,
                                                  std::set<std::string>& others) {
  std::optional<pb::WorldDescription> live;
  transport::DropCounters drops;
  transport::Reader<pb::WorldDescription> worlds(participant, TopicId::kWorld, &drops);
  (void)base::PollUntil(
      base::Deadline::AfterSeconds(wait_s), base::Milliseconds(100),
      [&] {
        (void)worlds.Take([&](const pb::WorldDescription& w, const transport::SampleInfo&) {
          if (w.terrain_hash() == terrain_hash) {
            live = w;
          } else {
            // Appended, not a chain of operator+: GCC 12 at -O3 warns falsely (-Wrestrict) on
            // the chain once this is inlined into the reader's take.
            std::string other = "'";
            other += Printable(w.name());
            other += "' of server '";
            other += Printable(w.server_id());
            other += "'";
            others.insert(std::move(other));
          }
        });
        return live.has_value() || stop.load();
      },
      [&](base::Nanos slice) { (void)worlds.Wait(base::Chrono(slice)); });
  return live;
}

}  // namespace

int RunTakeover(const TakeoverOptions& o, const std::atomic<bool>& stop, std::ostream& out) {
  std::filesystem::path new_file = o.out;
  if (new_file.empty()) {
    new_file = o.file;
    new_file.replace_filename(o.file.stem().string() + "-takeover" + o.file.extension().string());
  }
  CheckNotAnInput(new_file, {o.file});  // before anything happens on the network
  const BranchPoint bp = FindBranchPoint(o.file, o.at_s, o.vehicle);
  out << "branch point: " << bp.label << " on world '" << bp.world_name << "'"
      << (bp.checked ? "; the re-simulation up to it matches the recording bit for bit" : "")
      << std::endl;
  transport::Participant participant(o.domain);
  // The live server, and its world: the recording must continue on the terrain it was made on.
  std::set<std::string> others;
  const std::optional<pb::WorldDescription> live =
      FindLiveWorld(participant, bp.terrain_hash, o.wait_s, stop, others);
  if (!live) {
    out << "vdyn-recorder takeover: no server on domain " << o.domain << " runs world '"
        << bp.world_name << "' (terrain hash " << base::FormatHex(bp.terrain_hash, 16)
        << ") within " << o.wait_s << " s";
    for (const std::string& w : others) out << "; seen: " << w;
    out << "\n";
    return 1;
  }
  // Record first, so the new recording holds the restore's events.
  RecordOptions ro;
  ro.out = new_file;
  ro.writer.inputs = {o.file};  // never over the recording it continues
  ro.branched_from = bp.label;
  ro.command_line = o.command_line;
  ro.duration_s = o.duration_s;
  ro.status_line = o.status_line;
  ro.status_tty = o.status_tty;
  Capture capture(participant, ro);
  std::atomic<bool> capture_stop{false};
  std::optional<CaptureSummary> summary;
  std::exception_ptr capture_error;
  std::thread recorder([&] {
    try {
      summary = capture.Run(capture_stop);
    } catch (...) {
      capture_error = std::current_exception();
    }
  });
  auto finish = [&](int code) {
    capture_stop = true;
    recorder.join();
    if (capture_error) std::rethrow_exception(capture_error);
    if (summary) {
      out << "recorded " << summary->messages << " messages to " << ro.out.string()
          << " (branched from " << bp.label << ")\n";
    }
    return code;
  };
  // The restore's events must reach the recording: wait until the server's writers are matched.
  (void)capture.WaitForWriters(TopicId::kEvents, base::Deadline::AfterSeconds(o.wait_s));
  transport::ControlClient control(participant, "vdyn-recorder takeover");
  if (!control.WaitForServer(std::chrono::milliseconds(static_cast<std::int64_t>(o.wait_s * 1000)),
                             live->server_id())) {
    out << "vdyn-recorder takeover: " << control.last_error() << "\n";
    return finish(1);
  }
  pb::ControlRequest req;
  req.set_vehicle_id(o.as_vehicle.value_or(bp.vehicle));
  req.set_server_id(live->server_id());
  auto* rs = req.mutable_restore();
  *rs->mutable_state() = bp.state;
  *rs->mutable_params() = bp.params;
  *rs->mutable_input() = bp.input;
  rs->set_branched_from(bp.label);
  const auto reply = control.Call(req, std::chrono::seconds(10));
  if (!reply) {
    out << "vdyn-recorder takeover: no reply to the restore request: " << control.last_error()
        << "\n";
    return finish(1);
  }
  if (!reply->accepted()) {
    out << "vdyn-recorder takeover: server '" << Printable(live->server_id())
        << "' refused the restore: " << Printable(reply->reason()) << "\n";
    return finish(1);
  }
  out << "vehicle " << req.vehicle_id() << " of server '" << Printable(live->server_id())
      << "' continues from " << bp.label << " at step " << reply->applied_step()
      << ": drive it now (a rig or vdyn-input); recording to " << ro.out.string()
      << (o.duration_s > 0 ? "" : "; Ctrl-C ends") << "\n";
  out.flush();
  // Runs until Ctrl-C or --duration (the capture ends itself then too).
  const base::Deadline end =
      o.duration_s > 0 ? base::Deadline::AfterSeconds(o.duration_s) : base::Deadline::Never();
  while (!stop.load() && !end.Passed()) {
    base::SleepUntil(base::MonotonicNow() + std::min(base::Milliseconds(50), end.Left()));
  }
  return finish(0);
}

}  // namespace vdyn::recorder
