#include "vdyn/telemetry/bridge.h"

#include <array>
#include <cstdio>

#include <fmt/format.h>

#include "vdyn/client/loop.h"

namespace vdyn::telemetry {
namespace {

client::SessionView::Topics StateAndParams(std::uint32_t vehicle_id) {
  client::SessionView::Topics t;
  t.only_vehicle = vehicle_id;  // its partition: the other vehicles' states are not sent here
  t.states = true;
  t.params = true;  // which dash lights the car has
  t.world = false;  // worlds can be large and say nothing a dashboard shows
  t.diagnostics = false;
  return t;
}

std::string Destinations(const UdpSender* s) {
  if (s == nullptr) return "";
  std::string out;
  for (const auto& d : s->destinations()) out += (out.empty() ? "" : ", ") + d.text;
  return out;
}

}  // namespace

Bridge::Bridge(transport::Participant& participant, BridgeConfig config)
    : config_(std::move(config)), view_(participant, StateAndParams(config_.vehicle_id)) {
  outsim_.name = "OutSim";
  outsim_.hz = config_.outsim_hz;
  if (!config_.outsim.empty()) outsim_.sender = std::make_unique<UdpSender>(config_.outsim);
  outgauge_.name = "OutGauge";
  outgauge_.hz = config_.outgauge_hz;
  if (!config_.outgauge.empty()) outgauge_.sender = std::make_unique<UdpSender>(config_.outgauge);
}

Bridge::~Bridge() {
  stop_streams_ = true;
  for (Stream* s : {&outsim_, &outgauge_}) {
    if (s->thread.joinable()) s->thread.join();
  }
}

void Bridge::StreamLoop(Stream& stream, bool outsim) {
  client::FixedRateLoop loop(base::Nanos{static_cast<std::int64_t>(1e9 / stream.hz)});
  std::array<std::uint8_t, 128> buf{};
  const GaugeOptions gauge{config_.car, config_.outgauge_id};
  while (!stop_streams_) {
    const auto tick = loop.Wait();
    if (stop_streams_) break;
    ++stream.ticks;
    stream.skipped += tick.skipped;
    std::size_t n = 0;
    {
      std::lock_guard<std::mutex> lock(mu_);
      if (!latest_.have || tick.now - latest_.received > config_.stale_after) {
        ++stream.held;
        continue;
      }
      if (outsim) {
        n = Encode(MakeOutSim(latest_.state, config_.outsim_id), config_.outsim_id != 0, buf);
      } else {
        const pb::VehicleParams* params = latest_.params ? &*latest_.params : nullptr;
        n = Encode(MakeOutGauge(latest_.state, params, gauge), config_.outgauge_id != 0, buf);
      }
    }
    stream.sender->Send(std::span<const std::uint8_t>(buf.data(), n));
  }
}

void Bridge::Run(const std::atomic<bool>& stop, const std::function<void(const std::string&)>& say,
                 base::Nanos status_period) {
  auto describe = [&](const Stream& s, std::int32_t id, std::size_t size) {
    if (!s.sender) return std::string();
    return fmt::format("{} {:.4g} Hz, {} bytes{}, to {}", s.name, s.hz,
                       size + (id != 0 ? kIdSize : 0), id != 0 ? fmt::format(" (ID {})", id) : "",
                       Destinations(s.sender.get()));
  };
  std::string streams = describe(outsim_, config_.outsim_id, kOutSimSize);
  const std::string gauge = describe(outgauge_, config_.outgauge_id, kOutGaugeSize);
  if (!gauge.empty()) streams += (streams.empty() ? "" : "; ") + gauge;
  say(fmt::format("vdyn-telemetry: vehicle {}: {}; waiting for its states", config_.vehicle_id,
                  streams));
  if (!view_.one_vehicle_fallback().empty()) {
    say(fmt::format("vdyn-telemetry: reading every vehicle's states ({})",
                    view_.one_vehicle_fallback()));
  }
  if (outsim_.sender) outsim_.thread = std::thread([this] { StreamLoop(outsim_, true); });
  if (outgauge_.sender) outgauge_.thread = std::thread([this] { StreamLoop(outgauge_, false); });

  last_status_ = base::MonotonicNow();
  std::uint64_t seen = 0;
  base::MonoTime params_taken;
  bool fresh = false, ever = false;
  const double stale_s = config_.stale_after.seconds();
  while (!stop) {
    (void)view_.Wait(std::chrono::milliseconds(50));
    view_.Poll();
    const client::SessionView::Vehicle* v = view_.vehicle(config_.vehicle_id);
    const base::MonoTime now = base::MonotonicNow();
    // Parameters change rarely (a request replaces them): taken when they first come and then
    // once a second, not with every state.
    const bool params_due =
        v != nullptr && v->params && (!latest_.params || now - params_taken >= base::Seconds(1));
    if (v != nullptr && (v->states != seen || params_due)) {
      std::lock_guard<std::mutex> lock(mu_);
      if (v->states != seen) {
        states_ += v->states - seen;
        seen = v->states;
        latest_.state = v->state;
        latest_.received = v->received;
        latest_.have = true;
      }
      if (params_due) {
        latest_.params = v->params;
        params_taken = now;
      }
    }
    bool now_fresh = false;
    {
      std::lock_guard<std::mutex> lock(mu_);
      now_fresh = latest_.have && now - latest_.received <= config_.stale_after;
    }
    if (now_fresh && !fresh) {
      say(ever ? fmt::format("vdyn-telemetry: vehicle {}: states again: sending resumed",
                             config_.vehicle_id)
               : fmt::format("vdyn-telemetry: vehicle {}: first state (server '{}'): sending",
                             config_.vehicle_id, latest_.state.server_id()));
      ever = true;
    } else if (!now_fresh && fresh) {
      ++pauses_;
      say(fmt::format(
          "vdyn-telemetry: vehicle {}: no state for {:.3g} s (stale limit): sending paused",
          config_.vehicle_id, stale_s));
    }
    fresh = now_fresh;
    if (status_period.ns > 0 && now - last_status_ >= status_period) say(StatusLine());
  }
  stop_streams_ = true;
  for (Stream* s : {&outsim_, &outgauge_}) {
    if (s->thread.joinable()) s->thread.join();
  }
}

Bridge::StreamCounters Bridge::Counters(const Stream& s) const {
  StreamCounters c;
  c.ticks = s.ticks.load();
  c.held = s.held.load();
  c.skipped = s.skipped.load();
  if (s.sender) {
    c.sent = s.sender->sent();
    c.errors = s.sender->errors();
  }
  return c;
}

Bridge::StreamCounters Bridge::outsim() const {
  return Counters(outsim_);
}
Bridge::StreamCounters Bridge::outgauge() const {
  return Counters(outgauge_);
}

std::string Bridge::StatusLine() {
  const base::MonoTime now = base::MonotonicNow();
  const double dt = (now - last_status_).seconds();
  last_status_ = now;
  std::string line;
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (!latest_.have) {
      line = fmt::format("vehicle {}: no state yet", config_.vehicle_id);
    } else {
      const auto& s = latest_.state;
      const std::uint8_t g = GaugeGear(s);
      const std::string gear = g == kGaugeGearReverse   ? "R"
                               : g == kGaugeGearNeutral ? "N"
                                                        : std::to_string(g - 1);
      line = fmt::format("vehicle {}: step {}, {:.1f} km/h, gear {}, state age {:.0f} ms",
                         config_.vehicle_id, s.step(), s.speed_kmh(), gear,
                         (now - latest_.received).millis());
    }
  }
  for (Stream* s : {&outsim_, &outgauge_}) {
    if (!s->sender) continue;
    const StreamCounters c = Counters(*s);
    const double per_dest = static_cast<double>(s->sender->destinations().size());
    const double rate =
        dt > 0 ? static_cast<double>(c.sent - s->sent_at_status) / dt / per_dest : 0;
    s->sent_at_status = c.sent;
    line += fmt::format(" | {} {:.0f}/s to {}: {} sent, {} errors", s->name, rate,
                        s->sender->destinations().size(), c.sent, c.errors);
    if (c.errors > 0) line += " (" + s->sender->last_error() + ")";
  }
  return line;
}

std::string Bridge::Summary() const {
  std::string out =
      fmt::format("vdyn-telemetry: vehicle {}: {} states taken, {} pauses (stale states)",
                  config_.vehicle_id, states_.load(), pauses_.load());
  for (const Stream* s : {&outsim_, &outgauge_}) {
    if (!s->sender) continue;
    const StreamCounters c = Counters(*s);
    out += fmt::format(
        "\n  {}: {} ticks at {:.4g} Hz, {} sent, {} send errors, {} ticks held (no "
        "fresh state), {} ticks skipped (this machine was busy)",
        s->name, c.ticks, s->hz, c.sent, c.errors, c.held, c.skipped);
  }
  return out;
}

}  // namespace vdyn::telemetry
