#include "vdyn/transport/control_client.h"

#include <algorithm>
#include <memory>

#include "vdyn/world.pb.h"

namespace vdyn::transport {

bool WaitUntilServerKnowsReaders(Participant& participant, std::chrono::milliseconds timeout,
                                 const std::string& server_id) {
  DropCounters drops;
  std::unique_ptr<Reader<pb::WorldDescription>> world;
  try {
    world = std::make_unique<Reader<pb::WorldDescription>>(participant, TopicId::kWorld, &drops);
  } catch (const TransportError&) {
    return true;  // not permitted to read the world (DDS Security): nothing to wait on
  }
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  for (;;) {
    bool seen = false;
    (void)world->Take([&](const pb::WorldDescription& w, const SampleInfo&) {
      seen = seen || server_id.empty() || w.server_id() == server_id;
    });
    if (seen) return true;
    const auto now = std::chrono::steady_clock::now();
    if (now >= deadline) return false;
    (void)world->Wait(std::min<std::chrono::nanoseconds>(deadline - now, std::chrono::milliseconds(20)));
  }
}

ControlClient::ControlClient(Participant& participant, std::string client_id)
    : participant_(participant),
      client_id_(std::move(client_id)),
      writer_(participant, TopicId::kControl),
      reader_(participant, TopicId::kControlReply, &drops_) {}

bool ControlClient::WaitForServer(std::chrono::milliseconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (writer_.MatchedReaders() == 0 || reader_.MatchedWriters() == 0) {
    if (std::chrono::steady_clock::now() >= deadline) {
      last_error_ = "no server matched within " + std::to_string(timeout.count()) + " ms";
      return false;
    }
    (void)reader_.Wait(std::chrono::milliseconds(20));
  }
  const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
      std::max(deadline - std::chrono::steady_clock::now(), std::chrono::steady_clock::duration{}));
  if (!WaitUntilServerKnowsReaders(participant_, left)) {
    last_error_ = "a server matched this client but its world did not arrive within " +
                  std::to_string(timeout.count()) +
                  " ms (it may not know where to send its replies yet)";
    return false;
  }
  return true;
}

std::optional<pb::ControlReply> ControlClient::Call(pb::ControlRequest request,
                                                    std::chrono::milliseconds timeout) {
  request.set_request_id(next_id_++);
  request.set_client_id(client_id_);
  if (!writer_.Write(request.vehicle_id(), request)) {
    last_error_ = writer_.last_error();
    return std::nullopt;
  }
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  std::optional<pb::ControlReply> reply;
  while (!reply) {
    (void)reader_.Take([&](const pb::ControlReply& r, const SampleInfo&) {
      if (r.client_id() == client_id_ && r.request_id() == request.request_id()) reply = r;
    });
    if (reply) break;
    const auto now = std::chrono::steady_clock::now();
    if (now >= deadline) {
      last_error_ = "no reply to request " + std::to_string(request.request_id()) + " within " +
                    std::to_string(timeout.count()) + " ms";
      if (request.server_id().empty()) {
        last_error_ += " (no server answered: is a server running that owns vehicle " +
                       std::to_string(request.vehicle_id()) + "?)";
      } else {
        last_error_ += " (no server '" + request.server_id() + "' answered)";
      }
      return std::nullopt;
    }
    (void)reader_.Wait(std::min<std::chrono::nanoseconds>(deadline - now, std::chrono::milliseconds(50)));
  }
  return reply;
}

}  // namespace vdyn::transport
