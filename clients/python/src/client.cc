#include "client.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "vdyn/base/deadline.h"
#include "vdyn/base/limits.h"
#include "vdyn/io/maneuver.h"
#include "vdyn/messages/input_checks.h"

namespace vdyn::python {
namespace {

// The rate a Driver sends its input at, Hz.
// At least one input a minute (a period that fits: 1e-10 Hz overflowed it and aborted Python).
constexpr limits::Range kDriverRateHz{1.0 / 60.0, 10000.0, false, false, "rate_hz"};

// A call's deadline from its timeout in seconds (finite and >= 0; a time beyond the clock's range,
// 1e10 s and more, waits without end instead of wrapping round into the past).
base::Deadline DeadlineIn(double seconds) {
  if (!std::isfinite(seconds) || seconds < 0) {
    throw std::invalid_argument("a timeout must be a finite number of seconds >= 0, got " +
                                std::to_string(seconds));
  }
  return base::Deadline::AfterSeconds(seconds);
}

// What a transport call may wait of a deadline: the time left, at most a century (the control
// client adds it to the clock in nanoseconds, which a longer time would overflow).
std::chrono::milliseconds ForTransport(const base::Deadline& d) {
  constexpr std::int64_t kCenturyMs = 100LL * 365 * 24 * 3600 * 1000;
  return std::chrono::milliseconds(std::min(kCenturyMs, (d.Left().ns + 999'999) / 1'000'000));
}

// A bounded wait's slice: a reader's Wait returns early when data arrives.
constexpr base::Nanos kSlice = base::Milliseconds(20);

std::string Seconds(double s) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%g s", s);
  return buf;
}

// States a request's steps may hold in the server's state outbox at once (it holds at least
// limits::kMinStateOutboxFrames): a lockstep request asks for at most this many steps times
// vehicles, and waits for their states before the next, so the outbox never overflows.
constexpr auto kOutboxFrames = static_cast<std::uint32_t>(limits::kMinStateOutboxFrames / 2);
// With an input, a request carries it again at least this often (steps of 1 ms): the server's
// input watchdog (limits::kDefaultWatchdogMs of simulated time) would otherwise replace an input
// held longer by its safe state.
constexpr auto kInputRepeatSteps = static_cast<std::uint32_t>(limits::kDefaultWatchdogMs / 2);

// A recorder-sized receive buffer: a step's burst of states must not overflow the socket.
constexpr std::size_t kReceiveBufferBytes = std::size_t{16} << 20;

}  // namespace

Client::Client(std::uint32_t domain, const std::string& server_id, double timeout_s,
               const std::string& client_id)
    : server_id_(server_id),
      timeout_s_(timeout_s),
      participant_(domain, kReceiveBufferBytes),
      control_(participant_, client_id),
      view_(participant_, client::SessionView::Topics{.states = false,
                                                      .params = true,
                                                      .world = true,
                                                      .diagnostics = true,
                                                      .inputs = false,
                                                      .only_vehicle = std::nullopt, .only_server = {}}) {
  const base::Deadline deadline = DeadlineIn(timeout_s);
  const std::string who =
      server_id.empty() ? "no vdyn server" : "no vdyn server with the id '" + server_id + "'";
  const std::string where = " on DDS domain " + std::to_string(domain);
  // The world is transient-local: a server's arrives as soon as its writer and this reader match.
  const bool found = base::PollUntil(
      deadline, kSlice,
      [&] {
        view_.Poll();
        const auto& worlds = view_.worlds();
        if (server_id_.empty() && !worlds.empty()) server_id_ = worlds.begin()->first;
        return !server_id_.empty() && worlds.count(server_id_) > 0;
      },
      [&](base::Nanos slice) { (void)view_.Wait(base::Chrono(slice)); });
  if (!found) {
    std::string seen;
    for (const auto& [id, w] : view_.worlds()) seen += (seen.empty() ? "" : ", ") + id;
    throw TimeoutError(
        who + where + " answered within " + Seconds(timeout_s) + ": no world description arrived" +
        (seen.empty() ? " (is vdyn-server running with --domain " + std::to_string(domain) + "?)"
                      : " (worlds seen: " + seen + ")"));
  }
  // Then a request's round trip: that server takes this client's requests and reaches its replies.
  const auto left = std::max(ForTransport(deadline), std::chrono::milliseconds(1));
  if (!control_.WaitForServer(left, server_id_)) {
    throw TimeoutError("server '" + server_id_ + "'" + where + " did not answer within " +
                       Seconds(timeout_s) + ": " + control_.last_error());
  }
  const pb::WorldDescription& w = view_.worlds().at(server_id_);
  if (w.step_ns() > 0) step_ns_ = w.step_ns();
  for (const auto& v : w.vehicles()) vehicles_.insert(v.vehicle_id());
}

Client::~Client() = default;

void Client::PollView() {
  view_.Poll();
}

std::string Client::WorldBytes() {
  std::lock_guard lock(mutex_);
  PollView();
  return view_.worlds().at(server_id_).SerializeAsString();
}

std::uint64_t Client::WorldVersion() {
  std::lock_guard lock(mutex_);
  PollView();
  return view_.world_version();
}

std::vector<std::uint32_t> Client::Vehicles() {
  std::lock_guard lock(mutex_);
  return {vehicles_.begin(), vehicles_.end()};
}

std::string Client::ParamsBytes(std::uint32_t vehicle_id, double timeout_s) {
  std::lock_guard lock(mutex_);
  const pb::VehicleParams* params = nullptr;
  const bool found = base::PollUntil(
      DeadlineIn(timeout_s), kSlice,
      [&] {
        PollView();
        const auto* v = view_.vehicle(vehicle_id);
        if (v != nullptr && v->params) params = &*v->params;
        return params != nullptr;
      },
      [&](base::Nanos slice) { (void)view_.Wait(base::Chrono(slice)); });
  if (!found) {
    throw TimeoutError("no parameters of vehicle " + std::to_string(vehicle_id) +
                       " arrived on vdyn/params within " + Seconds(timeout_s) + " (" +
                       UnknownVehicleNote(vehicle_id, "the server publishes them at its start "
                                                      "and at each change") +
                       ")");
  }
  return params->SerializeAsString();
}

ReplyInfo Client::Request(pb::ControlRequest request, const std::string& what, double timeout_s) {
  std::lock_guard lock(mutex_);
  request.set_server_id(server_id_);
  const bool adds = request.has_spawn() || request.has_restore(), removes = request.has_remove();
  const std::uint32_t vehicle = request.vehicle_id();
  auto reply = control_.Call(std::move(request), ForTransport(DeadlineIn(timeout_s)));
  if (!reply) throw TimeoutError(what + ": " + control_.last_error());
  if (!reply->accepted()) {
    throw RefusedError(what + " refused by server '" + reply->server_id() + "': " + reply->reason(),
                       reply->reason());
  }
  if (adds) {
    vehicles_.insert(vehicle);
    removed_.erase(vehicle);
  }
  if (removes) {
    vehicles_.erase(vehicle);
    removed_.insert(vehicle);
    // The server disposes the vehicle's parameters as it removes it: once that arrives here,
    // params() of it no longer answers with them (bounded: a late dispose only delays that).
    (void)base::PollUntil(
        DeadlineIn(std::min(timeout_s, 5.0)), kSlice,
        [&] {
          PollView();
          const client::SessionView::Vehicle* v = view_.vehicle(vehicle);
          return v == nullptr || !v->params;
        },
        [&](base::Nanos slice) { (void)view_.Wait(base::Chrono(slice)); });
  }
  ReplyInfo info;
  info.server_id = reply->server_id();
  info.applied_step = reply->applied_step();
  info.sim_time_ns = reply->sim_time_ns();
  for (const pb::DiscardedSteps& d : reply->discarded()) {
    info.discarded[d.vehicle_id()] += d.count();
    info.discarded_notes.push_back("vehicle " + std::to_string(d.vehicle_id()) + ": " +
                                   std::to_string(d.count()) + " step(s) discarded by server '" +
                                   reply->server_id() + "', the first its step " +
                                   std::to_string(d.first_step()) + " (no state for them): " +
                                   d.reason());
  }
  info.discarded_not_listed = reply->discarded_not_listed();
  info.steps_without_state = reply->steps_without_state();
  if (info.discarded_not_listed > 0) {
    info.discarded_notes.push_back(std::to_string(info.discarded_not_listed) +
                                   " more step(s) of other vehicles discarded (not listed)");
  }
  return info;
}

std::set<std::uint32_t> Client::KnownVehicles() {
  std::set<std::uint32_t> known = vehicles_;
  PollView();
  for (const auto& [id, v] : view_.vehicles()) {
    if (v.params && removed_.count(id) == 0) known.insert(id);
  }
  return known;
}

std::string Client::UnknownVehicleNote(std::uint32_t vehicle_id, const std::string& otherwise) {
  const std::set<std::uint32_t> known = KnownVehicles();
  if (known.count(vehicle_id) != 0) return otherwise;
  return "server '" + server_id_ + "' has no vehicle " + std::to_string(vehicle_id) + ": " +
         VehicleList(known);
}

std::string Client::VehicleList(const std::set<std::uint32_t>& ids) {
  if (ids.empty()) return "it has none";
  std::string list;
  for (const std::uint32_t id : ids) list += (list.empty() ? "" : ", ") + std::to_string(id);
  return (ids.size() == 1 ? "its vehicle is " : "its vehicles are ") + list;
}

void Client::CheckStepInput(const pb::DriverInput& input) {
  std::lock_guard lock(mutex_);
  const std::set<std::uint32_t> known = KnownVehicles();
  if (known.count(input.vehicle_id()) == 0) {
    throw std::invalid_argument("no vehicle " + std::to_string(input.vehicle_id()) +
                                " on server '" + server_id_ + "' (" + VehicleList(known) +
                                "): nothing was stepped");
  }
  if (const std::string why = messages::WhyInputRefused(input); !why.empty()) {
    throw std::invalid_argument("the input for vehicle " + std::to_string(input.vehicle_id()) +
                                " is one the server would not apply: " + why +
                                "; nothing was stepped");
  }
}

std::uint32_t Client::ChunkSteps(std::uint32_t left, bool with_input) {
  std::lock_guard lock(mutex_);
  const auto vehicles = std::max<std::size_t>(1, vehicles_.size());
  std::uint32_t chunk = std::min<std::uint32_t>(
      left, std::max<std::uint32_t>(1, kOutboxFrames / static_cast<std::uint32_t>(vehicles)));
  if (with_input) chunk = std::min(chunk, kInputRepeatSteps);
  return chunk;
}

void Client::TakeStepStates(StateSource& states, std::uint32_t chunk, const ReplyInfo& reply,
                            const pb::DriverInput* input, double timeout_s,
                            std::map<std::uint32_t, StateTable>& out) {
  // The states of these steps start at these simulation times (the reply: the time after).
  const std::int64_t last = reply.sim_time_ns - step_ns_;
  const std::int64_t first = reply.sim_time_ns - static_cast<std::int64_t>(chunk) * step_ns_;
  // One sample of vdyn/states is one step of every vehicle the server had then: the steps are
  // complete when a sample of each has come, and a vehicle in none of them was not there (removed
  // by another client, or a server that restarted without it); one spawned or removed meanwhile
  // has the states of the steps it was there for.
  std::map<std::uint32_t, std::uint32_t> got;
  std::set<std::int64_t> times;
  auto take = [&] {
    std::lock_guard lock(mutex_);
    (void)states.Take([&](const pb::VehicleState& s) {
      ++received_[s.vehicle_id()];
      if (s.server_id() != server_id_ || s.sim_time_ns() < first || s.sim_time_ns() > last) return;
      out[s.vehicle_id()].Append(s);
      // The newest of each vehicle, for latest(): a lockstep server sends nothing between steps,
      // so a reader made after the step has nothing to give (latest() after step() timed out).
      if (auto [it, fresh] = from_steps_.try_emplace(s.vehicle_id(), s);
          !fresh && s.sim_time_ns() >= it->second.sim_time_ns()) {
        it->second = s;
      }
      ++got[s.vehicle_id()];
      times.insert(s.sim_time_ns());
      vehicles_.insert(s.vehicle_id());
    });
  };
  // A step of which every vehicle's state was discarded has no sample at all: the reply says how
  // many.
  auto without_sample = [&]() -> std::uint32_t { return reply.steps_without_state; };
  auto complete = [&] {
    take();
    return times.size() + without_sample() >= chunk;
  };
  const bool done =
      base::PollUntil(DeadlineIn(timeout_s), base::Milliseconds(50), complete,
                      [&](base::Nanos slice) { (void)states.Wait(base::Chrono(slice)); });
  std::lock_guard lock(mutex_);
  if (done) {
    std::vector<std::uint32_t> absent;
    for (std::uint32_t id : vehicles_) {
      if (got.count(id) == 0 && reply.discarded.count(id) == 0) absent.push_back(id);
    }
    for (std::uint32_t id : absent) vehicles_.erase(id);
    const std::uint32_t driven = input != nullptr ? input->vehicle_id() : 0;
    if (driven != 0 && got.count(driven) == 0 && reply.discarded.count(driven) == 0) {
      throw std::invalid_argument("no vehicle " + std::to_string(driven) + " on server '" +
                                  server_id_ + "': " + std::to_string(chunk) +
                                  " steps ran without it (" + VehicleList(vehicles_) + ")");
    }
    return;
  }
  const std::size_t missing = chunk - std::min<std::size_t>(chunk, times.size() + without_sample());
  throw TimeoutError(
      "the states of " + std::to_string(missing) + " of the last " + std::to_string(chunk) +
      " lockstep steps (simulation time " + std::to_string(static_cast<double>(first) * 1e-9) +
      " s to " + std::to_string(static_cast<double>(last) * 1e-9) + " s) did not arrive within " +
      Seconds(timeout_s) + " of the server's reply" +
      (times.empty() ? ": no vehicle's states at all" : "") +
      " (states lost by this reader so far: " + std::to_string(states.Lost()) + ")");
}

std::map<std::uint32_t, StateTable> Client::Step(std::uint32_t steps, const pb::DriverInput* input,
                                                 double timeout_s,
                                                 std::vector<std::string>* discarded) {
  if (steps == 0) throw std::invalid_argument("steps must be at least 1");
  if (steps > limits::kMaxStepsPerRequest) {
    throw std::invalid_argument("steps must be at most " +
                                std::to_string(limits::kMaxStepsPerRequest) + ", got " +
                                std::to_string(steps));
  }
  (void)DeadlineIn(timeout_s);  // a bad timeout is refused before anything is sent
  if (input != nullptr) CheckStepInput(*input);
  // One step() at a time per client (two threads' steps run one after the other): each takes the
  // states of its own steps from the one reader.
  std::lock_guard one_step(step_mu_);
  std::map<std::uint32_t, StateTable> out;
  StateSource& states = StepStates(timeout_s);
  for (std::uint32_t done = 0; done < steps;) {
    const std::uint32_t chunk = ChunkSteps(steps - done, input != nullptr);
    pb::ControlRequest request;
    request.mutable_step()->set_steps(chunk);
    if (input != nullptr) {
      request.set_vehicle_id(input->vehicle_id());
      *request.mutable_step()->mutable_input() = *input;
    }
    const ReplyInfo reply =
        Request(request, "step " + std::to_string(chunk) + " (lockstep)", timeout_s);
    try {
      TakeStepStates(states, chunk, reply, input, timeout_s, out);
    } catch (const std::invalid_argument& e) {
      if (done == 0) throw;
      // The vehicle went while this call ran (another client removed it): the message said only
      // the last request's steps, a fraction of what ran.
      throw std::invalid_argument(std::string(e.what()) + "; it went during this step() call, " +
                                  std::to_string(done) + " of its " + std::to_string(steps) +
                                  " steps after the start (their states are not returned)");
    }
    if (discarded != nullptr) {
      discarded->insert(discarded->end(), reply.discarded_notes.begin(),
                        reply.discarded_notes.end());
    }
    done += chunk;
  }
  for (auto& [id, table] : out) table.SortByStep();
  return out;
}

std::map<std::uint32_t, StateTable> Client::RunManeuver(const std::string& maneuver,
                                                        std::uint32_t vehicle_id,
                                                        std::optional<double> duration_s,
                                                        const std::string& source_id,
                                                        double timeout_s,
                                                        std::vector<std::string>* discarded) {
  if (duration_s) {
    if (const std::string why = limits::Check(limits::kDurationS, *duration_s); !why.empty()) {
      throw std::invalid_argument("run_maneuver: " + why);
    }
  }
  const Maneuver m = Maneuver::Named(maneuver);  // ManeuverError names the file, line and column
  const double h = static_cast<double>(step_ns_) * 1e-9;  // as the simulator computes its step
  const double end = duration_s ? *duration_s : m.end_time();
  const auto steps = static_cast<std::uint64_t>(std::llround(end / h));
  auto input_at = [&](std::uint64_t k) {
    pb::DriverInput in;
    in.set_vehicle_id(vehicle_id);
    in.set_source_id(source_id);
    client::FillFromManeuver(m.At(static_cast<double>(k) * h), in);
    return in;
  };
  std::map<std::uint32_t, StateTable> out;
  std::uint64_t k = 0;
  while (k < steps) {
    const pb::DriverInput in = input_at(k);
    const std::string bytes = in.SerializeAsString();
    std::uint32_t run = 1;  // the steps from k on whose input is the same
    while (k + run < steps && run < kInputRepeatSteps &&
           input_at(k + run).SerializeAsString() == bytes) {
      ++run;
    }
    for (auto& [id, table] : Step(run, &in, timeout_s, discarded)) out[id].Extend(table);
    k += run;
  }
  return out;
}

StateSource& Client::StepStates(double timeout_s) {
  if (states_) return *states_;
  auto states = std::make_unique<StateSource>(participant_, std::nullopt);
  // The server must know this reader before it steps, or it sends the states to no one.
  if (!transport::WaitUntilServerKnowsReaders(participant_, ForTransport(DeadlineIn(timeout_s)),
                                              server_id_)) {
    throw TimeoutError("server '" + server_id_ +
                       "' did not match this client's reader of the states within " +
                       Seconds(timeout_s) +
                       (timeout_s < 1.0 ? " (a new reader takes some milliseconds to be matched: "
                                          "give the first step() a timeout of a second or more)"
                                        : " (its world did not arrive again)"));
  }
  std::lock_guard lock(mutex_);  // StateReaders() reads it
  states_ = std::move(states);
  return *states_;
}

client::SessionView& Client::LatestView(std::uint32_t vehicle_id) {
  if (auto it = latest_.find(vehicle_id); it != latest_.end()) return *it->second;
  const bool own = latest_.size() < kLatestPartitions;
  if (!own && latest_all_) return *latest_all_;
  auto view = std::make_unique<client::SessionView>(
      participant_,
      client::SessionView::Topics{.states = true,
                                  .params = false,
                                  .world = false,
                                  .diagnostics = false,
                                  .inputs = false,
                                  .only_vehicle = own ? std::optional(vehicle_id) : std::nullopt,
                                  .only_server = server_id_});
  view->on_state = [this](const pb::VehicleState& s, const transport::SampleInfo&) {
    ++received_[s.vehicle_id()];  // Poll() runs with mutex_ held
  };
  if (!own) return *(latest_all_ = std::move(view));
  return *(latest_[vehicle_id] = std::move(view));
}

std::map<std::uint32_t, std::uint64_t> Client::StatesReceived() {
  std::lock_guard lock(mutex_);
  return received_;
}

std::vector<std::string> Client::StateReaders() {
  std::lock_guard lock(mutex_);
  std::vector<std::string> out;
  for (const auto& [id, view] : latest_) {
    const std::string& fallback = view->one_vehicle_fallback();
    out.push_back(
        "vehicle " + std::to_string(id) +
        (fallback.empty() ? " (its partition)" : " (every vehicle's states: " + fallback + ")"));
  }
  if (latest_all_)
    out.push_back("every vehicle (latest, beyond " + std::to_string(kLatestPartitions) +
                  " vehicles)");
  if (states_) out.push_back("every vehicle (steps)");
  return out;
}

StateTable Client::Latest(std::uint32_t vehicle_id, double timeout_s) {
  // Waits without mutex_ (a step() in another thread goes on meanwhile); polls with it (the
  // view's callback counts into received_).
  std::lock_guard one(latest_mu_);
  client::SessionView* view_of = nullptr;
  std::optional<pb::VehicleState> stepped;
  {
    std::lock_guard lock(mutex_);
    view_of = &LatestView(vehicle_id);
    if (const auto it = from_steps_.find(vehicle_id); it != from_steps_.end()) stepped = it->second;
  }
  client::SessionView& view = *view_of;
  std::optional<pb::VehicleState> live;
  auto poll = [&] {
    std::lock_guard lock(mutex_);
    view.Poll();
    if (const client::SessionView::Vehicle* v = view.vehicle(vehicle_id)) live = v->state;
  };
  auto wait = [&](base::Nanos slice) { (void)view.Wait(base::Chrono(slice)); };
  // A state of another start of the server than the step's (it restarted) is the newer one.
  auto newer_than_stepped = [&] {
    return live && (live->incarnation() != stepped->incarnation() ||
                    live->sim_time_ns() > stepped->sim_time_ns());
  };
  // The newest a step() brought, when no newer one comes here within 50 ms (a real-time server
  // sends one a step; a lockstep server none until the next step).
  if (stepped) {
    (void)base::PollUntil(DeadlineIn(std::min(timeout_s, 0.05)), kSlice, [&] {
      poll();
      return newer_than_stepped();
    }, wait);
    if (!newer_than_stepped()) {
      StateTable t;
      t.Append(*stepped);
      return t;
    }
  }
  const bool found = base::PollUntil(DeadlineIn(timeout_s), kSlice, [&] {
    poll();
    return live.has_value();
  }, wait);
  if (!found) {
    std::lock_guard lock(mutex_);
    throw TimeoutError("no state of vehicle " + std::to_string(vehicle_id) +
                       " arrived on vdyn/state within " + Seconds(timeout_s) + " (" +
                       UnknownVehicleNote(vehicle_id,
                                          "a lockstep server publishes states only while it "
                                          "steps, and so does a real-time one that step() or "
                                          "pause() left paused: resume() it") +
                       ")");
  }
  StateTable t;
  t.Append(*live);
  return t;
}

// --- Driver ----------------------------------------------------------------------------------

namespace {

// A driver's vehicle, source and strength, checked as the server checks what it receives: an id
// it would refuse makes every input of this driver one it drops.
const std::string& CheckedSource(std::uint32_t vehicle_id, const std::string& source_id,
                                 std::int32_t strength) {
  if (std::string why = limits::Check(limits::kVehicleId, vehicle_id); !why.empty()) {
    throw std::invalid_argument("driver: " + why);
  }
  if (std::string why = limits::Check(limits::kStrength, strength); !why.empty()) {
    throw std::invalid_argument("driver: " + why);
  }
  pb::DriverInput probe;
  probe.set_vehicle_id(vehicle_id);
  probe.set_source_id(source_id);
  if (std::string why = messages::WhyInputRefused(probe); !why.empty()) {
    throw std::invalid_argument("driver '" + source_id.substr(0, 64) +
                                "': a server would refuse every input of it: " + why);
  }
  return source_id;
}

}  // namespace

Driver::Driver(Client& client, std::uint32_t vehicle_id, const std::string& source_id,
               std::int32_t strength)
    : vehicle_id_(vehicle_id),
      publisher_(client.participant(), vehicle_id, CheckedSource(vehicle_id, source_id, strength),
                 strength) {
  current_.set_vehicle_id(vehicle_id);
}

void Driver::CheckInput(const pb::DriverInput& input) const {
  // The publisher writes this driver's own source id (checked when it was made) over the input's.
  pb::DriverInput sent = input;
  sent.clear_source_id();
  if (const std::string why = messages::WhyInputRefused(sent); !why.empty()) {
    throw std::invalid_argument("the input for vehicle " + std::to_string(vehicle_id_) +
                                " is one the server would not apply: " + why + "; not sent");
  }
}

Driver::~Driver() {
  Stop();
}

void Driver::Send(const pb::DriverInput& input) {
  CheckInput(input);
  std::lock_guard lock(mutex_);
  sending_ = input;
  sending_.set_vehicle_id(vehicle_id_);
  if (!publisher_.Publish(sending_)) {
    throw std::runtime_error("driver input for vehicle " + std::to_string(vehicle_id_) +
                             " not sent: " + publisher_.last_error());
  }
}

void Driver::Set(const pb::DriverInput& input) {
  CheckInput(input);
  std::lock_guard lock(mutex_);
  current_ = input;
  current_.set_vehicle_id(vehicle_id_);
}

void Driver::Start(double rate_hz) {
  if (const std::string why = limits::Check(kDriverRateHz, rate_hz); !why.empty()) {
    throw std::invalid_argument(why);  // "rate_hz must be in [0.0166667, 10000], got 0"
  }
  if (running_.exchange(true)) throw std::runtime_error("the driver is already running");
  const auto period = std::chrono::nanoseconds(std::llround(1e9 / rate_hz));
  thread_ = std::thread([this, period] {
    auto next = std::chrono::steady_clock::now();
    std::unique_lock wait(stop_mu_);
    while (running_.load()) {
      next += period;
      if (stop_cv_.wait_until(wait, next, [this] { return !running_.load(); })) break;
      // Ticks this machine was too busy for are skipped, not sent late in a burst.
      const auto late = std::chrono::steady_clock::now() - next;
      if (late >= period) {
        const auto skipped = late / period;
        skipped_.fetch_add(static_cast<std::uint64_t>(skipped));
        next += skipped * period;
      }
      std::lock_guard lock(mutex_);
      sending_.CopyFrom(current_);  // reuses the message's storage: no allocation once warm
      if (!publisher_.Publish(sending_)) failed_.fetch_add(1);
    }
  });
}

void Driver::Stop() {
  {
    std::lock_guard lock(stop_mu_);
    running_.store(false);
  }
  stop_cv_.notify_all();
  if (thread_.joinable()) thread_.join();
}

std::uint64_t Driver::sent() {
  std::lock_guard lock(mutex_);
  return publisher_.sent();
}

bool Driver::WaitForServer(double timeout_s) {
  return base::PollUntil(
      DeadlineIn(timeout_s), base::Milliseconds(10),
      [&] {
        std::lock_guard lock(mutex_);
        return publisher_.MatchedReaders() > 0;
      },
      // Matching has no waitable event.
      [](base::Nanos slice) { std::this_thread::sleep_for(base::Chrono(slice)); });
}

// --- Subscription -----------------------------------------------------------------------------

Subscription::Subscription(Client& client, std::uint32_t vehicle_id, std::size_t capacity)
    : vehicle_id_(vehicle_id),
      capacity_(capacity),
      server_id_(client.server_id()),
      source_(client.participant(), vehicle_id) {
  if (capacity == 0) throw std::invalid_argument("capacity must be at least 1");
  queue_.Reserve(capacity);
  thread_ = std::thread([this] { Run(); });
}

Subscription::~Subscription() {
  Close();
}

void Subscription::Close() {
  {
    std::lock_guard lock(mutex_);
    stop_.store(true);
  }
  ready_.notify_all();  // a next() waiting in another thread ends now, not at its timeout
  std::lock_guard once(close_mu_);  // two threads closing at once: one joins
  if (thread_.joinable()) thread_.join();
}

void Subscription::Run() {
  const std::size_t columns = StateColumns().size();
  while (!stop_.load()) {
    if (!source_.Wait(std::chrono::milliseconds(50))) continue;
    std::lock_guard lock(mutex_);
    (void)source_.Take([&](const pb::VehicleState& s) {
      if (s.server_id() != server_id_) return;  // another server's vehicle of that id
      received_.fetch_add(1);
      if (incarnation_ && *incarnation_ != s.incarnation()) {
        // Another start of the server: its steps count from 0, nothing between is missing.
        restarts_.fetch_add(1);
        last_step_.reset();
      }
      incarnation_ = s.incarnation();
      if (last_step_ && s.step() > *last_step_ + 1) missing_.fetch_add(s.step() - *last_step_ - 1);
      last_step_ = s.step();
      if (queue_.rows() - head_ >= capacity_) {
        overflowed_.fetch_add(1);
        return;
      }
      if (head_ > 0 && queue_.rows() >= capacity_) {
        // Move the unread rows to the front (the storage stays allocated: memory is flat).
        const std::size_t n = queue_.rows() - head_;
        std::copy(queue_.values.begin() + static_cast<std::ptrdiff_t>(head_ * columns),
                  queue_.values.end(), queue_.values.begin());
        queue_.values.resize(n * columns);
        auto shift = [&](auto& v) {
          std::copy(v.begin() + static_cast<std::ptrdiff_t>(head_), v.end(), v.begin());
          v.resize(n);
        };
        shift(queue_.step);
        shift(queue_.state_hash);
        shift(queue_.sim_time_ns);
        head_ = 0;
      }
      queue_.Append(s);
    });
    ready_.notify_all();
  }
}

std::uint64_t Subscription::dds_lost() {
  std::lock_guard lock(mutex_);
  return source_.Lost();
}

std::size_t Subscription::queued() {
  std::lock_guard lock(mutex_);
  return queue_.rows() - head_;
}

StateTable Subscription::Next(double timeout_s) {
  const base::Deadline deadline = DeadlineIn(timeout_s);
  std::unique_lock lock(mutex_);
  // In slices: a condition variable's wait_for adds its time to the clock, which 1e10 s overflows.
  const bool ready = base::PollUntil(
      deadline, base::Milliseconds(100), [&] { return queue_.rows() > head_ || stop_.load(); },
      [&](base::Nanos slice) { ready_.wait_for(lock, base::Chrono(slice)); });
  if (queue_.rows() <= head_ && stop_.load()) {
    throw TimeoutError("the subscription to vehicle " + std::to_string(vehicle_id_) +
                       " is closed: no state will arrive (take() returns what was queued)");
  }
  if (!ready) {
    throw TimeoutError("no state of vehicle " + std::to_string(vehicle_id_) +
                       " arrived on vdyn/state within " + Seconds(timeout_s));
  }
  const std::size_t c = StateColumns().size();
  StateTable t;
  t.values.assign(queue_.values.begin() + static_cast<std::ptrdiff_t>(head_ * c),
                  queue_.values.begin() + static_cast<std::ptrdiff_t>((head_ + 1) * c));
  t.step.push_back(queue_.step[head_]);
  t.state_hash.push_back(queue_.state_hash[head_]);
  t.sim_time_ns.push_back(queue_.sim_time_ns[head_]);
  ++head_;
  return t;
}

StateTable Subscription::TakeAll() {
  std::lock_guard lock(mutex_);
  const std::size_t c = StateColumns().size();
  StateTable t;
  const auto h = static_cast<std::ptrdiff_t>(head_);
  t.values.assign(queue_.values.begin() + h * static_cast<std::ptrdiff_t>(c), queue_.values.end());
  t.step.assign(queue_.step.begin() + h, queue_.step.end());
  t.state_hash.assign(queue_.state_hash.begin() + h, queue_.state_hash.end());
  t.sim_time_ns.assign(queue_.sim_time_ns.begin() + h, queue_.sim_time_ns.end());
  queue_.values.clear();
  queue_.step.clear();
  queue_.state_hash.clear();
  queue_.sim_time_ns.clear();
  head_ = 0;
  return t;
}

}  // namespace vdyn::python
