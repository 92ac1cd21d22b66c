#include "server_node.h"

#include <unistd.h>

#include <cmath>
#include <cstdio>

#include <spdlog/spdlog.h>

#include "convert.h"

namespace vdyn {

using transport::TopicId;

ServerNode::ServerNode(std::shared_ptr<const World> world, ServerOptions options)
    : world_(std::move(world)),
      options_(std::move(options)),
      participant_(options_.domain_id),
      state_writer_(participant_, TopicId::kState),
      input_reader_(participant_, TopicId::kInput, &drops_),
      control_reader_(participant_, TopicId::kControl, &drops_) {
  for (TopicId t : {TopicId::kControlReply, TopicId::kParams, TopicId::kWorld, TopicId::kEvents,
                    TopicId::kDiagnostics}) {
    writers_[t] = std::make_unique<transport::RawWriter>(participant_, t);
  }
  session_ = std::make_unique<Session>(world_, options_.session,
                                       [this](const pb::SessionEvent& e) { OnEvent(e); });
  // The world first (transient-local: viewers joining later get it), then the vehicles.
  auto world_msg = std::make_unique<pb::WorldDescription>(
      DescribeWorld(*world_, options_.session.server_id, options_.session.step_ns));
  const double lateral = 5.0;  // several vehicles start side by side
  for (std::size_t i = 0; i < options_.vehicle_ids.size(); ++i) {
    Pose2 pose = world_->spawn;
    pose.x -= std::sin(pose.yaw) * lateral * static_cast<double>(i);
    pose.y += std::cos(pose.yaw) * lateral * static_cast<double>(i);
    session_->Spawn(options_.vehicle_ids[i], pose, 0.0, pb::VehicleParams());
    *world_msg->add_vehicles() = DescribeVehicle(
        options_.vehicle_ids[i],
        session_->simulator(options_.vehicle_ids[i]).params());
  }
  Enqueue(TopicId::kWorld, transport::ServerKey(options_.session.server_id), std::move(world_msg));
  // Last: if anything above throws, no thread is left running.
  publisher_ = std::thread([this] { PublisherLoop(); });
}

ServerNode::~ServerNode() {
  {
    std::lock_guard<std::mutex> lock(mu_);
    publisher_stop_ = true;
  }
  cv_.notify_all();
  if (publisher_.joinable()) publisher_.join();
}

void ServerNode::Enqueue(TopicId topic, std::uint32_t key,
                         std::unique_ptr<google::protobuf::Message> msg) {
  {
    std::lock_guard<std::mutex> lock(mu_);
    auto& q = topic == TopicId::kEvents ? events_ : urgent_;
    if (urgent_.size() + events_.size() >= kMaxQueue) {
      drops_.Count("publisher queue full, not sent", transport::Spec(topic).name);
      return;
    }
    q.push_back({topic, key, std::move(msg)});
  }
  cv_.notify_one();
}

void ServerNode::PublisherLoop() {
  while (true) {
    Outgoing item;
    {
      std::unique_lock<std::mutex> lock(mu_);
      cv_.wait(lock, [this] { return publisher_stop_ || !urgent_.empty() || !events_.empty(); });
      if (urgent_.empty() && events_.empty()) return;  // stopping, all sent
      auto& q = !urgent_.empty() ? urgent_ : events_;
      item = std::move(q.front());
      q.pop_front();
    }
    transport::RawWriter& w = *writers_.at(item.topic);
    // A reliable write times out (10 ms) only while a reader's history is full: try again for
    // up to a second before giving the message up (a re-simulation needs every event).
    bool sent = false;
    for (int attempt = 0; attempt < 100 && !sent; ++attempt) sent = w.Write(item.key, *item.msg);
    if (!sent) {
      drops_.Count(std::string("write failed on ") + transport::Spec(item.topic).name,
                   w.last_error());
    }
  }
}

void ServerNode::OnEvent(const pb::SessionEvent& e) {
  Enqueue(TopicId::kEvents, e.vehicle_id(), std::make_unique<pb::SessionEvent>(e));
  const pb::VehicleParams* params = nullptr;
  if (e.has_spawned()) params = &e.spawned().params();
  if (e.has_params_changed()) params = &e.params_changed().params();
  if (params != nullptr) {
    auto msg = std::make_unique<pb::VehicleParams>(*params);
    Enqueue(TopicId::kParams, e.vehicle_id(), std::move(msg));
  }
}

void ServerNode::HandleRequest(const pb::ControlRequest& r) {
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
      if (!session_->OfferInput(r.step().input(), &why)) {
        drops_.Count("out-of-range input in a step request", why);
      }
    }
    reply = session_->Apply(r);
  }
  if (r.has_step() && reply.accepted()) {
    // Answered when its steps are done: the ones pending before it, then its own.
    deferred_step_replies_.push_back(
        {session_->steps() + static_cast<std::int64_t>(session_->pending_steps()), reply});
    return;
  }
  if ((r.has_pause() || r.has_resume()) && reply.accepted()) {
    CancelStepReplies(std::string("cancelled by a ") + (r.has_pause() ? "pause" : "resume") +
                      " request before its steps were done");
  }
  if (!reply.accepted()) {
    drops_.Count("rejected control request", reply.reason());
  }
  Enqueue(TopicId::kControlReply, r.vehicle_id(), std::make_unique<pb::ControlReply>(reply));
}

bool ServerNode::Boundary() {
  bool got_request = false;
  // At most 16 requests per step boundary: a flood waits in the reader (keep-all) instead of
  // stretching one step of the 1 kHz loop.
  control_reader_.Take(
      [&](const pb::ControlRequest& r, const transport::SampleInfo&) {
        got_request = true;
        HandleRequest(r);
      },
      16);
  input_reader_.Take([&](const pb::DriverInput& in, const transport::SampleInfo& info) {
    if (info.key != in.vehicle_id()) {
      drops_.Count("key mismatch on vdyn/input", "envelope key " + std::to_string(info.key) +
                                                     " vs vehicle_id " +
                                                     std::to_string(in.vehicle_id()));
      return;
    }
    if (!session_->HasVehicle(in.vehicle_id())) return;  // another server's vehicle
    std::string why;
    if (!session_->OfferInput(in, &why)) drops_.Count("out-of-range input on vdyn/input", why);
  });
  return got_request;
}

void ServerNode::StepOnce() {
  session_->Step([this](std::uint32_t id, const pb::VehicleState& s) {
    // Best effort, keep last 1: never blocks the loop.
    if (!state_writer_.Write(id, s)) {
      drops_.Count("write failed on vdyn/state", state_writer_.last_error());
    }
  });
  if (session_->paused()) session_->ConsumePendingStep();
  SendDueStepReplies();
}

void ServerNode::SendDueStepReplies() {
  std::vector<DeferredReply> waiting;
  for (DeferredReply& d : deferred_step_replies_) {
    if (d.target_steps > session_->steps()) {
      waiting.push_back(std::move(d));
      continue;
    }
    pb::ControlReply& reply = d.reply;
    if (session_->HasVehicle(reply.vehicle_id())) {
      reply.set_applied_step(
          static_cast<std::uint64_t>(session_->simulator(reply.vehicle_id()).state().step));
    }
    reply.set_sim_time_ns(session_->steps() * session_->step_ns());
    Enqueue(TopicId::kControlReply, reply.vehicle_id(), std::make_unique<pb::ControlReply>(reply));
  }
  deferred_step_replies_ = std::move(waiting);
}

void ServerNode::CancelStepReplies(const std::string& why) {
  for (DeferredReply& d : deferred_step_replies_) {
    d.reply.set_accepted(false);
    d.reply.set_reason(why);
    d.reply.set_sim_time_ns(session_->steps() * session_->step_ns());
    Enqueue(TopicId::kControlReply, d.reply.vehicle_id(),
            std::make_unique<pb::ControlReply>(d.reply));
  }
  deferred_step_replies_.clear();
}

void ServerNode::ReportWindow(std::int64_t now_ns) {
  const double wall_s = static_cast<double>(now_ns - window_start_ns_) * 1e-9;
  const std::int64_t cpu = ProcessCpuNs();
  auto d = std::make_unique<pb::Diagnostics>();
  d->set_server_id(options_.session.server_id);
  d->set_mode(options_.mode == ServerOptions::Mode::kRealtime ? "realtime" : "lockstep");
  d->set_sim_time_ns(session_->steps() * session_->step_ns());
  d->set_steps(static_cast<std::uint64_t>(session_->steps()));
  last_p50_us_ = lateness_.Percentile(50);
  last_p99_us_ = lateness_.Percentile(99);
  last_max_us_ = lateness_.Max();
  last_rate_hz_ = wall_s > 0 ? static_cast<double>(session_->steps() - window_start_steps_) / wall_s
                             : 0.0;
  d->set_lateness_p50_us(last_p50_us_);
  d->set_lateness_p99_us(last_p99_us_);
  d->set_lateness_max_us(last_max_us_);
  d->set_steps_caught_up(steps_caught_up_);
  d->set_max_lag_steps(max_lag_steps_seen_);
  d->set_step_rate_hz(last_rate_hz_);
  d->set_cpu_percent(wall_s > 0 ? 100.0 * static_cast<double>(cpu - window_start_cpu_ns_) * 1e-9 /
                                      wall_s
                                : 0.0);
  for (const auto& [kind, count] : drops_.Snapshot()) {
    pb::DropCount* dc = d->add_drops();
    dc->set_kind(kind);
    dc->set_count(count);
  }
  for (std::uint32_t id : session_->vehicle_ids()) {
    pb::VehicleDiagnostics* v = d->add_vehicles();
    v->set_vehicle_id(id);
    v->set_watchdog_safe_state(session_->in_safe_state(id));
    const double age = session_->input_age_s(id);
    v->set_input_age_ms(std::isfinite(age) ? age * 1000.0 : -1.0);
    v->set_input_source(session_->input_source(id));
    v->set_nonfinite_steps(session_->simulator(id).nonfinite_steps());
    v->set_sanitized_inputs(session_->simulator(id).sanitized_inputs());
  }
  d->set_scheduling(scheduling_);
  Enqueue(TopicId::kDiagnostics, transport::ServerKey(options_.session.server_id), std::move(d));
  lateness_.Clear();
  window_start_ns_ = now_ns;
  window_start_cpu_ns_ = cpu;
  window_start_steps_ = session_->steps();
}

void ServerNode::PrintStatus(std::int64_t now_ns) {
  // On a terminal the line rewrites itself 4 times a second; into a file, a line every 5 s.
  static const bool tty = isatty(STDERR_FILENO) == 1;
  if (!options_.status_line || now_ns - last_status_ns_ < (tty ? 250'000'000 : 5'000'000'000)) {
    return;
  }
  last_status_ns_ = now_ns;
  std::string vehicles;
  for (std::uint32_t id : session_->vehicle_ids()) {
    const double v = Velocity(session_->simulator(id).state().x).norm() * 3.6;
    char buf[96];
    std::snprintf(buf, sizeof buf, "  v%u %5.1f km/h%s", id, v,
                  session_->in_safe_state(id) ? " (no input: braking)" : "");
    vehicles += buf;
  }
  std::fprintf(stderr, "%st %7.2f s%s | %6.0f steps/s | late p50 %4.0f p99 %5.0f max %6.0f us  %s",
               tty ? "\r" : "",
               static_cast<double>(session_->steps()) * 1e-9 *
                   static_cast<double>(session_->step_ns()),
               vehicles.c_str(), last_rate_hz_, last_p50_us_, last_p99_us_, last_max_us_,
               tty ? "" : "\n");
  std::fflush(stderr);
}

int ServerNode::RunRealtime(const std::atomic<bool>& stop) {
  scheduling_ = SetUpRealtimeScheduling(options_.rt_priority);
  spdlog::info("server '{}': real time at {} Hz on domain {}, scheduling: {}",
               options_.session.server_id, 1e9 / static_cast<double>(options_.session.step_ns),
               options_.domain_id, scheduling_);
  const std::int64_t h = options_.session.step_ns;
  const auto end_steps = static_cast<std::int64_t>(
      std::llround(options_.duration_s * 1e9 / static_cast<double>(h)));
  const std::int64_t start_ns = MonotonicNowNs();
  const std::int64_t start_cpu_ns = ProcessCpuNs();
  std::int64_t next = start_ns + h;  // the deadline of step k is start + (k + 1) h
  window_start_ns_ = start_ns;
  window_start_cpu_ns_ = start_cpu_ns;
  while (!stop.load(std::memory_order_relaxed)) {
    SleepUntilNs(next);
    std::int64_t now = MonotonicNowNs();
    // Run every step whose deadline has passed: simulation time advances in exact steps and
    // catches up after a late wake-up; no step is skipped.
    int run_this_wake = 0;
    while (now >= next && !stop.load(std::memory_order_relaxed)) {
      const double late_us = static_cast<double>(now - next) * 1e-3;
      lateness_.Add(late_us);
      lateness_all_.Add(late_us);
      Boundary();
      if (!session_->paused() || session_->pending_steps() > 0) StepOnce();
      next += h;
      if (++run_this_wake > 1) ++steps_caught_up_;
      now = MonotonicNowNs();
      const std::int64_t lag = (now - next) / h;
      if (lag > 0) max_lag_steps_seen_ = std::max<std::uint64_t>(max_lag_steps_seen_, lag);
      if (lag > options_.max_lag_steps) {
        // The machine cannot keep up: start the schedule afresh from now (wall time is dropped,
        // never a step) and say so.
        ++schedule_rebases_;
        drops_.Count("schedule rebased: more than max_lag_steps behind");
        next = now + h;
      }
      if (end_steps > 0 && session_->steps() >= end_steps) break;
    }
    if (now - window_start_ns_ >= 1'000'000'000) ReportWindow(now);
    PrintStatus(now);
    if (end_steps > 0 && session_->steps() >= end_steps) break;
  }
  if (options_.status_line && isatty(STDERR_FILENO) == 1) std::fprintf(stderr, "\n");
  const std::int64_t end_ns = MonotonicNowNs();
  ReportWindow(end_ns);
  spdlog::info("server '{}': {} steps in {:.3f} s of wall time; tick lateness p50 {:.0f} us, p99 "
               "{:.0f} us, max {:.0f} us; {} steps caught up; drift {:.3f} ms",
               options_.session.server_id, session_->steps(),
               static_cast<double>(end_ns - start_ns) * 1e-9, lateness_all_.Percentile(50),
               lateness_all_.Percentile(99), lateness_all_.Max(), steps_caught_up_,
               (static_cast<double>(session_->steps() * session_->step_ns()) -
                static_cast<double>(end_ns - start_ns)) * 1e-6);
  if (!options_.stats_out.empty()) WriteStats(start_ns, end_ns, start_cpu_ns);
  return 0;
}

void ServerNode::WriteStats(std::int64_t start_ns, std::int64_t end_ns,
                            std::int64_t start_cpu_ns) const {
  std::FILE* f = std::fopen(options_.stats_out.c_str(), "w");
  if (f == nullptr) {
    spdlog::error("cannot write the run summary to {}", options_.stats_out);
    return;
  }
  const double wall_s = static_cast<double>(end_ns - start_ns) * 1e-9;
  const double sim_s = static_cast<double>(session_->steps()) *
                       static_cast<double>(session_->step_ns()) * 1e-9;
  // Steps whose deadline passed by the end but that never ran (a rebase drops wall time).
  const auto due = static_cast<std::int64_t>((end_ns - start_ns) / session_->step_ns());
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
               100.0 * static_cast<double>(ProcessCpuNs() - start_cpu_ns) * 1e-9 / wall_s);
  std::fprintf(f, "scheduling %s\n", scheduling_.c_str());
  std::fclose(f);
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
  window_start_ns_ = MonotonicNowNs();
  window_start_cpu_ns_ = ProcessCpuNs();
  std::int64_t last_request = MonotonicNowNs();
  const auto timeout_ns = static_cast<std::int64_t>(options_.lockstep_timeout_s * 1e9);
  while (!stop.load(std::memory_order_relaxed)) {
    // The client is silent only while no request comes and no steps it asked for are running.
    if (Boundary()) last_request = MonotonicNowNs();
    while (session_->pending_steps() > 0 && !stop.load(std::memory_order_relaxed)) {
      StepOnce();
      Boundary();
      last_request = MonotonicNowNs();
    }
    const std::int64_t now = MonotonicNowNs();
    if (now - window_start_ns_ >= 1'000'000'000) ReportWindow(now);
    if (now - last_request > timeout_ns) {
      spdlog::error("lockstep: no control request for {:.1f} s; the client is gone? stopping",
                    options_.lockstep_timeout_s);
      return 3;
    }
    control_reader_.Wait(std::chrono::milliseconds(20));
  }
  return 0;
}

int ServerNode::Run(const std::atomic<bool>& stop) {
  const int code = options_.mode == ServerOptions::Mode::kRealtime ? RunRealtime(stop)
                                                                    : RunLockstep(stop);
  // Let the publisher drain (replies, events, diagnostics) before the writers go away.
  for (int i = 0; i < 200; ++i) {
    {
      std::lock_guard<std::mutex> lock(mu_);
      if (urgent_.empty() && events_.empty()) break;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  return code;
}

}  // namespace vdyn
