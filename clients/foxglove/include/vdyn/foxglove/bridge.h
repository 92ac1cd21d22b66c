// The session side of vdyn-foxglove: what DDS carries becomes Foxglove channels, and Foxglove
// clients' requests become control requests and driver input.
//
//   /vehicle/<id>/state  vdyn.pb.VehicleState, every state (or --state-hz)     advertised while
//   /vehicle/<id>/tf     foxglove.FrameTransforms, latest only, --scene-hz      the vehicle sends
//   /vehicle/<id>/scene  foxglove.SceneUpdate, latest only, --scene-hz          states
//   /vdyn/world          foxglove.SceneUpdate: the terrain, sent to each new subscriber
//   /vdyn/diagnostics    vdyn.pb.Diagnostics;  /vdyn/events  vdyn.pb.SessionEvent
//
// Threads: Run() is the source thread (DDS in; serialises only what someone subscribed to, once
// for every subscriber; pushes into the clients' Outboxes and never waits for a client). The
// ClientHandler calls come on the server's thread. A parameter change waits for the server's
// reply on a requests thread of its own. docs/topics.md and clients/foxglove/README.md.
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>

#include "vdyn/base/time.h"
#include "vdyn/foxglove/scene.h"
#include "vdyn/foxglove/server.h"
#include "vdyn/transport/dds.h"

namespace vdyn::foxglove {

struct BridgeConfig {
  std::string name = "vdyn-foxglove";
  double state_hz = 0;  // 0: every state
  double scene_hz = 60;
  SceneOptions scene;
  bool allow_input = false;          // client publish: driving from the browser
  std::int32_t input_strength = 10;  // the ownership strength of that input (as vdyn-input's)
  base::Nanos vehicle_timeout = base::Seconds(3);  // unadvertised after this long without a state
  std::chrono::milliseconds request_timeout{3000};
};

class Bridge final : public ClientHandler {
 public:
  Bridge(transport::Participant& participant, BridgeConfig config);
  ~Bridge() override;
  Bridge(const Bridge&) = delete;
  Bridge& operator=(const Bridge&) = delete;

  // How to close a client (the server's Close), for one whose control queue overflowed.
  void SetCloser(std::function<void(ClientId, const std::string&)> close);
  // Where the notable events go (vehicles and clients that come and go, worlds); called from the
  // bridge's threads, one at a time or not: the function serialises its output. Set before Run.
  void SetLog(std::function<void(const std::string&)> log);
  // The source loop until `stop`.
  void Run(const std::atomic<bool>& stop);
  // Forgets every client (after the server stopped: nothing is pushed to their queues again).
  void CloseAll();

  struct Counters {
    int clients = 0, subscriptions = 0, vehicles = 0;
    std::uint64_t states_in = 0, states_refused = 0;  // refused: not drawable (CheckState)
    std::uint64_t dds_lost = 0;      // samples DDS reports lost to the state readers (best effort)
    std::uint64_t messages_out = 0;  // message data handed to the clients' queues
    std::uint64_t dropped_messages = 0, dropped_bytes = 0;  // by the queues' bounds
    std::uint64_t bad_messages = 0;               // client messages that could not be used
    std::uint64_t inputs = 0, input_refused = 0;  // driver input from clients
    std::uint64_t input_clamped = 0;              // of the inputs, those clamped to the limits
    std::uint64_t params_accepted = 0, params_refused = 0;
    std::string last_refusal;
  };
  Counters counters() const;

  void OnOpen(ClientId id, const std::shared_ptr<Outbox>& outbox, const std::string& subprotocol,
              const std::string& peer) override;
  void OnText(ClientId id, std::string_view text) override;
  void OnBinary(ClientId id, std::span<const std::uint8_t> message) override;
  void OnClose(ClientId id, const std::string& why) override;

  struct Impl;

 private:
  std::unique_ptr<Impl> impl_;
};

}  // namespace vdyn::foxglove
