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
    : client_id_(std::move(client_id)),
      writer_(participant, TopicId::kControl),
      reader_(participant, TopicId::kControlReply, &drops_) {}

bool ControlClient::WaitForServer(std::chrono::milliseconds timeout, const std::string& server_id) {
  using Clock = std::chrono::steady_clock;
  const auto deadline = Clock::now() + timeout;
  while (writer_.MatchedReaders() == 0 || reader_.MatchedWriters() == 0) {
    if (Clock::now() >= deadline) {
      last_error_ = "no server matched within " + std::to_string(timeout.count()) + " ms";
      return false;
    }
    (void)reader_.Wait(std::chrono::milliseconds(20));
  }
  // Matching shows only this side's view (and a recorder's reader of requests matches too): a
  // hello, sent again until one is answered, shows both ways work from the server's side.
  pb::ControlRequest hello;
  hello.mutable_hello();
  hello.set_client_id(client_id_);
  hello.set_server_id(server_id);
  const std::uint64_t first_id = next_id_;
  int sent = 0;
  auto send_at = Clock::now();
  for (;;) {
    auto now = Clock::now();
    if (now >= send_at && now < deadline) {
      hello.set_request_id(next_id_++);
      if (!writer_.Write(0, hello)) {
        last_error_ = writer_.last_error();
        return false;
      }
      ++sent;
      send_at = now + kHelloInterval;
    }
    bool answered = false;
    (void)reader_.Take([&](const pb::ControlReply& r, const SampleInfo&) {
      if (answered || r.client_id() != client_id_ || r.request_id() < first_id ||
          r.request_id() >= next_id_ || (!server_id.empty() && r.server_id() != server_id)) {
        return;
      }
      answered = true;
      answering_server_ = r.server_id();
    });
    if (answered) return true;
    now = Clock::now();
    if (now >= deadline) {
      last_error_ = std::string(server_id.empty() ? "no server" : "server '" + server_id + "'") +
                    " answered none of this client's " + std::to_string(sent) +
                    " hello request(s) within " + std::to_string(timeout.count()) +
                    " ms; its requests are read (by " +
                    (server_id.empty() ? "a server" : "that server or another") +
                    " that has not discovered this client yet, a recorder, or a program that "
                    "is not a vdyn server)";
      return false;
    }
    (void)reader_.Wait(std::max<Clock::duration>(std::min(deadline, send_at) - now, {}));
  }
}

std::optional<pb::ControlReply> ControlClient::CallGreeted(pb::ControlRequest request,
                                                           std::chrono::milliseconds timeout) {
  if (!greeted_.contains(request.server_id())) {
    if (!WaitForServer(timeout, request.server_id())) return std::nullopt;
    greeted_.insert(request.server_id());
  }
  return Call(std::move(request), timeout);
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
