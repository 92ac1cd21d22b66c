// The rig loop's link to the domain over DDS: driver input written with the rig's ownership
// strength (client::InputPublisher), the vehicle's newest state and parameters
// (client::SessionView), and reset requests sent from a thread of their own (a request waits
// for its reply; the 1 kHz loop never does).
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <mutex>
#include <string>
#include <thread>

#include "vdyn/client/driver_input.h"
#include "vdyn/client/session_view.h"
#include "vdyn/transport/control_client.h"
#include "vdyn/wheel_input/rig.h"

namespace vdyn::wheel_input {

class DdsLink : public InputSink, public VehicleFeed, public Resetter {
 public:
  DdsLink(transport::Participant& participant, std::uint32_t vehicle_id, std::string source_id,
          std::int32_t strength);
  ~DdsLink() override;

  bool Publish(pb::DriverInput& msg, base::MonoTime sampled) override;
  std::string last_error() const override { return publisher_.last_error(); }

  void Poll() override { view_.Poll(); }
  const pb::VehicleState* state() const override;
  base::MonoTime state_received() const override;
  std::int64_t state_source_wall_ns() const override;
  const pb::VehicleParams* params() const override;

  void RequestReset() override;
  std::uint64_t resets_accepted() const { return resets_accepted_; }

  // Waits up to `timeout` for the vehicle's parameters (a late joiner gets them at once).
  // (or until *stop: Ctrl-C during --wait; false then)
  bool WaitForParams(std::chrono::nanoseconds timeout, const std::atomic<bool>* stop = nullptr);
  client::SessionView& view() { return view_; }

 private:
  void ResetWorker();

  std::uint32_t vehicle_id_;
  std::string source_id_;
  client::InputPublisher publisher_;
  client::SessionView view_;
  transport::ControlClient control_;
  std::mutex mu_;
  std::condition_variable cv_;
  bool reset_pending_ = false;
  bool stop_ = false;
  std::atomic<std::uint64_t> resets_accepted_{0};
  std::thread worker_;
};

}  // namespace vdyn::wheel_input
