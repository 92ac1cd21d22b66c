#include "vdyn/runtime/server_node.h"

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>

#include <spdlog/spdlog.h>

#include "vdyn/base/limits.h"
#include "vdyn/base/text.h"
#include "vdyn/bridge/convert.h"
#include "vdyn/messages/checks.h"

namespace vdyn {

using transport::TopicId;

namespace {
constexpr TopicId kReliableTopics[] = {TopicId::kControlReply, TopicId::kParams, TopicId::kWorld,
                                       TopicId::kEvents, TopicId::kDiagnostics};
}  // namespace

ServerNode::ServerNode(std::shared_ptr<const World> world, ServerOptions options)
    : world_(std::move(world)),
      options_(std::move(options)),
      participant_(options_.domain_id),
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
  drop_requests_full_ = drops_.Register("request queue full, request refused");
  drop_key_mismatch_ = drops_.Register("key mismatch on vdyn/input");
  drop_out_of_range_ = drops_.Register("out-of-range input on vdyn/input");
  drop_rejected_ = drops_.Register("rejected control request");
  drop_step_input_ = drops_.Register("out-of-range input in a step request");

  if (const std::string clash = FindClash(); !clash.empty()) throw std::runtime_error(clash);
  session_ = std::make_unique<Session>(world_, options_.session,
                                       [this](SessionEventRecord&& r) { OnEvent(std::move(r)); });
  // 32 steps of as many vehicles as it may run (at least 512 frames): the writer thread may
  // stall for tens of ms while a session starts (discovery, the world, every vehicle's
  // parameters, the vehicles' own state writers).
  states_ = std::make_unique<StateOutbox>(
      participant_, drops_,
      std::max<std::size_t>(
          512, 32 * std::max(options_.vehicle_ids.size(), options_.session.max_vehicles)));
  state_sink_ = [this](std::uint32_t id, const pb::VehicleState& s) { states_->Push(id, s); };
  // The world first (transient-local: viewers joining later get it), then the vehicles.
  auto world_msg = std::make_unique<pb::WorldDescription>(
      DescribeWorld(*world_, options_.session.server_id, options_.session.step_ns));
  const double lateral = 5.0;  // several vehicles start side by side
  for (std::size_t i = 0; i < options_.vehicle_ids.size(); ++i) {
    Pose2 pose = world_->spawn;
    pose.x -= std::sin(pose.yaw) * lateral * static_cast<double>(i);
    pose.y += std::cos(pose.yaw) * lateral * static_cast<double>(i);
    session_->Spawn(options_.vehicle_ids[i], pose, 0.0, pb::VehicleParams());
    *world_msg->add_vehicles() =
        DescribeVehicle(options_.vehicle_ids[i], session_->simulator(options_.vehicle_ids[i]).params());
  }
  Send(TopicId::kWorld, transport::ServerKey(options_.session.server_id), std::move(world_msg));
  deferred_step_replies_.reserve(256);
  // Last: if anything above throws, no thread is left running.
  publisher_ = std::thread([this] { PublisherLoop(); });
  receiver_ = std::thread([this] { ReceiverLoop(); });
}

ServerNode::~ServerNode() {
  receiver_stop_ = true;
  if (receiver_.joinable()) receiver_.join();
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

void ServerNode::HandleRequest(const pb::ControlRequest& r, std::uint64_t writer) {
  const std::string& me = options_.session.server_id;
  if (!r.server_id().empty() && r.server_id() != me) return;  // for another server
  const bool server_wide = r.has_pause() || r.has_resume() || r.has_step() || r.has_spawn();
  if (r.server_id().empty() && !server_wide && !session_->HasVehicle(r.vehicle_id())) {
    return;  // another server's vehicle
  }
  pb::ControlReply reply;
  if (options_.mode == ServerOptions::Mode::kLockstep && r.has_resume()) {
    reply = session_->Reject(r, "lockstep mode advances only on step requests");
  } else {
    if (r.has_step() && r.step().has_input() && r.step().input().vehicle_id() != 0) {
      std::string why;
      if (!session_->OfferInput(r.step().input(), &why)) drops_.Count(drop_step_input_, why);
    }
    reply = session_->Apply(r);
  }
  if (r.has_step() && reply.accepted()) {
    // Answered when its steps are done: the ones pending before it, then its own.
    deferred_step_replies_.push_back({r.step().steps(), writer, reply});
    return;
  }
  if ((r.has_pause() || r.has_resume()) && reply.accepted()) {
    CancelStepReplies(std::string("cancelled by a ") + (r.has_pause() ? "pause" : "resume") +
                      " request before its steps were done");
  }
  if (!reply.accepted()) drops_.Count(drop_rejected_, reply.reason());
  Send(TopicId::kControlReply, r.vehicle_id(), std::make_unique<pb::ControlReply>(reply));
}

bool ServerNode::Boundary() {
  bool got_request = false;
  // At most 16 requests per step boundary: a flood waits in the queue instead of stretching one
  // step of the 1 kHz loop. Requests are applied here (they may allocate); the request objects go
  // back to the receiver to be freed.
  Request req;
  for (int n = 0; n < limits::kMaxRequestsPerBoundary && requests_.TryPop(req); ++n) {
    got_request = true;
    HandleRequest(*req.msg, req.writer);
    if (!spent_requests_.TryPush(std::move(req.msg))) req.msg.reset();
  }
  std::uint64_t gone = 0;
  while (gone_clients_.TryPop(gone)) ClientGone(gone);
  // Inputs were checked by the receiver (key, ranges); the newest of each vehicle wins.
  while (pb::DriverInput* in = inputs_.Front()) {
    if (session_->HasVehicle(in->vehicle_id())) session_->OfferInput(*in, nullptr);
    inputs_.Pop();
  }
  return got_request;
}

void ServerNode::StepOnce() {
  session_->Step(state_sink_);
  states_->Send();
  if (session_->paused() && session_->pending_steps() > 0) {
    session_->ConsumePendingStep();
    if (!deferred_step_replies_.empty() && deferred_step_replies_.front().remaining > 0) {
      --deferred_step_replies_.front().remaining;
    }
  }
  if (!deferred_step_replies_.empty()) SendDueStepReplies();
}

void ServerNode::SendDueStepReplies() {
  // The requests are served in order: the first one's steps run first.
  std::size_t done = 0;
  while (done < deferred_step_replies_.size() && deferred_step_replies_[done].remaining == 0) {
    pb::ControlReply& reply = deferred_step_replies_[done].reply;
    if (session_->HasVehicle(reply.vehicle_id())) {
      reply.set_applied_step(
          static_cast<std::uint64_t>(session_->simulator(reply.vehicle_id()).state().step));
    }
    reply.set_sim_time_ns(session_->steps() * session_->step_ns());
    Send(TopicId::kControlReply, reply.vehicle_id(), std::make_unique<pb::ControlReply>(reply));
    ++done;
  }
  deferred_step_replies_.erase(deferred_step_replies_.begin(),
                               deferred_step_replies_.begin() + static_cast<std::ptrdiff_t>(done));
}

void ServerNode::ClientGone(std::uint64_t writer) {
  // The steps a client asked for, and that have not run, are dropped with it: a long step
  // request does not outlive the client that wanted it.
  std::uint32_t dropped = 0;
  for (auto it = deferred_step_replies_.begin(); it != deferred_step_replies_.end();) {
    if (it->writer == writer) {
      dropped += it->remaining;
      it = deferred_step_replies_.erase(it);
    } else {
      ++it;
    }
  }
  if (dropped > 0) {
    session_->CancelPendingSteps(dropped);
    drops_.Count(drop_rejected_, "steps cancelled: the client that asked for them is gone");
  }
  if (!deferred_step_replies_.empty()) SendDueStepReplies();
}

void ServerNode::CancelStepReplies(const std::string& why) {
  for (DeferredReply& d : deferred_step_replies_) {
    d.reply.set_accepted(false);
    d.reply.set_reason(why);
    d.reply.set_sim_time_ns(session_->steps() * session_->step_ns());
    Send(TopicId::kControlReply, d.reply.vehicle_id(), std::make_unique<pb::ControlReply>(d.reply));
  }
  deferred_step_replies_.clear();
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
      if (r->n_vehicles >= static_cast<int>(r->vehicles.size())) return;
      VehicleReport& v = r->vehicles[static_cast<std::size_t>(r->n_vehicles++)];
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
      v.sanitized_inputs = sim.sanitized_inputs();
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
  scheduling_ = SetUpRealtimeScheduling(options_.rt_priority);
  const std::int64_t h = options_.session.step_ns;
  const std::int64_t end_steps =
      options_.duration_s > 0 ? std::llround(options_.duration_s * 1e9 / static_cast<double>(h)) : 0;
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
  if (!options_.stats_out.empty()) WriteStats(start, end, start_cpu);
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
  if (std::fclose(f) != 0) spdlog::error("writing the run summary {} failed", options_.stats_out);
}

int ServerNode::RunLockstep(const std::atomic<bool>& stop) {
  scheduling_ = "lockstep (no clock)";
  spdlog::info("server '{}': lockstep on domain {}; steps run on request", options_.session.server_id,
               options_.domain_id);
  session_->Apply([] {
    pb::ControlRequest r;
    r.mutable_pause();
    return r;
  }());
  window_start_ = base::MonotonicNow();
  window_start_cpu_ = base::ProcessCpuTime();
  base::MonoTime last_request = base::MonotonicNow();
  const auto timeout = base::Nanos{static_cast<std::int64_t>(options_.lockstep_timeout_s * 1e9)};
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
    if ((now - window_start_).ns >= 1'000'000'000) PushReport(now);
    if (now - last_request > timeout) {
      spdlog::error("lockstep: no control request for {} s; the client is gone? stopping",
                    base::FormatNumber(options_.lockstep_timeout_s));
      return 3;
    }
    if (requests_.empty() && inputs_.empty()) loop_bell_.Wait(token, base::Milliseconds(20));
  }
  return 0;
}

int ServerNode::Run(const std::atomic<bool>& stop) {
  const int code = options_.mode == ServerOptions::Mode::kRealtime ? RunRealtime(stop)
                                                                    : RunLockstep(stop);
  session_->FlushEvents();
  states_->Drain(base::Milliseconds(500));
  // Let the publisher drain (replies, events, diagnostics) for at most the deadline, whatever a
  // reader does.
  receiver_stop_ = true;
  if (receiver_.joinable()) receiver_.join();
  publisher_deadline_ns_ =
      (base::MonotonicNow() +
       base::Nanos{static_cast<std::int64_t>(options_.shutdown_deadline_s * 1e9)}).ns;
  publisher_stop_ = true;
  publisher_bell_.Ring();
  if (publisher_.joinable()) publisher_.join();
  return code;
}

// --- receiver thread -----------------------------------------------------------------------------

void ServerNode::Refuse(const pb::ControlRequest& r, const std::string& why) {
  // Answered here (the loop never sees it), from the request alone: the session belongs to the
  // loop thread. An id too long to echo is cut to its limit (such a client cannot match it).
  auto reply = std::make_unique<pb::ControlReply>();
  reply->set_request_id(r.request_id());
  reply->set_client_id(r.client_id().substr(0, limits::kMaxIdBytes));
  reply->set_vehicle_id(r.vehicle_id());
  reply->set_server_id(options_.session.server_id);
  reply->set_accepted(false);
  reply->set_reason(why.substr(0, limits::kMaxReasonBytes));
  drops_.Count(drop_rejected_, why);
  if (early_replies_.TryPush(std::move(reply))) publisher_bell_.Ring();
}

void ServerNode::ReceiverLoop() {
  const std::string& me = options_.session.server_id;
  transport::Waitset waitset(participant_);
  waitset.Attach(input_reader_);
  waitset.Attach(control_reader_);
  // What other servers on the domain run (their diagnostics, once a second, and worlds): a spawn
  // of one of their vehicles is refused here.
  transport::Reader<pb::Diagnostics> diagnostics(participant_, TopicId::kDiagnostics, &drops_);
  transport::Reader<pb::WorldDescription> worlds(participant_, TopicId::kWorld, &drops_);
  std::unique_ptr<pb::ControlRequest> spent;
  std::map<std::uint64_t, std::int32_t> strengths;   // input writer -> its ownership strength
  std::map<std::uint64_t, int> control_writers;      // writers that sent requests -> checks missed
  base::MonoTime next_housekeeping = base::MonotonicNow();

  // Inputs the reader refused (malformed, non-finite, ...): their source is blamed.
  input_reader_.on_refused = [&](const transport::SampleInfo& info, std::string_view kind,
                                 std::string_view detail, const google::protobuf::Message* m) {
    const auto* in = dynamic_cast<const pb::DriverInput*>(m);
    arbiter_.Refuse(info.publication_handle, in != nullptr ? in->vehicle_id() : info.key,
                    in != nullptr ? in->source_id().substr(0, limits::kMaxIdBytes) : std::string(),
                    std::string(kind) + (detail.empty() ? "" : ": ") + std::string(detail),
                    base::MonotonicNow());
  };
  // Requests the reader refused but could parse (a NaN, an id too long) are answered.
  control_reader_.on_refused = [&](const transport::SampleInfo&, std::string_view kind,
                                   std::string_view detail, const google::protobuf::Message* m) {
    const auto* r = dynamic_cast<const pb::ControlRequest*>(m);
    if (r == nullptr) return;
    if (!r->server_id().empty() && r->server_id() != me) return;
    std::string why(kind);
    if (!detail.empty()) why += ": " + std::string(detail);
    if (kind.find("non-finite") != std::string_view::npos) {
      why = std::string(detail) + " must be a finite number";
    } else if (kind.find("oversized string") != std::string_view::npos) {
      why = std::string(detail) + " is longer than " +
            std::to_string(messages::MaxStringBytes(std::string(
                detail.substr(detail.find_last_of('.') == std::string_view::npos
                                  ? 0
                                  : detail.find_last_of('.') + 1)))) +
            " bytes";
    }
    Refuse(*r, why);
  };

  while (!receiver_stop_.load(std::memory_order_relaxed)) {
    waitset.Wait(std::chrono::milliseconds(50));
    const base::MonoTime now = base::MonotonicNow();
    bool handed = false;
    // What the other servers run, first: a spawn below is checked against it.
    diagnostics.Take([&](const pb::Diagnostics& d, const transport::SampleInfo&) {
      if (d.server_id() == me) return;
      for (const auto& v : d.vehicles()) others_[v.vehicle_id()] = {d.server_id(), now};
    });
    worlds.Take([&](const pb::WorldDescription& w, const transport::SampleInfo&) {
      if (w.server_id() == me) return;
      for (const auto& v : w.vehicles()) others_[v.vehicle_id()] = {w.server_id(), now};
    });
    input_reader_.Take([&](const pb::DriverInput& in, const transport::SampleInfo& info) {
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
      auto known = strengths.find(info.publication_handle);
      if (known == strengths.end()) {
        known = strengths.emplace(info.publication_handle,
                                  input_reader_.WriterStrength(info.publication_handle)).first;
      }
      // Only the source that drives this vehicle now reaches the loop.
      if (!arbiter_.Offer(in, info.publication_handle, known->second, now)) return;
      pb::DriverInput* slot = inputs_.Reserve();
      if (slot == nullptr) {
        drops_.Count(drop_inputs_full_);
        return;
      }
      *slot = in;
      inputs_.Commit();
      handed = true;
    });
    control_reader_.Take(
        [&](const pb::ControlRequest& r, const transport::SampleInfo& info) {
          if (!r.server_id().empty() && r.server_id() != me) return;  // another server's
          if (info.key != r.vehicle_id()) {
            Refuse(r, "the envelope key " + std::to_string(info.key) +
                          " does not match vehicle_id " + std::to_string(r.vehicle_id()));
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
          control_writers[info.publication_handle] = 0;
          Request req{std::make_unique<pb::ControlRequest>(r), info.publication_handle};
          if (!requests_.TryPush(std::move(req))) {
            drops_.Count(drop_requests_full_);
            Refuse(r, "the server is busy: too many requests waiting; try again");
            return;
          }
          handed = true;
        },
        64);
    while (spent_requests_.TryPop(spent)) spent.reset();
    if (handed) loop_bell_.Ring();

    if (now >= next_housekeeping) {
      next_housekeeping = now + base::Milliseconds(200);
      // Clients whose control writer has gone: their pending steps are dropped. Gone means
      // missing from the matched writers at two checks in a row (a query that fails tells
      // nothing): a client waiting for a reply is never dropped on one odd answer.
      std::vector<std::uint64_t> live;
      if (!control_writers.empty() && control_reader_.MatchedWriterHandles(live)) {
        for (auto it = control_writers.begin(); it != control_writers.end();) {
          const bool present = std::find(live.begin(), live.end(), it->first) != live.end();
          it->second = present ? 0 : it->second + 1;
          if (it->second >= 2 && gone_clients_.TryPush(std::uint64_t{it->first})) {
            spdlog::info("server '{}': a control client is gone; its pending steps are dropped",
                         me);
            it = control_writers.erase(it);
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
        for (auto it = strengths.begin(); it != strengths.end();) {
          it = std::find(live.begin(), live.end(), it->first) == live.end() ? strengths.erase(it)
                                                                            : std::next(it);
        }
      }
      std::vector<InputArbiter::Source> copy = arbiter_.Snapshot(now);
      std::lock_guard<std::mutex> lock(sources_mu_);
      sources_copy_ = std::move(copy);
    }
  }
  input_reader_.on_refused = nullptr;
  control_reader_.on_refused = nullptr;
}

std::string ServerNode::FindClash() {
  // Listen for what other servers publish about themselves: their worlds (transient-local, at
  // once), diagnostics (once a second) and states. With nobody else on the domain the wait ends
  // after discovery (300 ms); once another server is seen, for up to discovery_s.
  const std::string& me = options_.session.server_id;
  transport::DropCounters drops;
  transport::Reader<pb::WorldDescription> worlds(participant_, TopicId::kWorld, &drops);
  transport::Reader<pb::Diagnostics> diagnostics(participant_, TopicId::kDiagnostics, &drops);
  transport::Reader<pb::VehicleState> states(participant_, TopicId::kState, &drops);
  transport::Waitset waitset(participant_);
  waitset.Attach(worlds);
  waitset.Attach(diagnostics);
  waitset.Attach(states);
  const base::MonoTime start = base::MonotonicNow();
  const base::MonoTime quiet_end = start + base::Milliseconds(300);
  const base::MonoTime end =
      start + base::Nanos{static_cast<std::int64_t>(options_.discovery_s * 1e9)};
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
  while (true) {
    const base::MonoTime now = base::MonotonicNow();
    const bool others = foreign(worlds) || foreign(diagnostics) || foreign(states);
    if (now >= end || (!others && now >= quiet_end)) break;
    waitset.Wait(std::chrono::milliseconds(20));
    worlds.Take([&](const pb::WorldDescription& w, const transport::SampleInfo&) {
      for (const auto& v : w.vehicles()) note(w.server_id(), v.vehicle_id());
      if (w.server_id() == me) same_id = true;
    });
    diagnostics.Take([&](const pb::Diagnostics& d, const transport::SampleInfo&) {
      for (const auto& v : d.vehicles()) note(d.server_id(), v.vehicle_id());
      if (d.server_id() == me) same_id = true;
    });
    states.Take([&](const pb::VehicleState& st, const transport::SampleInfo&) {
      note(st.server_id(), st.vehicle_id());
    });
    // Decided as soon as a clash is certain.
    bool clash = same_id;
    for (std::uint32_t id : options_.vehicle_ids) clash = clash || taken.count(id) != 0;
    if (clash) break;
  }
  for (const auto& [vehicle, server] : taken) others_[vehicle] = {server, base::MonotonicNow()};
  const std::string domain = std::to_string(options_.domain_id);
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
  for (int i = 0; i < r.n_vehicles; ++i) {
    const VehicleReport& v = r.vehicles[static_cast<std::size_t>(i)];
    pb::VehicleDiagnostics* vd = d.add_vehicles();
    vd->set_vehicle_id(v.id);
    vd->set_watchdog_safe_state(v.safe_state);
    vd->set_input_age_ms(v.input_age_ms);
    vd->set_input_source(v.source);
    vd->set_nonfinite_steps(v.nonfinite_steps);
    vd->set_sanitized_inputs(v.sanitized_inputs);
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
  PublishOne(TopicId::kDiagnostics, transport::ServerKey(server_id), d,
             base::MonotonicNow() + base::Milliseconds(100));

  // The status line: rewritten in place on a terminal, a line every 5 s into a file.
  static const bool tty = isatty(STDERR_FILENO) == 1;
  const std::int64_t now = base::MonotonicNow().ns;
  if (!options_.status_line || (!tty && now - last_status_ns_ < 5'000'000'000)) return;
  last_status_ns_ = now;
  std::string vehicles;
  for (int i = 0; i < r.n_vehicles; ++i) {
    const VehicleReport& v = r.vehicles[static_cast<std::size_t>(i)];
    char buf[96];
    std::snprintf(buf, sizeof buf, "  v%u %5.1f km/h%s", v.id, v.speed_kmh,
                  v.safe_state ? " (no input: braking)" : "");
    vehicles += buf;
  }
  std::fprintf(stderr, "%st %7.2f s%s | %6.0f steps/s | late p50 %4.0f p99 %5.0f max %6.0f us  %s",
               tty ? "\r" : "", static_cast<double>(r.sim_time_ns) * 1e-9, vehicles.c_str(), rate,
               p50, p99, max_us, tty ? "" : "\n");
  std::fflush(stderr);
}

void ServerNode::PublisherLoop() {
  const std::string& server_id = options_.session.server_id;
  const std::uint64_t terrain_hash = TerrainHash(world_->terrain);
  Outgoing out;
  std::unique_ptr<pb::ControlReply> early;
  SessionEventRecord rec;
  auto queues_empty = [&] {
    return outbox_.empty() && early_replies_.empty() && reports_.empty() && events_.empty();
  };
  while (true) {
    const std::uint32_t token = publisher_bell_.Token();
    const base::MonoTime now = base::MonotonicNow();
    const std::int64_t deadline = publisher_deadline_ns_.load(std::memory_order_relaxed);
    if (publisher_stop_.load() && (queues_empty() || (deadline != 0 && now.ns >= deadline))) {
      const std::size_t left = outbox_.size() + events_.size() + early_replies_.size();
      if (left > 0) {
        spdlog::warn("server '{}': {} messages not sent by the shutdown deadline", server_id, left);
      }
      break;
    }
    // Replies, parameters and the world first: a slow recorder never delays an answer.
    while (outbox_.TryPop(out)) {
      PublishOne(out.topic, out.key, *out.msg, now + base::Seconds(1));
      if (out.topic == TopicId::kControlReply) {
        const auto& reply = static_cast<const pb::ControlReply&>(*out.msg);
        if (!reply.accepted()) {
          spdlog::debug("refused request {} of '{}': {}", reply.request_id(),
                        base::Quote(reply.client_id(), 64), base::Quote(reply.reason(), 200));
        }
      }
      out.msg.reset();
    }
    while (early_replies_.TryPop(early)) {
      PublishOne(TopicId::kControlReply, early->vehicle_id(), *early, now + base::Seconds(1));
      early.reset();
    }
    while (WindowReport* r = reports_.Front()) {
      PublishReport(*r);
      reports_.Pop();
    }
    // Then events, a batch at a time.
    for (int n = 0; n < 64 && events_.TryPop(rec); ++n) {
      const pb::SessionEvent e = ToMessage(rec, server_id, terrain_hash, options_.session.step_ns);
      rec.message.reset();
      rec.params.reset();
      PublishOne(TopicId::kEvents, e.vehicle_id(), e, base::MonotonicNow() + base::Seconds(1));
      const pb::VehicleParams* params = nullptr;
      if (e.has_spawned()) params = &e.spawned().params();
      if (e.has_params_changed()) params = &e.params_changed().params();
      if (params != nullptr) {
        PublishOne(TopicId::kParams, e.vehicle_id(), *params,
                   base::MonotonicNow() + base::Seconds(1));
      }
    }
    drops_.Report();
    if (queues_empty() && !publisher_stop_.load()) {
      publisher_bell_.Wait(token, base::Milliseconds(500));
    }
  }
  drops_.Report();
}

}  // namespace vdyn
