#include "client.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "vdyn/base/limits.h"
#include "vdyn/client/loop.h"
#include "vdyn/io/maneuver.h"

namespace vdyn::python {
namespace {

using Clock = std::chrono::steady_clock;

std::chrono::milliseconds Ms(double seconds) {
  if (!std::isfinite(seconds) || seconds < 0) {
    throw std::invalid_argument("a timeout must be a finite number of seconds >= 0, got " +
                                std::to_string(seconds));
  }
  return std::chrono::milliseconds(static_cast<std::int64_t>(std::ceil(seconds * 1e3)));
}

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
                                                      .only_vehicle = std::nullopt}) {
  const auto timeout = Ms(timeout_s);
  const auto deadline = Clock::now() + timeout;
  const std::string who = server_id.empty() ? "no vdyn server" : "server '" + server_id + "'";
  const std::string where = " on DDS domain " + std::to_string(domain);
  // The world is transient-local: a server's arrives as soon as its writer and this reader match.
  for (;;) {
    view_.Poll();
    const auto& worlds = view_.worlds();
    if (server_id_.empty() && !worlds.empty()) server_id_ = worlds.begin()->first;
    if (!server_id_.empty() && worlds.count(server_id_) > 0) break;
    const auto now = Clock::now();
    if (now >= deadline) {
      std::string seen;
      for (const auto& [id, w] : worlds) seen += (seen.empty() ? "" : ", ") + id;
      throw TimeoutError(
          who + where + " answered within " + Seconds(timeout_s) +
          ": no world description arrived" +
          (seen.empty() ? " (is vdyn-server running with --domain " + std::to_string(domain) + "?)"
                        : " (worlds seen: " + seen + ")"));
    }
    (void)view_.Wait(std::min<Clock::duration>(deadline - now, std::chrono::milliseconds(20)));
  }
  // Then a request's round trip: that server takes this client's requests and reaches its replies.
  const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
      std::max<Clock::duration>(deadline - Clock::now(), std::chrono::milliseconds(1)));
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

std::vector<std::uint32_t> Client::Vehicles() {
  std::lock_guard lock(mutex_);
  return {vehicles_.begin(), vehicles_.end()};
}

std::string Client::ParamsBytes(std::uint32_t vehicle_id, double timeout_s) {
  std::lock_guard lock(mutex_);
  const auto deadline = Clock::now() + Ms(timeout_s);
  for (;;) {
    PollView();
    const auto* v = view_.vehicle(vehicle_id);
    if (v != nullptr && v->params) return v->params->SerializeAsString();
    const auto now = Clock::now();
    if (now >= deadline) {
      throw TimeoutError("no parameters of vehicle " + std::to_string(vehicle_id) +
                         " arrived on vdyn/params within " + Seconds(timeout_s));
    }
    (void)view_.Wait(std::min<Clock::duration>(deadline - now, std::chrono::milliseconds(20)));
  }
}

ReplyInfo Client::Request(pb::ControlRequest request, const std::string& what, double timeout_s) {
  std::lock_guard lock(mutex_);
  request.set_server_id(server_id_);
  const bool adds = request.has_spawn() || request.has_restore(), removes = request.has_remove();
  const std::uint32_t vehicle = request.vehicle_id();
  auto reply = control_.Call(std::move(request), Ms(timeout_s));
  if (!reply) throw TimeoutError(what + ": " + control_.last_error());
  if (!reply->accepted()) {
    throw RefusedError(what + " refused by server '" + reply->server_id() + "': " + reply->reason(),
                       reply->reason());
  }
  if (adds) vehicles_.insert(vehicle);
  if (removes) vehicles_.erase(vehicle);
  return {reply->server_id(), reply->applied_step(), reply->sim_time_ns()};
}

std::map<std::uint32_t, StateTable> Client::Step(std::uint32_t steps, const pb::DriverInput* input,
                                                 double timeout_s) {
  if (steps == 0) throw std::invalid_argument("steps must be at least 1");
  if (steps > limits::kMaxStepsPerRequest) {
    throw std::invalid_argument("steps must be at most " +
                                std::to_string(limits::kMaxStepsPerRequest) + ", got " +
                                std::to_string(steps));
  }
  const auto timeout = Ms(timeout_s);
  std::map<std::uint32_t, StateTable> out;
  StateSource& states = StepStates(timeout_s);
  std::uint32_t done = 0;
  while (done < steps) {
    std::uint32_t chunk;
    {
      std::lock_guard lock(mutex_);
      const auto vehicles = std::max<std::size_t>(1, vehicles_.size());
      chunk = std::min<std::uint32_t>(
          steps - done,
          std::max<std::uint32_t>(1, kOutboxFrames / static_cast<std::uint32_t>(vehicles)));
      if (input != nullptr) chunk = std::min(chunk, kInputRepeatSteps);
    }
    pb::ControlRequest request;
    request.mutable_step()->set_steps(chunk);
    if (input != nullptr) {
      request.set_vehicle_id(input->vehicle_id());
      *request.mutable_step()->mutable_input() = *input;
    }
    const ReplyInfo reply =
        Request(request, "step " + std::to_string(chunk) + " (lockstep)", timeout_s);
    std::lock_guard lock(mutex_);
    // The states of these steps start at these simulation times (the reply: the time after).
    const std::int64_t last = reply.sim_time_ns - step_ns_;
    const std::int64_t first = reply.sim_time_ns - static_cast<std::int64_t>(chunk) * step_ns_;
    std::map<std::uint32_t, std::uint32_t> got;
    auto take = [&] {
      (void)states.Take([&](const pb::VehicleState& s) {
        if (s.server_id() != server_id_ || s.sim_time_ns() < first || s.sim_time_ns() > last)
          return;
        out[s.vehicle_id()].Append(s);
        ++got[s.vehicle_id()];
        vehicles_.insert(s.vehicle_id());
      });
    };
    auto complete = [&] {
      if (got.empty()) return false;
      for (std::uint32_t id : vehicles_) {
        if (got[id] < chunk) return false;
      }
      return true;
    };
    const auto deadline = Clock::now() + timeout;
    take();
    while (!complete()) {
      const auto now = Clock::now();
      if (now >= deadline) {
        std::string missing;
        for (std::uint32_t id : vehicles_) {
          if (got[id] >= chunk) continue;
          missing += (missing.empty() ? "" : "; ") + std::string("vehicle ") + std::to_string(id) +
                     ": " + std::to_string(chunk - got[id]) + " of " + std::to_string(chunk);
        }
        if (got.empty() && vehicles_.empty()) missing = "no vehicle's states at all";
        throw TimeoutError(
            "the states of the last " + std::to_string(chunk) +
            " lockstep steps (simulation time " +
            std::to_string(static_cast<double>(first) * 1e-9) + " s to " +
            std::to_string(static_cast<double>(last) * 1e-9) + " s) did not arrive within " +
            Seconds(timeout_s) + " of the server's reply: missing " + missing +
            " (states lost by this reader so far: " + std::to_string(states.Lost()) + ")");
      }
      (void)states.Wait(std::min<Clock::duration>(deadline - now, std::chrono::milliseconds(50)));
      take();
    }
    done += chunk;
  }
  for (auto& [id, table] : out) table.SortByStep();
  return out;
}

std::map<std::uint32_t, StateTable> Client::RunManeuver(const std::string& maneuver,
                                                        std::uint32_t vehicle_id, double duration_s,
                                                        const std::string& source_id,
                                                        double timeout_s) {
  const Maneuver m = Maneuver::Named(maneuver);  // ManeuverError names the file, line and column
  if (!std::isfinite(duration_s)) throw std::invalid_argument("duration must be finite");
  const double h = static_cast<double>(step_ns_) * 1e-9;  // as the simulator computes its step
  const double end = duration_s > 0 ? duration_s : m.end_time();
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
    for (auto& [id, table] : Step(run, &in, timeout_s)) out[id].Extend(table);
    k += run;
  }
  return out;
}

StateSource& Client::StepStates(double timeout_s) {
  if (states_) return *states_;
  auto states = std::make_unique<StateSource>(participant_, std::nullopt);
  // The server must know this reader before it steps, or it sends the states to no one.
  if (!transport::WaitUntilServerKnowsReaders(participant_, Ms(timeout_s), server_id_)) {
    throw TimeoutError("server '" + server_id_ + "' did not match this client's reader of the states within " +
                       Seconds(timeout_s) + " (its world did not arrive again)");
  }
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
                                  .only_vehicle = own ? std::optional(vehicle_id) : std::nullopt});
  if (!own) return *(latest_all_ = std::move(view));
  return *(latest_[vehicle_id] = std::move(view));
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
  std::lock_guard lock(mutex_);
  client::SessionView& view = LatestView(vehicle_id);
  const auto deadline = Clock::now() + Ms(timeout_s);
  for (;;) {
    view.Poll();
    if (const auto* v = view.vehicle(vehicle_id)) {
      StateTable t;
      t.Append(v->state);
      return t;
    }
    const auto now = Clock::now();
    if (now >= deadline) {
      throw TimeoutError("no state of vehicle " + std::to_string(vehicle_id) +
                         " arrived on vdyn/state within " + Seconds(timeout_s) +
                         " (a lockstep server publishes states only while it steps)");
    }
    (void)view.Wait(std::min<Clock::duration>(deadline - now, std::chrono::milliseconds(20)));
  }
}

// --- Driver ----------------------------------------------------------------------------------

Driver::Driver(Client& client, std::uint32_t vehicle_id, const std::string& source_id,
               std::int32_t strength)
    : vehicle_id_(vehicle_id), publisher_(client.participant(), vehicle_id, source_id, strength) {
  current_.set_vehicle_id(vehicle_id);
}

Driver::~Driver() {
  Stop();
}

void Driver::Send(const pb::DriverInput& input) {
  std::lock_guard lock(mutex_);
  sending_ = input;
  sending_.set_vehicle_id(vehicle_id_);
  if (!publisher_.Publish(sending_)) {
    throw std::runtime_error("driver input for vehicle " + std::to_string(vehicle_id_) +
                             " not sent: " + publisher_.last_error());
  }
}

void Driver::Set(const pb::DriverInput& input) {
  std::lock_guard lock(mutex_);
  current_ = input;
  current_.set_vehicle_id(vehicle_id_);
}

void Driver::Start(double rate_hz) {
  if (!std::isfinite(rate_hz) || rate_hz <= 0 || rate_hz > 10'000) {
    throw std::invalid_argument("rate_hz must be in (0, 10000], got " + std::to_string(rate_hz));
  }
  if (running_.exchange(true)) throw std::runtime_error("the driver is already running");
  const base::Nanos period{static_cast<std::int64_t>(std::llround(1e9 / rate_hz))};
  thread_ = std::thread([this, period] {
    client::FixedRateLoop loop(period);
    while (running_.load()) {
      const auto tick = loop.Wait();
      skipped_.fetch_add(tick.skipped);
      std::lock_guard lock(mutex_);
      sending_.CopyFrom(current_);  // reuses the message's storage: no allocation once warm
      if (!publisher_.Publish(sending_)) failed_.fetch_add(1);
    }
  });
}

void Driver::Stop() {
  running_.store(false);
  if (thread_.joinable()) thread_.join();
}

std::uint64_t Driver::sent() {
  std::lock_guard lock(mutex_);
  return publisher_.sent();
}

bool Driver::WaitForServer(double timeout_s) {
  const auto deadline = Clock::now() + Ms(timeout_s);
  std::unique_lock lock(mutex_);
  while (publisher_.MatchedReaders() == 0) {
    if (Clock::now() >= deadline) return false;
    lock.unlock();
    std::this_thread::sleep_for(std::chrono::milliseconds(10));  // matching has no waitable event
    lock.lock();
  }
  return true;
}

// --- Subscription -----------------------------------------------------------------------------

Subscription::Subscription(Client& client, std::uint32_t vehicle_id, std::size_t capacity)
    : vehicle_id_(vehicle_id), capacity_(capacity), source_(client.participant(), vehicle_id) {
  if (capacity == 0) throw std::invalid_argument("capacity must be at least 1");
  queue_.Reserve(capacity);
  thread_ = std::thread([this] { Run(); });
}

Subscription::~Subscription() {
  Close();
}

void Subscription::Close() {
  stop_.store(true);
  if (thread_.joinable()) thread_.join();
}

void Subscription::Run() {
  const std::size_t columns = StateColumns().size();
  while (!stop_.load()) {
    if (!source_.Wait(std::chrono::milliseconds(50))) continue;
    std::lock_guard lock(mutex_);
    (void)source_.Take([&](const pb::VehicleState& s) {
      received_.fetch_add(1);
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
  std::unique_lock lock(mutex_);
  if (!ready_.wait_for(lock, Ms(timeout_s), [&] { return queue_.rows() > head_; })) {
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
