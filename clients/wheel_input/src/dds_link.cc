#include "vdyn/wheel_input/dds_link.h"

#include <spdlog/spdlog.h>

#include "vdyn/base/deadline.h"

namespace vdyn::wheel_input {

DdsLink::DdsLink(transport::Participant& participant, std::uint32_t vehicle_id,
                 std::string source_id, std::int32_t strength)
    : vehicle_id_(vehicle_id),
      source_id_(source_id),
      publisher_(participant, vehicle_id, source_id, strength),
      view_(participant, client::SessionView::Topics{.states = true,
                                                     .params = true,
                                                     .world = false,
                                                     .diagnostics = false,
                                                     .inputs = false,
                                                     .only_vehicle = vehicle_id, .only_server = {}}),
      control_(participant, source_id) {
  if (!view_.one_vehicle_fallback().empty()) {
    spdlog::warn("vdyn-input: reading every vehicle's states ({})", view_.one_vehicle_fallback());
  }
  worker_ = std::thread([this] { ResetWorker(); });
}

DdsLink::~DdsLink() {
  {
    std::lock_guard<std::mutex> lock(mu_);
    stop_ = true;
  }
  cv_.notify_all();
  worker_.join();
}

bool DdsLink::Publish(pb::DriverInput& msg, base::MonoTime sampled) {
  return publisher_.Publish(msg, sampled);
}

const pb::VehicleState* DdsLink::state() const {
  const auto* v = view_.vehicle(vehicle_id_);
  return v != nullptr && v->states > 0 ? &v->state : nullptr;
}

base::MonoTime DdsLink::state_received() const {
  const auto* v = view_.vehicle(vehicle_id_);
  return v != nullptr ? v->received : base::MonoTime{};
}

std::int64_t DdsLink::state_source_wall_ns() const {
  const auto* v = view_.vehicle(vehicle_id_);
  return v != nullptr ? v->source_timestamp_ns : 0;
}

const pb::VehicleParams* DdsLink::params() const {
  const auto* v = view_.vehicle(vehicle_id_);
  return v != nullptr && v->params ? &*v->params : nullptr;
}

bool DdsLink::WaitForParams(std::chrono::nanoseconds timeout, const std::atomic<bool>* stop) {
  return base::PollUntil(
      base::Deadline::After(base::Nanos{timeout.count()}), base::Milliseconds(50),
      [&] {
        view_.Poll();
        return params() != nullptr || (stop != nullptr && stop->load());
      },
      [&](base::Nanos slice) { (void)view_.Wait(base::Chrono(slice)); });
}

void DdsLink::RequestReset() {
  {
    std::lock_guard<std::mutex> lock(mu_);
    reset_pending_ = true;
  }
  cv_.notify_all();
}

void DdsLink::ResetWorker() {
  std::unique_lock<std::mutex> lock(mu_);
  while (true) {
    cv_.wait(lock, [&] { return stop_ || reset_pending_; });
    if (stop_) return;
    reset_pending_ = false;
    lock.unlock();
    pb::ControlRequest req;
    req.set_vehicle_id(vehicle_id_);
    req.mutable_reset();
    // The first request waits for a server's answer to a hello (before the server has
    // discovered this client, a request reaches no one).
    const auto reply = control_.CallGreeted(req, std::chrono::seconds(2));
    if (!reply) {
      spdlog::warn("vdyn-input: reset of vehicle {}: {}", vehicle_id_, control_.last_error());
    } else if (!reply->accepted()) {
      spdlog::warn("vdyn-input: reset of vehicle {} refused: {}", vehicle_id_, reply->reason());
    } else {
      ++resets_accepted_;
      spdlog::info("vdyn-input: vehicle {} reset", vehicle_id_);
    }
    lock.lock();
  }
}

}  // namespace vdyn::wheel_input
