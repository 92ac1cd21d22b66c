#include "vdyn/runtime/server_node.h"

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <set>
#include <thread>

#include <spdlog/spdlog.h>

#include "vdyn/base/limits.h"
#include "vdyn/base/scheduling.h"
#include "vdyn/base/text.h"
#include "vdyn/bridge/convert.h"
#include "vdyn/bridge/params.h"
#include "vdyn/messages/checks.h"
#include "vdyn/runtime/placement.h"

namespace vdyn {

using transport::TopicId;

namespace {
constexpr TopicId kReliableTopics[] = {TopicId::kControlReply, TopicId::kParams, TopicId::kWorld,
                                       TopicId::kEvents, TopicId::kDiagnostics};
// Step requests waiting for their steps; more wait in the queue until some are done.
constexpr std::size_t kMaxDeferred = 256;
// The most events one request makes (a restore: input changes, removed, spawned, applied): a
// request waits rather than lose one (a re-simulation needs them all).
constexpr std::size_t kEventsPerRequest = 4;
// Room in the event queue kept for the steps' own events (input changes, checkpoints): requests
// wait while the publisher is further behind than this.
constexpr std::size_t kEventsForSteps = 1024;
}  // namespace

ServerNode::ServerNode(std::shared_ptr<const World> world, ServerOptions options)
    : world_(std::move(world)),
      options_(std::move(options)),
      participant_(options_.domain_id, transport::ParticipantOptions{0, Claim(false).Encode()}),
      input_reader_(participant_, TopicId::kInput, &drops_),
      control_reader_(participant_, TopicId::kControl, &drops_) {
  writers_.resize(8);
  for (TopicId t : kReliableTopics) {
    writers_[static_cast<int>(t)] = std::make_unique<transport::RawWriter>(participant_, t);
  }
  drop_rebase_ = drops_.Register("schedule rebased: more than max_lag_steps behind");
  drop_events_full_ = drops_.Register("event queue full, event lost");
  drop_outbox_full_ = drops_.Register("publisher queue full, not sent");
  drop_inputs_full_ = drops_.Register("input queue full, input dropped");
  drop_key_mismatch_ = drops_.Register("key mismatch on vdyn/input");
  drop_out_of_range_ = drops_.Register("out-of-range input on vdyn/input");
  drop_rejected_ = drops_.Register("rejected control request");
  drop_step_input_ = drops_.Register("out-of-range input in a step request");
  // Checked by the receiver or the planner before: never expected, counted should it happen.
  drop_session_refused_input_ = drops_.Register("input the session refused after its checks");
  drop_unknown_buttons_ = drops_.Register("unknown button bits on vdyn/input (ignored)");
  drop_unanswered_gone_ = drops_.Register(
      "control request unanswered: its client went away before its steps were done");
  drop_unanswered_write_ =
      drops_.Register("control request unanswered: the reply could not be written");
  drop_unanswered_stopped_ = drops_.Register(
      "control request unanswered: the server stopped before the reply was written");
  drop_unanswered_room_ = drops_.Register("control request unanswered: no room to hand it on");

  if (const std::string clash = FindClash(); !clash.empty()) throw std::runtime_error(clash);
  // This start of the server: its states, events and world carry it, so that a recording of a
  // server restarted with the same id tells the two starts apart.
  if (options_.session.incarnation == 0) {
    options_.session.incarnation = static_cast<std::uint64_t>(base::WallNow().ns);
  }
  // From here on this server runs its vehicles: a server that starts later gives way to it.
  if (!participant_.SetUserData(Claim(true).Encode())) {
    spdlog::warn("server '{}': cannot announce that it runs its vehicles: {}",
                 options_.session.server_id, participant_.last_error());
  }
  session_ = std::make_unique<Session>(world_, options_.session,
                                       [this](SessionEventRecord&& r) { OnEvent(std::move(r)); });
  // 64 steps of as many vehicles as it may run (at least 512 frames of a page each): the writer
  // thread may stall for tens of ms while a session starts (discovery, the world, every
  // vehicle's parameters), and at 256 vehicles on two cores the stepping threads (real-time
  // scheduling) leave it little CPU while they catch up after a late tick (up to ~15 steps).
  states_ = std::make_unique<StateOutbox>(
      participant_, drops_, transport::ServerKey(options_.session.server_id),
      std::max<std::size_t>(
          limits::kMinStateOutboxFrames,
          64 * std::max(options_.vehicle_ids.size(), options_.session.max_vehicles)),
      options_.vehicle_ids);
  // The world first (transient-local: viewers joining later get it), then the vehicles.
  auto world_msg = std::make_unique<pb::WorldDescription>(
      DescribeWorld(*world_, options_.session.server_id, options_.session.step_ns));
  world_msg->set_incarnation(options_.session.incarnation);
  // Side by side on the free ground around the spawn (placement.h).
  const std::vector<Pose2> poses =
      StartPoses(*world_, ParamsFromProto(options_.session.default_params).get(),
                 options_.vehicle_ids.size());
  for (std::size_t i = 0; i < options_.vehicle_ids.size(); ++i) {
    session_->Spawn(options_.vehicle_ids[i], poses[i], options_.start_speed_mps,
                    pb::VehicleParams());
    *world_msg->add_vehicles() =
        DescribeVehicle(options_.vehicle_ids[i], session_->simulator(options_.vehicle_ids[i]).params());
  }
  Send(TopicId::kWorld, transport::ServerKey(options_.session.server_id), std::move(world_msg));
  deferred_step_replies_.reserve(kMaxDeferred);
  // Each report slot holds room for the most vehicles the session may run: the loop fills one in
  // place, allocating nothing and leaving no vehicle out.
  const std::size_t most = std::max(options_.vehicle_ids.size(), options_.session.max_vehicles);
  for (std::size_t k = 0; k < reports_.capacity(); ++k) reports_.Slot(k)->vehicles.resize(most);
  planner_ = std::make_unique<RequestPlanner>(world_, options_.session);
  planner_->Sync(*session_);
  // Last: if anything above throws, no thread is left running.
  publisher_ = std::thread([this] { PublisherLoop(); });
  requests_ = std::thread([this] { RequestLoop(); });
  receiver_ = std::thread([this] { ReceiverLoop(); });
}

ServerNode::~ServerNode() {
  receiver_stop_ = true;
  if (receiver_.joinable()) receiver_.join();
  requests_stop_ = true;
  request_bell_.Ring();
  if (requests_.joinable()) requests_.join();
  if (publisher_.joinable()) {
    if (publisher_deadline_ns_.load() == 0) {
      publisher_deadline_ns_ = (base::MonotonicNow() + base::Milliseconds(200)).ns;
    }
    publisher_stop_ = true;
    publisher_bell_.Ring();
    publisher_.join();
  }
}

// --- loop thread ---------------------------------------------------------------------------------

void ServerNode::Send(TopicId topic, std::uint32_t key,
                      std::unique_ptr<google::protobuf::Message> msg) {
  Outgoing o{topic, key, std::move(msg)};
  if (!outbox_.TryPush(std::move(o))) {
    drops_.Count(drop_outbox_full_, transport::Spec(topic).name);
    return;
  }
  publisher_bell_.Ring();
}

void ServerNode::OnEvent(SessionEventRecord&& r) {
  if (!events_.TryPush(std::move(r))) {
    drops_.Count(drop_events_full_);
    return;
  }
  publisher_bell_.Ring();
}

void ServerNode::Answer(RequestOutcome&& o) {
  // Room is checked before a request is taken; were it not there, the request is counted, not
  // lost silently.
  if (!outcomes_.TryPush(std::move(o))) NoRoomToAnswer();
}

void ServerNode::NoRoomToAnswer() {
  requests_unanswered_.fetch_add(1, std::memory_order_relaxed);
  drops_.Count(drop_unanswered_room_);
}

bool ServerNode::Boundary() {
  bool applied = false;
  const base::MonoTime t0 = prepared_.Front() != nullptr ? base::MonotonicNow() : base::MonoTime{};
  // At most 16 requests per step boundary, each a swap (the request thread made it ready): a
  // burst waits in the queue instead of stretching one step of the 1 kHz loop. A request is taken
  // only when its answers have room: its own, and every step request a pause may cancel.
  for (int n = 0; n < limits::kMaxRequestsPerBoundary; ++n) {
    std::unique_ptr<PreparedRequest>* front = prepared_.Front();
    if (front == nullptr) break;
    PreparedRequest& p = **front;
    if (OutcomeRoom() < 1 + deferred_step_replies_.size() || spent_.capacity() == spent_.size() ||
        events_.capacity() - events_.size() < kEventsPerRequest + kEventsForSteps) {
      break;
    }
    const bool step = p.op == PreparedRequest::Op::kStep;
    if (step && deferred_step_replies_.size() == kMaxDeferred) break;
    if (step && p.step_input && !session_->OfferInput(p.request->step().input(), nullptr)) {
      drops_.Count(drop_session_refused_input_);
    }
    RequestOutcome o = session_->Commit(p);
    if (step && o.accepted) {
      // Answered when its steps are done: the ones pending before it, then its own.
      deferred_step_replies_.push_back({p.steps, p.client, std::move(o)});
    } else {
      const bool pause = p.op == PreparedRequest::Op::kPause;
      if ((pause || p.op == PreparedRequest::Op::kResume) && o.accepted) {
        CancelStepReplies(pause ? RequestOutcome::Why::kCancelledByPause
                                : RequestOutcome::Why::kCancelledByResume);
      }
      Answer(std::move(o));
    }
    // Back to the request thread, with what the swap replaced: freed there.
    std::unique_ptr<PreparedRequest> spent = std::move(*front);
    prepared_.Pop();
    // Room checked above; were it not there, it is freed here rather than lost.
    if (!spent_.TryPush(std::move(spent))) spent.reset();
    applied = true;
  }
  if (applied) {
    request_boundaries_.Add((base::MonotonicNow() - t0).micros());
    publisher_bell_.Ring();
    request_bell_.Ring();
  }
  // A client that went away is taken once every step it may be owed can be answered (else at a
  // later boundary, when the publisher has caught up).
  std::uint64_t gone = 0;
  while (OutcomeRoom() >= deferred_step_replies_.size() && gone_clients_.TryPop(gone)) {
    ClientGone(gone);
  }
  // Inputs were checked by the receiver (key, ranges); the newest of each vehicle wins.
  while (pb::DriverInput* in = inputs_.Front()) {
    if (session_->HasVehicle(in->vehicle_id()) && !session_->OfferInput(*in, nullptr)) {
      drops_.Count(drop_session_refused_input_);
    }
    inputs_.Pop();
  }
  return applied;
}

void ServerNode::StepOnce() {
  session_->StepInto(*states_);  // each state encoded into its frame by its stepping thread
  states_->Send();
  sim_time_ns_.store(session_->steps() * session_->step_ns(), std::memory_order_relaxed);
  if (session_->paused() && session_->pending_steps() > 0) {
    session_->ConsumePendingStep();
    if (!deferred_step_replies_.empty() && deferred_step_replies_.front().remaining > 0) {
      DeferredReply& running = deferred_step_replies_.front();
      --running.remaining;
      // A discarded step published no state: the reply says whose, so that a client waiting
      // for every state of these steps knows which will not come.
      bool any_state = false;
      for (const auto& [id, v] : session_->vehicles()) {
        if (v.step_status != StepStatus::kOk) {
          running.outcome.AddDiscarded(id, v.sim->state().step - 1, v.step_status);
        } else {
          any_state = true;
        }
      }
      if (!any_state && !session_->vehicles().empty()) ++running.outcome.steps_without_state;
    }
  }
  if (!deferred_step_replies_.empty()) SendDueStepReplies();
}

void ServerNode::SendDueStepReplies() {
  // The requests are served in order: the first one's steps run first. An answer without room
  // now goes at a later boundary.
  std::size_t done = 0;
  while (done < deferred_step_replies_.size() && deferred_step_replies_[done].remaining == 0 &&
         OutcomeRoom() > 0) {
    RequestOutcome& o = deferred_step_replies_[done].outcome;
    const std::uint32_t id = o.request->vehicle_id();
    if (session_->HasVehicle(id)) o.applied_step = session_->simulator(id).state().step;
    o.sim_time_ns = session_->steps() * session_->step_ns();
    Answer(std::move(o));
    ++done;
  }
  if (done == 0) return;
  deferred_step_replies_.erase(deferred_step_replies_.begin(),
                               deferred_step_replies_.begin() + static_cast<std::ptrdiff_t>(done));
  publisher_bell_.Ring();
}

void ServerNode::ClientGone(std::uint64_t writer) {
  // The steps a client asked for, and that have not run, are dropped with it: a long step
  // request does not outlive the client that wanted it. Its outcome says so (the publisher tells
  // the operator); no reply is written for a client that is gone.
  std::uint32_t dropped = 0;
  for (auto it = deferred_step_replies_.begin(); it != deferred_step_replies_.end();) {
    if (it->writer == writer) {  // room checked before (Boundary)
      dropped += it->remaining;
      RequestOutcome& o = it->outcome;
      o.accepted = false;
      o.why = RequestOutcome::Why::kClientGone;
      o.steps_not_run = it->remaining;
      o.sim_time_ns = session_->steps() * session_->step_ns();
      Answer(std::move(o));
      it = deferred_step_replies_.erase(it);
    } else {
      ++it;
    }
  }
  if (dropped > 0) {
    session_->CancelPendingSteps(dropped);
    publisher_bell_.Ring();
  }
  if (!deferred_step_replies_.empty()) SendDueStepReplies();
}

void ServerNode::CancelStepReplies(RequestOutcome::Why why) {
  for (DeferredReply& d : deferred_step_replies_) {
    d.outcome.accepted = false;
    d.outcome.why = why;
    d.outcome.sim_time_ns = session_->steps() * session_->step_ns();
    Answer(std::move(d.outcome));
  }
  deferred_step_replies_.clear();
}

void ServerNode::AnswerWhatIsLeft() {
  // On the loop's thread once the loop has ended and the request thread has stopped: the steps
  // still owed, and the requests that never reached the loop, are answered. Bounded: what the
  // publisher cannot take by the shutdown deadline is counted as unanswered.
  const base::MonoTime give_up =
      base::MonotonicNow() +
      options_.shutdown_deadline;
  auto answer = [&](RequestOutcome&& o) {
    while (!outcomes_.TryPush(std::move(o))) {
      publisher_bell_.Ring();
      if (base::MonotonicNow() >= give_up) {
        requests_unanswered_.fetch_add(1);
        drops_.Count(drop_unanswered_stopped_);
        return;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
  };
  for (DeferredReply& d : deferred_step_replies_) {
    d.outcome.accepted = false;
    d.outcome.why = RequestOutcome::Why::kStopped;
    d.outcome.sim_time_ns = session_->steps() * session_->step_ns();
    answer(std::move(d.outcome));
  }
  deferred_step_replies_.clear();
  std::unique_ptr<PreparedRequest> p;
  while (prepared_.TryPop(p)) {
    RequestOutcome o;
    o.request = p->request;
    o.why = RequestOutcome::Why::kText;
    o.text = "the server is stopping: the request was not applied";
    o.sim_time_ns = session_->steps() * session_->step_ns();
    answer(std::move(o));
  }
  publisher_bell_.Ring();
}

void ServerNode::PushReport(base::MonoTime now) {
  const base::Nanos cpu = base::ProcessCpuTime();
  if (WindowReport* r = reports_.Reserve()) {
    r->wall_ns = (now - window_start_).ns;
    r->cpu_ns = (cpu - window_start_cpu_).ns;
    r->sim_time_ns = session_->steps() * session_->step_ns();
    r->steps = session_->steps();
    r->window_steps = session_->steps() - window_start_steps_;
    r->steps_caught_up = steps_caught_up_;
    r->max_lag_steps = max_lag_steps_seen_;
    r->lateness = lateness_;
    r->n_vehicles = 0;
    session_->ForEachVehicle([&](std::uint32_t id) {
      // Room for the most vehicles the session may run (made in the constructor).
      if (r->n_vehicles >= r->vehicles.size()) return;
      VehicleReport& v = r->vehicles[r->n_vehicles++];
      const Simulator& sim = session_->simulator(id);
      v.id = id;
      v.safe_state = session_->in_safe_state(id);
      const double age = session_->input_age_s(id);
      v.input_age_ms = std::isfinite(age) ? age * 1000.0 : -1.0;
      const std::string& src = session_->input_source(id);
      const std::size_t n = std::min(src.size(), sizeof v.source - 1);
      std::memcpy(v.source, src.data(), n);
      v.source[n] = '\0';
      v.nonfinite_steps = sim.nonfinite_steps();
      v.under_ground_steps = sim.under_ground_steps();
      v.runaway_steps = sim.runaway_steps();
      v.sanitized_inputs = sim.sanitized_inputs();
      v.invariant_failures = sim.invariant_failures();
      std::snprintf(v.last_invariant_failure, sizeof v.last_invariant_failure, "%s",
                    sim.last_invariant_failure());
      v.speed_kmh = Velocity(sim.state().x).norm() * 3.6;
    });
    reports_.Commit();
    publisher_bell_.Ring();
  }
  lateness_.Clear();
  window_start_ = now;
  window_start_cpu_ = cpu;
  window_start_steps_ = session_->steps();
}

int ServerNode::RunRealtime(const std::atomic<bool>& stop) {
  std::string scheduling = base::SetUpRealtimeScheduling(options_.rt_priority);
  // The stepping workers wait on the loop and the loop on them: they share its scheduling.
  if (session_->step_threads() > 1 && scheduling.rfind("SCHED_FIFO", 0) == 0) {
    const std::string refused = session_->SetStepThreadsPriority(options_.rt_priority);
    if (!refused.empty()) scheduling += "; stepping workers: " + refused;
  }
  scheduling_ =
      scheduling + "; " + std::to_string(session_->step_threads()) + " stepping thread(s); " +
      (options_.state_writer_nice != 0 ? states_->SetWriterNice(options_.state_writer_nice)
                                       : states_->WriterNice());
  const std::int64_t h = options_.session.step_ns;
  const std::int64_t end_steps =
      options_.duration.ns > 0
          ? std::llround(static_cast<double>(options_.duration.ns) / static_cast<double>(h))
          : 0;
  spdlog::info("server '{}': real time on domain {}, {} vehicle(s), step {} ms; {}",
               options_.session.server_id, options_.domain_id, session_->vehicle_count(),
               static_cast<double>(h) * 1e-6, scheduling_);
  const base::MonoTime start = base::MonotonicNow();
  const base::Nanos start_cpu = base::ProcessCpuTime();
  base::MonoTime next = start + base::Nanos{h};  // the deadline of step k is start + (k + 1) h
  window_start_ = start;
  window_start_cpu_ = start_cpu;
  while (!stop.load(std::memory_order_relaxed)) {
    base::SleepUntil(next);
    base::MonoTime now = base::MonotonicNow();
    // Run every step whose deadline has passed: simulation time advances in exact steps and
    // catches up after a late wake-up; no step is skipped.
    int run_this_wake = 0;
    while (now >= next && !stop.load(std::memory_order_relaxed)) {
      const double late_us = (now - next).micros();
      lateness_.Add(static_cast<float>(late_us));
      lateness_all_.Add(late_us);
      Boundary();
      if (!session_->paused() || session_->pending_steps() > 0) StepOnce();
      next = next + base::Nanos{h};
      if (++run_this_wake > 1) ++steps_caught_up_;
      now = base::MonotonicNow();
      const std::int64_t lag = (now - next).ns / h;
      if (lag > 0) max_lag_steps_seen_ = std::max<std::uint64_t>(max_lag_steps_seen_, lag);
      if (lag > options_.max_lag_steps) {
        // The machine cannot keep up: start the schedule afresh from now (wall time is dropped,
        // never a step) and say so.
        ++schedule_rebases_;
        drops_.Count(drop_rebase_);
        next = now + base::Nanos{h};
      }
      if (end_steps > 0 && session_->steps() >= end_steps) break;
    }
    if ((now - window_start_).ns >= 1'000'000'000) PushReport(now);
    if (end_steps > 0 && session_->steps() >= end_steps) break;
  }
  const base::MonoTime end = base::MonotonicNow();
  PushReport(end);
  spdlog::info("server '{}': {} steps in {:.3f} s of wall time; tick lateness p50 {:.0f} us, p99 "
               "{:.0f} us, max {:.0f} us; {} steps caught up; drift {:.3f} ms",
               options_.session.server_id, session_->steps(), (end - start).seconds(),
               lateness_all_.Percentile(50), lateness_all_.Percentile(99), lateness_all_.Max(),
               steps_caught_up_,
               (static_cast<double>(session_->steps() * session_->step_ns()) -
                static_cast<double>((end - start).ns)) * 1e-6);
  if (!options_.stats_out.empty()) {
    (void)states_->Drain(base::Milliseconds(500));  // so that states_written is complete
    WriteStats(start, end, start_cpu);
  }
  return 0;
}

void ServerNode::WriteStats(base::MonoTime start, base::MonoTime end, base::Nanos start_cpu) const {
  std::FILE* f = std::fopen(options_.stats_out.c_str(), "w");
  if (f == nullptr) {
    spdlog::error("cannot write the run summary to {}: {}", options_.stats_out,
                  std::strerror(errno));
    return;
  }
  const double wall_s = (end - start).seconds();
  const double sim_s = static_cast<double>(session_->steps()) *
                       static_cast<double>(session_->step_ns()) * 1e-9;
  // Steps whose deadline passed by the end but that never ran (a rebase drops wall time).
  const auto due = static_cast<std::int64_t>((end - start).ns / session_->step_ns());
  std::fprintf(f, "ticks %llu\n", static_cast<unsigned long long>(lateness_all_.count()));
  std::fprintf(f, "steps %lld\n", static_cast<long long>(session_->steps()));
  std::fprintf(f, "steps_due %lld\n", static_cast<long long>(due));
  std::fprintf(f, "lateness_p50_us %.1f\n", lateness_all_.Percentile(50));
  std::fprintf(f, "lateness_p99_us %.1f\n", lateness_all_.Percentile(99));
  std::fprintf(f, "lateness_p999_us %.1f\n", lateness_all_.Percentile(99.9));
  std::fprintf(f, "lateness_max_us %.1f\n", lateness_all_.Max());
  std::fprintf(f, "fraction_under_1ms %.6f\n", lateness_all_.FractionBelow(1000.0));
  std::fprintf(f, "steps_caught_up %llu\n", static_cast<unsigned long long>(steps_caught_up_));
  std::fprintf(f, "max_lag_steps %llu\n", static_cast<unsigned long long>(max_lag_steps_seen_));
  std::fprintf(f, "schedule_rebases %llu\n", static_cast<unsigned long long>(schedule_rebases_));
  std::fprintf(f, "wall_s %.6f\n", wall_s);
  std::fprintf(f, "sim_s %.6f\n", sim_s);
  std::fprintf(f, "drift_ms %.3f\n", (sim_s - wall_s) * 1e3);
  std::fprintf(f, "cpu_percent %.2f\n",
               100.0 * (base::ProcessCpuTime() - start_cpu).seconds() / wall_s);
  std::fprintf(f, "scheduling %s\n", scheduling_.c_str());
  // Every state a step made: handed to the state writer, or refused there (queue full).
  std::fprintf(f, "states_pushed %llu\n", static_cast<unsigned long long>(states_->pushed()));
  std::fprintf(f, "states_refused %llu\n", static_cast<unsigned long long>(states_->refused()));
  // Of those handed over, written by the state writer by the time of this summary, and writes
  // that failed.
  std::fprintf(f, "states_written %llu\n", static_cast<unsigned long long>(states_->written()));
  std::fprintf(f, "state_write_failures %llu\n",
               static_cast<unsigned long long>(states_->write_failures()));
  // The state writer's rounds: the loop's hand-over to the writer's wake-up, then its writes.
  const StateOutbox::Times t = states_->WriterTimes();
  std::fprintf(f, "state_rounds %llu\n", static_cast<unsigned long long>(t.rounds));
  std::fprintf(f, "state_wake_p50_us %.1f\nstate_wake_p99_us %.1f\n", t.wake_p50, t.wake_p99);
  std::fprintf(f, "state_send_p50_us %.1f\nstate_send_p99_us %.1f\n", t.send_p50, t.send_p99);
  std::fprintf(f, "state_send_cpu_p50_us %.1f\nstate_send_cpu_p99_us %.1f\n", t.send_cpu_p50,
               t.send_cpu_p99);
  std::fprintf(f, "step_threads %d\n", session_->step_threads());
  // The boundaries that applied requests, and how long the requests held each.
  std::fprintf(f, "request_boundaries %llu\n",
               static_cast<unsigned long long>(request_boundaries_.count()));
  std::fprintf(f, "request_boundary_p50_us %.1f\n", request_boundaries_.Percentile(50));
  std::fprintf(f, "request_boundary_p99_us %.1f\n", request_boundaries_.Percentile(99));
  std::fprintf(f, "request_boundary_max_us %.1f\n", request_boundaries_.Max());
  std::fprintf(f, "requests_received %llu\n",
               static_cast<unsigned long long>(requests_received_.load()));
  std::fprintf(f, "replies_sent %llu\n", static_cast<unsigned long long>(replies_sent_.load()));
  std::fprintf(f, "requests_unanswered %llu\n",
               static_cast<unsigned long long>(requests_unanswered_.load()));
  if (std::fclose(f) != 0) spdlog::error("writing the run summary {} failed", options_.stats_out);
}

int ServerNode::RunLockstep(const std::atomic<bool>& stop) {
  scheduling_ = "lockstep (no clock)";
  spdlog::info("server '{}': lockstep on domain {}; steps run on request", options_.session.server_id,
               options_.domain_id);
  // Lockstep starts paused: steps run only on request.
  const pb::ControlReply paused = session_->Apply([] {
    pb::ControlRequest r;
    r.mutable_pause();
    return r;
  }());
  if (!paused.accepted())
    throw std::logic_error("the session refused to pause: " + paused.reason());
  window_start_ = base::MonotonicNow();
  window_start_cpu_ = base::ProcessCpuTime();
  base::MonoTime last_request = base::MonotonicNow();
  const base::Nanos timeout = options_.lockstep_timeout;
  while (!stop.load(std::memory_order_relaxed)) {
    const std::uint32_t token = loop_bell_.Token();
    // The client is silent only while no request comes and no steps it asked for are running.
    if (Boundary()) last_request = base::MonotonicNow();
    while (session_->pending_steps() > 0 && !stop.load(std::memory_order_relaxed)) {
      StepOnce();
      Boundary();
      last_request = base::MonotonicNow();
      const base::MonoTime now = base::MonotonicNow();
      if ((now - window_start_).ns >= 1'000'000'000) PushReport(now);
    }
    const base::MonoTime now = base::MonotonicNow();
    // A request the loop never saw (refused on its way) is a sign of life too.
    last_request = std::max(last_request, base::MonoTime{last_request_ns_.load()});
    if ((now - window_start_).ns >= 1'000'000'000) PushReport(now);
    if (now - last_request > timeout) {
      spdlog::error("lockstep: no control request for {} s; the client is gone? stopping",
                    base::FormatApprox(options_.lockstep_timeout.seconds()));
      return 3;
    }
    if (prepared_.empty() && inputs_.empty()) loop_bell_.Wait(token, base::Milliseconds(20));
  }
  return 0;
}

int ServerNode::Run(const std::atomic<bool>& stop) {
  const int code = options_.mode == ServerOptions::Mode::kRealtime ? RunRealtime(stop)
                                                                    : RunLockstep(stop);
  session_->FlushEvents();
  if (!states_->Drain(base::Milliseconds(500))) {
    spdlog::warn("server '{}': stopping with {} state(s) not yet written on vdyn/state",
                 options_.session.server_id, states_->pushed() - states_->written() - states_->write_failures());
  }
  // The receiver takes what is still in the control reader, and the request thread answers it
  // (the server is stopping); what never reached the loop, and the steps it owes, are answered
  // here. Then the publisher drains (replies, events, diagnostics) for at most the deadline,
  // whatever a reader does.
  receiver_stop_ = true;
  if (receiver_.joinable()) receiver_.join();
  requests_stop_ = true;
  request_bell_.Ring();
  if (requests_.joinable()) requests_.join();
  AnswerWhatIsLeft();
  publisher_deadline_ns_ =
      (base::MonotonicNow() +
       options_.shutdown_deadline).ns;
  publisher_stop_ = true;
  publisher_bell_.Ring();
  if (publisher_.joinable()) publisher_.join();
  return code;
}

// --- receiver thread -----------------------------------------------------------------------------

void ServerNode::Refuse(const pb::ControlRequest& r, const std::string& why) {
  // Answered by the request thread from the request alone (the loop never sees it). Room in
  // incoming_ was checked before the sample was taken.
  Incoming in{std::make_shared<const pb::ControlRequest>(r), 0, why};
  if (!incoming_.TryPush(std::move(in))) NoRoomToAnswer();
}

// What the receiver thread keeps between its rounds.
struct ServerNode::Receiver {
  Receiver(transport::Participant& participant, transport::DropCounters* drops)
      : diagnostics(participant, TopicId::kDiagnostics, drops),
        worlds(participant, TopicId::kWorld, drops) {
    // Every bit a Button names (vdyn/input.proto).
    for (int i = 0; i < pb::Button_descriptor()->value_count(); ++i) {
      known_buttons |= static_cast<std::uint32_t>(pb::Button_descriptor()->value(i)->number());
    }
  }
  // What other servers on the domain run (their diagnostics, once a second, and worlds): a
  // spawn of one of their vehicles is refused here.
  transport::Reader<pb::Diagnostics> diagnostics;
  transport::Reader<pb::WorldDescription> worlds;
  std::map<std::uint64_t, std::int32_t> strengths;  // input writer -> its ownership strength
  std::map<std::uint64_t, int> control_writers;     // writers that sent requests -> checks missed
  // In real time, the writer whose pause is the last pause, resume or step request passed on
  // (0: none): a pause lasts while its client is there (docs/topics.md).
  std::uint64_t pause_writer = 0;
  std::uint32_t known_buttons = 0;
  int got = 0;  // requests taken in the last round
  base::MonoTime next_housekeeping = base::MonotonicNow();
};

void ServerNode::ReceiverLoop() {
  Receiver rx(participant_, &drops_);
  transport::Waitset waitset(participant_, &drops_);
  waitset.Attach(input_reader_);
  waitset.Attach(control_reader_);
  input_reader_.on_refused = [this](const transport::SampleInfo& info, std::string_view kind,
                                    std::string_view detail, const google::protobuf::Message* m) {
    InputRefusedByReader(info, kind, detail, m);
  };
  control_reader_.on_refused = [this, &rx](const transport::SampleInfo&, std::string_view kind,
                                           std::string_view detail,
                                           const google::protobuf::Message* m) {
    RequestRefusedByReader(rx, kind, detail, m);
  };
  // Set while incoming_ is full and requests may wait in the control reader: then the receiver
  // waits for the request thread's ring (a millisecond at most, for the inputs), not on the
  // waitset (which would not wait: the reader holds data).
  bool backlog = false;
  base::MonoTime drain_until{0};
  while (true) {
    const std::uint32_t room_token = receiver_bell_.Token();
    const bool stopping = receiver_stop_.load(std::memory_order_relaxed);
    if (stopping) {
      // What is still in the control reader is taken and answered (the server is stopping), for
      // at most the shutdown deadline.
      if (drain_until.ns == 0) {
        drain_until = base::MonotonicNow() + options_.shutdown_deadline;
      } else if ((!backlog && rx.got == 0) || base::MonotonicNow() >= drain_until) {
        break;
      }
    }
    if (backlog) {
      receiver_bell_.Wait(room_token, base::Milliseconds(1));
    } else if (!stopping) {
      (void)waitset.Wait(std::chrono::milliseconds(50));
    }
    const base::MonoTime now = base::MonotonicNow();
    rx.got = 0;
    ReceiveOtherServers(rx, now);  // first: a spawn below is checked against them
    const bool handed = ReceiveInputs(rx, now);
    ReceiveRequests(rx, now, stopping);
    backlog = incoming_.size() == incoming_.capacity();
    if (handed) loop_bell_.Ring();
    if (now >= rx.next_housekeeping) ReceiverHousekeeping(rx, now);
  }
  input_reader_.on_refused = nullptr;
  control_reader_.on_refused = nullptr;
}

// Inputs the reader refused (malformed, non-finite, ...): their source is blamed.
void ServerNode::InputRefusedByReader(const transport::SampleInfo& info, std::string_view kind,
                                      std::string_view detail, const google::protobuf::Message* m) {
  const auto* in = dynamic_cast<const pb::DriverInput*>(m);
  arbiter_.Refuse(info.publication_handle, in != nullptr ? in->vehicle_id() : info.key,
                  in != nullptr ? in->source_id().substr(0, limits::kMaxIdBytes) : std::string(),
                  std::string(kind) + (detail.empty() ? "" : ": ") + std::string(detail),
                  base::MonotonicNow());
}

// Requests the reader refused but could parse (a NaN, an id too long) are answered.
void ServerNode::RequestRefusedByReader(Receiver& rx, std::string_view kind,
                                        std::string_view detail,
                                        const google::protobuf::Message* m) {
  const auto* r = dynamic_cast<const pb::ControlRequest*>(m);
  if (r == nullptr) return;
  if (!r->server_id().empty() && r->server_id() != options_.session.server_id) return;
  std::string why(kind);
  if (!detail.empty()) why += ": " + std::string(detail);
  if (kind.find("non-finite") != std::string_view::npos) {
    why = std::string(detail) + " must be a finite number";
  } else if (kind.find("oversized string") != std::string_view::npos) {
    const std::size_t dot = detail.find_last_of('.');
    const std::string field(detail.substr(dot == std::string_view::npos ? 0 : dot + 1));
    why = std::string(detail) + " is longer than " +
          std::to_string(messages::MaxStringBytes(field)) + " bytes";
  }
  requests_received_.fetch_add(1, std::memory_order_relaxed);
  last_request_ns_.store(base::MonotonicNow().ns, std::memory_order_relaxed);
  ++rx.got;
  Refuse(*r, why);
}

void ServerNode::ReceiveOtherServers(Receiver& rx, base::MonoTime now) {
  const std::string& me = options_.session.server_id;
  (void)rx.diagnostics.Take([&](const pb::Diagnostics& d, const transport::SampleInfo&) {
    if (d.server_id() == me) return;
    for (const auto& v : d.vehicles()) others_[v.vehicle_id()] = {d.server_id(), now};
  });
  (void)rx.worlds.Take([&](const pb::WorldDescription& w, const transport::SampleInfo&) {
    if (w.server_id() == me) return;
    for (const auto& v : w.vehicles()) others_[v.vehicle_id()] = {w.server_id(), now};
  });
}

bool ServerNode::ReceiveInputs(Receiver& rx, base::MonoTime now) {
  bool handed = false;
  (void)input_reader_.Take([&](const pb::DriverInput& in, const transport::SampleInfo& info) {
    if (info.key != in.vehicle_id()) {
      const std::string why = "envelope key " + std::to_string(info.key) + " vs vehicle_id " +
                              std::to_string(in.vehicle_id());
      drops_.Count(drop_key_mismatch_, why);
      arbiter_.Refuse(info.publication_handle, in.vehicle_id(), in.source_id(),
                      "key mismatch: " + why, now);
      return;
    }
    const std::string why = CheckInputRanges(in);
    if (!why.empty()) {
      drops_.Count(drop_out_of_range_, why);
      arbiter_.Refuse(info.publication_handle, in.vehicle_id(), in.source_id(),
                      "out of range: " + why, now);
      return;
    }
    const std::uint32_t unknown_bits = in.buttons() & ~rx.known_buttons;
    if (unknown_bits != 0) {
      // Taken without them: a newer client's buttons mean nothing here, and are named.
      char detail[160];
      std::snprintf(detail, sizeof detail, "'%s' on vehicle %u set 0x%x",
                    base::Quote(in.source_id(), 64).c_str(), in.vehicle_id(), unknown_bits);
      drops_.Count(drop_unknown_buttons_, detail);
    }
    auto known = rx.strengths.find(info.publication_handle);
    if (known == rx.strengths.end()) {
      known = rx.strengths
                  .emplace(info.publication_handle,
                           input_reader_.WriterStrength(info.publication_handle))
                  .first;
    }
    // Only the source that drives this vehicle now reaches the loop.
    if (!arbiter_.Offer(in, info.publication_handle, known->second, now)) return;
    pb::DriverInput* slot = inputs_.Reserve();
    if (slot == nullptr) {
      drops_.Count(drop_inputs_full_);
      return;
    }
    *slot = in;
    slot->set_buttons(in.buttons() & rx.known_buttons);
    inputs_.Commit();
    handed = true;
  });
  return handed;
}

// As many requests as the request thread has room for: the rest wait in the reader.
void ServerNode::ReceiveRequests(Receiver& rx, base::MonoTime now, bool stopping) {
  const auto room = static_cast<int>(incoming_.capacity() - incoming_.size());
  if (room <= 0) return;
  const std::string& me = options_.session.server_id;
  (void)control_reader_.Take(
      [&](const pb::ControlRequest& r, const transport::SampleInfo& info) {
        if (!r.server_id().empty() && r.server_id() != me) return;  // another server's
        requests_received_.fetch_add(1, std::memory_order_relaxed);
        last_request_ns_.store(base::MonotonicNow().ns, std::memory_order_relaxed);
        ++rx.got;
        if (stopping) {
          Refuse(r, "the server is stopping: the request was not applied");
          return;
        }
        if (info.key != r.vehicle_id()) {
          Refuse(r, "the envelope key " + std::to_string(info.key) + " does not match vehicle_id " +
                        std::to_string(r.vehicle_id()));
          return;
        }
        if (r.has_spawn()) {
          const auto other = others_.find(r.vehicle_id());
          if (other != others_.end() && now - other->second.seen < base::Seconds(3)) {
            Refuse(r, "vehicle " + std::to_string(r.vehicle_id()) + " is run by server '" +
                          other->second.server_id + "' on this domain");
            return;
          }
        }
        rx.control_writers[info.publication_handle] = 0;
        if (r.has_pause()) rx.pause_writer = info.publication_handle;
        if (r.has_resume() || r.has_step()) rx.pause_writer = 0;
        Incoming in{std::make_shared<const pb::ControlRequest>(r), info.publication_handle, {}};
        if (!incoming_.TryPush(std::move(in))) NoRoomToAnswer();  // room checked before
      },
      room);
  request_bell_.Ring();
}

void ServerNode::ReceiverHousekeeping(Receiver& rx, base::MonoTime now) {
  rx.next_housekeeping = now + base::Milliseconds(200);
  // Clients whose control writer has gone: their pending steps are dropped. Gone means missing
  // from the matched writers at two checks in a row (a query that fails tells nothing): a client
  // waiting for a reply is never dropped on one odd answer.
  const bool real_time = options_.mode != ServerOptions::Mode::kLockstep;
  std::vector<std::uint64_t> live;
  if (!rx.control_writers.empty() && control_reader_.MatchedWriterHandles(live)) {
    bool handed = false;
    for (auto it = rx.control_writers.begin(); it != rx.control_writers.end();) {
      const bool present = std::find(live.begin(), live.end(), it->first) != live.end();
      it->second = present ? 0 : it->second + 1;
      if (it->second >= 2 && gone_clients_.TryPush(std::uint64_t{it->first})) {
        // The loop cancels the steps it still owed that client; the publisher says so.
        if (real_time && it->first == rx.pause_writer) ResumeForGoneClient(rx.pause_writer);
        it = rx.control_writers.erase(it);
        handed = true;
      } else {
        ++it;
      }
    }
    if (handed) loop_bell_.Ring();
  }
  // Input writers that have gone are forgotten.
  if (input_reader_.MatchedWriterHandles(live)) {
    arbiter_.Forget(live);
    for (auto it = rx.strengths.begin(); it != rx.strengths.end();) {
      it = std::find(live.begin(), live.end(), it->first) == live.end() ? rx.strengths.erase(it)
                                                                        : std::next(it);
    }
  }
  std::vector<InputArbiter::Source> copy = arbiter_.Snapshot(now);
  std::lock_guard<std::mutex> lock(sources_mu_);
  sources_copy_ = std::move(copy);
}

ServerClaim ServerNode::Claim(bool running) const {
  return {options_.session.server_id, options_.vehicle_ids, running};
}

std::string ServerNode::FindClash() {
  // Listen for other servers: their claims (their participants' USER_DATA, seen at discovery,
  // before they publish anything: claim.h), worlds (transient-local, at once), diagnostics (once a
  // second) and states. With nobody else on the domain the wait ends after discovery (300 ms);
  // once another server is seen, for up to discovery_s.
  const std::string& me = options_.session.server_id;
  const std::string domain = std::to_string(options_.domain_id);
  const ServerClaim mine = Claim(false);
  const transport::Guid own_guid = participant_.guid();
  transport::DropCounters drops;
  transport::ParticipantReader peers(participant_);
  transport::Reader<pb::WorldDescription> worlds(participant_, TopicId::kWorld, &drops);
  transport::Reader<pb::Diagnostics> diagnostics(participant_, TopicId::kDiagnostics, &drops);
  transport::Reader<pb::VehicleState> states(participant_, TopicId::kState, &drops);
  transport::Waitset waitset(participant_, &drops_);
  waitset.Attach(worlds);
  waitset.Attach(diagnostics);
  waitset.Attach(states);
  const base::MonoTime start = base::MonotonicNow();
  const base::MonoTime quiet_end = start + base::Milliseconds(300);
  const base::MonoTime end =
      start + options_.discovery;
  std::map<std::uint32_t, std::string> taken;  // vehicle -> server
  bool same_id = false;
  auto note = [&](const std::string& server, std::uint32_t vehicle) {
    if (server == me) {
      same_id = true;
    } else {
      taken.emplace(vehicle, server);
    }
  };
  const std::uint64_t own[] = {writers_[static_cast<int>(TopicId::kWorld)]->InstanceHandle(),
                              writers_[static_cast<int>(TopicId::kDiagnostics)]->InstanceHandle()};
  std::vector<std::uint64_t> handles;
  auto foreign = [&](transport::RawReader& r) {
    if (!r.MatchedWriterHandles(handles)) return false;
    for (std::uint64_t h : handles) {
      if (h != own[0] && h != own[1]) return true;
    }
    return false;
  };
  // Other servers' claims, by participant: all of them, since whether a claim that clashes with
  // ours runs may depend on one that does not (ChooseRunners).
  std::map<transport::Guid, ServerClaim> claims;
  std::vector<transport::ParticipantReader::Peer> changes;
  auto first_common = [&](const ServerClaim& c) -> std::string {
    for (std::uint32_t v : mine.vehicle_ids) {
      if (std::find(c.vehicle_ids.begin(), c.vehicle_ids.end(), v) != c.vehicle_ids.end()) {
        return std::to_string(v);
      }
    }
    return {};
  };
  while (true) {
    changes.clear();
    if (!peers.Take(changes))
      drops_.Count("DDS error on the domain's participants", peers.last_error());
    for (const auto& peer : changes) {
      if (peer.guid == own_guid) continue;
      const std::optional<ServerClaim> c = ServerClaim::Decode(peer.user_data);
      if (peer.alive && c) {
        claims[peer.guid] = *c;
      } else {
        claims.erase(peer.guid);
      }
    }
    // A running server never gives way: a clash with one is certain at once.
    for (const auto& [guid, c] : claims) {
      if (!c.running || !mine.Clashes(c)) continue;
      return c.server_id == me ? "another server with the id '" + me + "' runs on domain " +
                                     domain +
                                     ": give this one another --server-id, or another --domain"
                               : "vehicle " + first_common(c) + " is already run by server '" +
                                     c.server_id + "' on domain " + domain +
                                     ": choose other --vehicle-ids, or another --domain";
    }
    const base::MonoTime now = base::MonotonicNow();
    const bool others =
        !claims.empty() || foreign(worlds) || foreign(diagnostics) || foreign(states);
    if (now >= end || (!others && now >= quiet_end)) break;
    (void)waitset.Wait(std::chrono::milliseconds(20));  // an error is counted in drops_
    (void)worlds.Take([&](const pb::WorldDescription& w, const transport::SampleInfo&) {
      for (const auto& v : w.vehicles()) note(w.server_id(), v.vehicle_id());
      if (w.server_id() == me) same_id = true;
    });
    (void)diagnostics.Take([&](const pb::Diagnostics& d, const transport::SampleInfo&) {
      for (const auto& v : d.vehicles()) note(d.server_id(), v.vehicle_id());
      if (d.server_id() == me) same_id = true;
    });
    (void)states.Take([&](const pb::VehicleState& st, const transport::SampleInfo&) {
      note(st.server_id(), st.vehicle_id());
    });
    // Decided as soon as a clash is certain.
    bool clash = same_id;
    for (std::uint32_t id : options_.vehicle_ids) clash = clash || taken.count(id) != 0;
    if (clash) break;
  }
  // The claims of servers started at the same moment, decided once every claim of the wait is in.
  if (std::string why = SettleClaims(mine, own_guid, claims); !why.empty()) return why;
  for (const auto& [vehicle, server] : taken) others_[vehicle] = {server, base::MonotonicNow()};
  if (same_id) {
    return "another server with the id '" + me + "' runs on domain " + domain +
           ": give this one another --server-id, or another --domain";
  }
  for (std::uint32_t id : options_.vehicle_ids) {
    if (const auto it = taken.find(id); it != taken.end()) {
      return "vehicle " + std::to_string(id) + " is already run by server '" + it->second +
             "' on domain " + domain + ": choose other --vehicle-ids, or another --domain";
    }
  }
  return {};
}

std::string ServerNode::SettleClaims(const ServerClaim& mine, const transport::Guid& own_guid,
                                     const std::map<transport::Guid, ServerClaim>& claims) const {
  const std::string& me = options_.session.server_id;
  const std::string domain = std::to_string(options_.domain_id);
  std::vector<const ServerClaim*> by_guid;
  std::vector<transport::Guid> guids;
  bool mine_in = false;
  for (const auto& [guid, c] : claims) {
    if (!mine_in && own_guid < guid) {
      by_guid.push_back(&mine);
      guids.push_back(own_guid);
      mine_in = true;
    }
    by_guid.push_back(&c);
    guids.push_back(guid);
  }
  if (!mine_in) {
    by_guid.push_back(&mine);
    guids.push_back(own_guid);
  }
  const std::vector<bool> runs = ChooseRunners(by_guid);
  const auto own = static_cast<std::size_t>(
      std::find(guids.begin(), guids.end(), own_guid) - guids.begin());
  auto common = [&](const ServerClaim& c) {
    if (c.server_id == me) return std::string("the id '") + me + "'";
    for (std::uint32_t v : mine.vehicle_ids) {
      if (std::find(c.vehicle_ids.begin(), c.vehicle_ids.end(), v) != c.vehicle_ids.end()) {
        return "vehicle " + std::to_string(v);
      }
    }
    return std::string();
  };
  for (std::size_t i = 0; i < by_guid.size(); ++i) {
    if (i == own || !mine.Clashes(*by_guid[i])) continue;
    const ServerClaim& c = *by_guid[i];
    if (!runs[own] && runs[i]) {
      return c.server_id == me
                 ? "another server with the id '" + me + "' started at the same moment on domain " +
                       domain +
                       " and keeps the id (claims are settled in the order of the participants' "
                       "GUIDs): give this one another --server-id, or another --domain"
                 : common(c) + " is claimed by server '" + c.server_id +
                       "', started at the same moment on domain " + domain +
                       "; that server keeps it (claims are settled in the order of the "
                       "participants' GUIDs): choose other --vehicle-ids, or another --domain";
    }
    if (runs[own]) {
      spdlog::info("server '{}': server '{}' started at the same moment and claims {} too; this "
                   "server keeps it (claims are settled in the order of the participants' GUIDs)",
                   me, c.server_id, common(c));
    }
  }
  return {};
}

// --- request thread ------------------------------------------------------------------------------

bool ServerNode::ForThisServer(const pb::ControlRequest& r) const {
  // The receiver passes requests for this server by name, and those for whichever server owns
  // the vehicle: a vehicle command of that kind is for another server unless this one has it.
  if (!r.server_id().empty()) return true;
  const bool server_wide =
      r.has_pause() || r.has_resume() || r.has_step() || r.has_spawn() || r.has_hello();
  return server_wide || planner_->Knows(r.vehicle_id());
}

void ServerNode::AnswerHere(const std::shared_ptr<const pb::ControlRequest>& r, std::string why) {
  RequestOutcome o;
  o.request = r;
  o.accepted = why.empty();
  o.why = why.empty() ? RequestOutcome::Why::kNone : RequestOutcome::Why::kText;
  o.text = std::move(why);
  o.sim_time_ns = sim_time_ns_.load(std::memory_order_relaxed);
  if (!answers_.TryPush(std::move(o))) NoRoomToAnswer();  // room checked before
}

void ServerNode::ResumeForGoneClient(std::uint64_t& pause_writer) {
  // A real-time session paused by a client that then left would stay paused for good (issue 33):
  // the server resumes it, through the request path as any resume (an event is recorded; the
  // reply goes to no one). Without room now, at the next check.
  if (incoming_.size() == incoming_.capacity()) return;
  auto r = std::make_shared<pb::ControlRequest>();
  r->set_server_id(options_.session.server_id);
  r->set_client_id("vdyn-server: the client that paused left");
  r->mutable_resume();
  spdlog::info("server '{}': the client that paused the session left; resuming",
               options_.session.server_id);
  if (incoming_.TryPush(Incoming{std::move(r), 0, {}})) {
    pause_writer = 0;
    request_bell_.Ring();
  }
}

void ServerNode::RequestLoop() {
  const bool lockstep = options_.mode == ServerOptions::Mode::kLockstep;
  const std::string stopping_why = "the server is stopping: the request was not applied";
  std::unique_ptr<PreparedRequest> spent;
  Incoming in;
  base::MonoTime give_up{0};  // once stopping: the shutdown deadline
  while (true) {
    const std::uint32_t token = request_bell_.Token();
    bool did = false;
    while (spent_.TryPop(spent)) {
      planner_->Settle(std::move(spent));
      did = true;
    }
    const bool stopping = requests_stop_.load();
    if (stopping && give_up.ns == 0) {
      give_up = base::MonotonicNow() +
                options_.shutdown_deadline;
    }
    if (stopping && base::MonotonicNow() >= give_up) {
      // The publisher took no answer for the whole deadline: what is left is counted.
      while (incoming_.TryPop(in)) {
        requests_unanswered_.fetch_add(1, std::memory_order_relaxed);
        drops_.Count(drop_unanswered_stopped_);
      }
      break;
    }
    // A request is taken only when both its ways on have room; none while a restore has not
    // come back from the loop (its outcome decides what the vehicle is).
    while ((stopping || !planner_->waiting()) && answers_.size() < answers_.capacity() &&
           prepared_.size() < prepared_.capacity() && incoming_.TryPop(in)) {
      did = true;
      const std::shared_ptr<const pb::ControlRequest> request = std::move(in.request);
      if (!in.refusal.empty()) {
        AnswerHere(request, std::move(in.refusal));
        continue;
      }
      if (!ForThisServer(*request)) {
        requests_for_others_.fetch_add(1, std::memory_order_relaxed);
        continue;
      }
      if (stopping) {
        AnswerHere(request, stopping_why);
        continue;
      }
      if (lockstep && request->has_resume()) {
        AnswerHere(request, "lockstep mode advances only on step requests");
        continue;
      }
      RequestPlanner::Plan plan = planner_->Prepare(request);
      if (!plan.bad_step_input.empty()) drops_.Count(drop_step_input_, plan.bad_step_input);
      if (plan.hello) {
        AnswerHere(request, {});  // accepted, at once: nothing to apply
        continue;
      }
      if (!plan.prepared) {
        AnswerHere(request, std::move(plan.refusal));
        continue;
      }
      plan.prepared->client = in.writer;
      if (!prepared_.TryPush(std::move(plan.prepared))) NoRoomToAnswer();  // room checked before
      loop_bell_.Ring();
    }
    if (did) {
      receiver_bell_.Ring();
      publisher_bell_.Ring();
    }
    if (stopping && incoming_.empty()) break;
    if (!did) request_bell_.Wait(token, base::Milliseconds(50));
  }
}

// --- publisher thread ----------------------------------------------------------------------------

bool ServerNode::PublishOne(TopicId topic, std::uint32_t key, const google::protobuf::Message& m,
                            base::MonoTime give_up) {
  transport::RawWriter& w = *writers_[static_cast<int>(topic)];
  // A reliable write blocks at most 10 ms, and only while a reader's history is full: try again
  // until `give_up` (a re-simulation needs every event) and the shutdown deadline.
  while (true) {
    if (w.Write(key, m)) return true;
    const base::MonoTime now = base::MonotonicNow();
    const std::int64_t deadline = publisher_deadline_ns_.load(std::memory_order_relaxed);
    if (now >= give_up || (deadline != 0 && now.ns >= deadline)) {
      drops_.Count(std::string("write failed on ") + transport::Spec(topic).name, w.last_error());
      if (topic == TopicId::kControlReply) {
        // A client is waiting for it: say so where a person looks.
        spdlog::warn("server '{}': a reply could not be written: {}", options_.session.server_id,
                     w.last_error());
      }
      return false;
    }
  }
}

namespace {
// The vehicles' part of the status line: each one's speed, up to four; beyond, how many there are,
// their speeds' range and how many brake without input.
std::string StatusOfVehicles(const ServerNode::WindowReport& r) {
  std::string out;
  char buf[128];
  if (r.n_vehicles <= 4) {
    for (std::size_t i = 0; i < r.n_vehicles; ++i) {
      const ServerNode::VehicleReport& v = r.vehicles[i];
      std::snprintf(buf, sizeof buf, "  v%u %5.1f km/h%s", v.id, v.speed_kmh,
                    v.safe_state ? " (no input: braking)" : "");
      out += buf;
    }
    return out;
  }
  double lo = r.vehicles[0].speed_kmh, hi = lo;
  std::size_t braking = 0;
  for (std::size_t i = 0; i < r.n_vehicles; ++i) {
    lo = std::min(lo, r.vehicles[i].speed_kmh);
    hi = std::max(hi, r.vehicles[i].speed_kmh);
    braking += r.vehicles[i].safe_state ? 1 : 0;
  }
  std::snprintf(buf, sizeof buf, "  %zu vehicles %.1f-%.1f km/h, %zu without input (braking)",
                r.n_vehicles, lo, hi, braking);
  return buf;
}
}  // namespace

void ServerNode::PublishReport(WindowReport& r) {
  const std::string& server_id = options_.session.server_id;
  const double wall_s = static_cast<double>(r.wall_ns) * 1e-9;
  const double p50 = r.lateness.Percentile(50), p99 = r.lateness.Percentile(99);
  const double max_us = r.lateness.Max();
  const double rate = wall_s > 0 ? static_cast<double>(r.window_steps) / wall_s : 0.0;
  pb::Diagnostics d;
  d.set_server_id(server_id);
  d.set_mode(options_.mode == ServerOptions::Mode::kRealtime ? "realtime" : "lockstep");
  d.set_sim_time_ns(r.sim_time_ns);
  d.set_steps(static_cast<std::uint64_t>(r.steps));
  d.set_lateness_p50_us(p50);
  d.set_lateness_p99_us(p99);
  d.set_lateness_max_us(max_us);
  d.set_steps_caught_up(r.steps_caught_up);
  d.set_max_lag_steps(r.max_lag_steps);
  d.set_step_rate_hz(rate);
  d.set_cpu_percent(wall_s > 0 ? 100.0 * static_cast<double>(r.cpu_ns) * 1e-9 / wall_s : 0.0);
  for (const auto& [kind, count] : drops_.Snapshot()) {
    pb::DropCount* dc = d.add_drops();
    dc->set_kind(kind);
    dc->set_count(count);
  }
  for (std::size_t i = 0; i < r.n_vehicles; ++i) {
    const VehicleReport& v = r.vehicles[i];
    // A state that went non-finite is contained (the vehicle put back at rest where it was, a
    // spawned event): said in the log too, not only counted in the diagnostics.
    auto& said = contained_said_[v.id];
    if (v.nonfinite_steps < said[0] || v.under_ground_steps < said[1] ||
        v.runaway_steps < said[2]) {
      said = {};  // another vehicle of that id
    }
    const std::tuple<std::uint64_t, std::uint64_t*, StepStatus> contained[] = {
        {v.nonfinite_steps, &said[0], StepStatus::kNonFinite},
        {v.under_ground_steps, &said[1], StepStatus::kUnderGround},
        {v.runaway_steps, &said[2], StepStatus::kRunaway}};
    for (const auto& [count, told, status] : contained) {
      if (count <= *told) continue;
      spdlog::warn("server '{}': vehicle {}: {} ({} more time(s), {} in all)", server_id, v.id,
                   ContainedWhy(status), count - *told, count);
      *told = count;
    }
    pb::VehicleDiagnostics* vd = d.add_vehicles();
    vd->set_vehicle_id(v.id);
    vd->set_watchdog_safe_state(v.safe_state);
    vd->set_input_age_ms(v.input_age_ms);
    vd->set_input_source(v.source);
    vd->set_nonfinite_steps(v.nonfinite_steps);
    vd->set_under_ground_steps(v.under_ground_steps);
    vd->set_runaway_steps(v.runaway_steps);
    vd->set_sanitized_inputs(v.sanitized_inputs);
    vd->set_invariant_failures(v.invariant_failures);
    vd->set_last_invariant_failure(v.last_invariant_failure);
    std::lock_guard<std::mutex> lock(sources_mu_);
    const base::MonoTime now = base::MonotonicNow();
    for (const InputArbiter::Source& src : sources_copy_) {
      if (src.vehicle_id != v.id) continue;
      pb::InputSourceDiagnostics* sd = vd->add_sources();
      sd->set_source_id(src.source_id.empty() ? "writer " + std::to_string(src.handle)
                                              : src.source_id);
      sd->set_strength(src.strength);
      sd->set_driving(src.driving);
      sd->set_accepted(src.accepted);
      sd->set_refused(src.refused);
      sd->set_last_refusal(src.last_refusal.substr(0, limits::kMaxNameBytes));
      sd->set_since_valid_ms(src.last_valid.ns >= 0 ? (now - src.last_valid).millis() : -1.0);
      sd->set_since_refused_ms(src.last_refused.ns >= 0 ? (now - src.last_refused).millis() : -1.0);
    }
  }
  d.set_scheduling(scheduling_);
  d.set_requests_received(requests_received_.load(std::memory_order_relaxed));
  d.set_replies_sent(replies_sent_.load(std::memory_order_relaxed));
  d.set_requests_unanswered(requests_unanswered_.load(std::memory_order_relaxed));
  d.set_requests_for_other_servers(requests_for_others_.load(std::memory_order_relaxed));
  PublishOne(TopicId::kDiagnostics, transport::ServerKey(server_id), d,
             base::MonotonicNow() + base::Milliseconds(100));

  // The status line: rewritten in place on a terminal, a line every 5 s into a file.
  static const bool tty = isatty(STDERR_FILENO) == 1;
  const std::int64_t now = base::MonotonicNow().ns;
  if (!options_.status_line || (!tty && now - last_status_ns_ < 5'000'000'000)) return;
  last_status_ns_ = now;
  const std::string vehicles = StatusOfVehicles(r);
  std::fprintf(stderr, "%st %7.2f s%s | %6.0f steps/s | late p50 %4.0f p99 %5.0f max %6.0f us  %s",
               tty ? "\r" : "", static_cast<double>(r.sim_time_ns) * 1e-9, vehicles.c_str(), rate,
               p50, p99, max_us, tty ? "" : "\n");
  std::fflush(stderr);
}

void ServerNode::PublishOutcome(RequestOutcome& o, base::MonoTime now) {
  const std::string& me = options_.session.server_id;
  if (o.why == RequestOutcome::Why::kClientGone) {
    // No reply: its client is gone. Said in the operator's terms.
    requests_unanswered_.fetch_add(1, std::memory_order_relaxed);
    const std::string client = base::Quote(o.request->client_id(), 64);
    drops_.Count(drop_unanswered_gone_, "client '" + client + "'");
    spdlog::warn(
        "server '{}': client '{}' went away before the {} steps it asked for were done: "
        "the {} still to run are cancelled, and the simulation stays paused at {:.3f} s",
        me, client, o.request->step().steps(), o.steps_not_run, static_cast<double>(o.sim_time_ns) * 1e-9);
    o = RequestOutcome{};
    return;
  }
  const pb::ControlReply reply = ToReply(o, me);
  if (!reply.accepted()) {
    drops_.Count(drop_rejected_, reply.reason());
    spdlog::debug("refused request {} of '{}': {}", reply.request_id(),
                  base::Quote(reply.client_id(), 64), base::Quote(reply.reason(), 200));
  }
  if (PublishOne(TopicId::kControlReply, reply.vehicle_id(), reply, now + base::Seconds(1))) {
    replies_sent_.fetch_add(1, std::memory_order_relaxed);
  } else {
    requests_unanswered_.fetch_add(1, std::memory_order_relaxed);
    drops_.Count(drop_unanswered_write_,
                 writers_[static_cast<int>(TopicId::kControlReply)]->last_error());
  }
  o = RequestOutcome{};  // the request is freed here, off the loop
}

void ServerNode::PublisherLoop() {
  const std::string& server_id = options_.session.server_id;
  const std::uint64_t terrain_hash = TerrainHash(world_->terrain);
  Outgoing out;
  RequestOutcome outcome;
  SessionEventRecord rec;
  auto queues_empty = [&] {
    return outbox_.empty() && outcomes_.empty() && answers_.empty() && reports_.empty() &&
           events_.empty();
  };
  while (true) {
    const std::uint32_t token = publisher_bell_.Token();
    const base::MonoTime now = base::MonotonicNow();
    const std::int64_t deadline = publisher_deadline_ns_.load(std::memory_order_relaxed);
    if (publisher_stop_.load() && (queues_empty() || (deadline != 0 && now.ns >= deadline))) {
      // Replies not written by the deadline: their requests are unanswered, and counted so.
      const std::size_t replies = outcomes_.size() + answers_.size();
      while (outcomes_.TryPop(outcome) || answers_.TryPop(outcome)) {
        if (outcome.why != RequestOutcome::Why::kClientGone) {
          requests_unanswered_.fetch_add(1, std::memory_order_relaxed);
          drops_.Count(drop_unanswered_stopped_);
        }
      }
      const std::size_t left = outbox_.size() + events_.size() + replies;
      if (left > 0) {
        spdlog::warn(
            "server '{}': {} messages not sent by the shutdown deadline ({} of them "
            "replies)",
            server_id, left, replies);
      }
      break;
    }
    // Replies, parameters and the world first: a slow recorder never delays an answer.
    while (outbox_.TryPop(out)) {
      PublishOne(out.topic, out.key, *out.msg, now + base::Seconds(1));
      out.msg.reset();
    }
    while (outcomes_.TryPop(outcome)) PublishOutcome(outcome, now);
    while (answers_.TryPop(outcome)) PublishOutcome(outcome, now);
    while (WindowReport* r = reports_.Front()) {
      PublishReport(*r);
      reports_.Pop();
    }
    // Then events, a batch at a time.
    for (int n = 0; n < 64 && events_.TryPop(rec); ++n) {
      const pb::SessionEvent e = ToMessage(rec, server_id, terrain_hash, options_.session.step_ns,
                                            options_.session.incarnation);
      rec.params.reset();
      rec.request.reset();
      PublishOne(TopicId::kEvents, e.vehicle_id(), e, base::MonotonicNow() + base::Seconds(1));
      const pb::VehicleParams* params = nullptr;
      if (e.has_spawned()) params = &e.spawned().params();
      if (e.has_params_changed()) params = &e.params_changed().params();
      if (params != nullptr) {
        PublishOne(TopicId::kParams, e.vehicle_id(), *params,
                   base::MonotonicNow() + base::Seconds(1));
      }
      // A removed vehicle's parameters end with it: a reader joining later took them from the
      // topic's history and counted the vehicle as there (Python's params(), the recorder's info).
      if (e.has_removed()) {
        transport::RawWriter& w = *writers_[static_cast<int>(TopicId::kParams)];
        if (!w.Dispose(e.vehicle_id())) {
          drops_.Count(std::string("dispose failed on ") + transport::Spec(TopicId::kParams).name,
                       w.last_error());
        }
      }
    }
    drops_.Report();
    if (queues_empty() && !publisher_stop_.load()) {
      publisher_bell_.Wait(token, base::Milliseconds(500));
    }
  }
  // What was written reaches its reliable readers before the server leaves, within the same
  // deadline: a recorder that lost a datagram of the last events gets it again (a server that
  // left at once took the session's last input events with it, and a verify of the recording
  // could not re-simulate its last half second).
  // The events first (a re-simulation needs every one); a topic reached after the deadline is
  // asked without waiting (a reader that went away without a word holds up the others until its
  // lease ends, while Cyclone goes on resending to it), and only one still unacknowledged is named.
  constexpr TopicId kAckOrder[] = {TopicId::kEvents, TopicId::kParams, TopicId::kWorld,
                                   TopicId::kControlReply, TopicId::kDiagnostics};
  static_assert(std::size(kAckOrder) == std::size(kReliableTopics));
  const std::int64_t deadline = publisher_deadline_ns_.load(std::memory_order_relaxed);
  for (TopicId t : kAckOrder) {
    if (deadline == 0) break;  // set before every stop; never 0 here
    const std::int64_t left = std::max<std::int64_t>(0, deadline - base::MonotonicNow().ns);
    transport::RawWriter& w = *writers_[static_cast<int>(t)];
    if (!w.WaitForAcks(std::chrono::nanoseconds(left))) {
      spdlog::warn("server '{}': {} not acknowledged by every reader by the shutdown deadline: {}",
                   server_id, transport::Spec(t).name, w.last_error());
    }
  }
  drops_.Report();
}

}  // namespace vdyn
