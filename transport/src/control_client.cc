#include "vdyn/transport/control_client.h"

#include <algorithm>
#include <memory>

#include "vdyn/base/deadline.h"
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
  bool seen = false;
  return base::PollUntil(
      base::Deadline::After(base::FromChrono(timeout)), base::Milliseconds(20),
      [&] {
        (void)world->Take([&](const pb::WorldDescription& w, const SampleInfo&) {
          seen = seen || server_id.empty() || w.server_id() == server_id;
        });
        return seen;
      },
      [&](base::Nanos slice) { (void)world->Wait(base::Chrono(slice)); });
}

ControlClient::ControlClient(Participant& participant, std::string client_id)
    : client_id_(std::move(client_id)),
      writer_(participant, TopicId::kControl),
      reader_(participant, TopicId::kControlReply, &drops_) {}

bool ControlClient::WaitForServer(std::chrono::milliseconds timeout, const std::string& server_id) {
  const base::Deadline deadline = base::Deadline::After(base::FromChrono(timeout));
  // Matching is no sample to wait on: the reader's Wait returns early only if a reply arrives.
  if (!base::PollUntil(
          deadline, base::Milliseconds(20),
          [&] { return writer_.MatchedReaders() > 0 && reader_.MatchedWriters() > 0; },
          [&](base::Nanos slice) { (void)reader_.Wait(base::Chrono(slice)); })) {
    last_error_ = "no server matched within " + std::to_string(timeout.count()) + " ms";
    return false;
  }
  // Matching shows only this side's view (and a recorder's reader of requests matches too): a
  // hello, sent again every kHelloInterval until one is answered, shows both ways work from the
  // server's side.
  pb::ControlRequest hello;
  hello.mutable_hello();
  hello.set_client_id(client_id_);
  hello.set_server_id(server_id);
  const std::uint64_t first_id = next_id_;
  int sent = 0;
  base::Deadline send_at = base::Deadline::After(base::Nanos{0});
  bool answered = false, failed = false;
  const bool done = base::PollUntil(
      deadline, base::FromChrono(kHelloInterval),
      [&] {
        (void)reader_.Take([&](const pb::ControlReply& r, const SampleInfo&) {
          if (answered || r.client_id() != client_id_ || r.request_id() < first_id ||
              r.request_id() >= next_id_ || (!server_id.empty() && r.server_id() != server_id)) {
            return;
          }
          answered = true;
          answering_server_ = r.server_id();
        });
        if (answered) return true;
        if (send_at.Passed() && !deadline.Passed()) {
          hello.set_request_id(next_id_++);
          if (!writer_.Write(0, hello)) {
            last_error_ = writer_.last_error();
            failed = true;
            return true;
          }
          ++sent;
          send_at = base::Deadline::After(base::FromChrono(kHelloInterval));
        }
        return false;
      },
      [&](base::Nanos slice) {
        (void)reader_.Wait(base::Chrono(std::min(slice, send_at.Left())));
      });
  if (done) return answered && !failed;
  last_error_ = std::string(server_id.empty() ? "no server" : "server '" + server_id + "'") +
                " answered none of this client's " + std::to_string(sent) +
                " hello request(s) within " + std::to_string(timeout.count()) +
                " ms; its requests are read (by " +
                (server_id.empty() ? "a server" : "that server or another") +
                " that has not discovered this client yet, a recorder, or a program that "
                "is not a vdyn server)";
  return false;
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
  std::optional<pb::ControlReply> reply;
  const bool got = base::PollUntil(
      base::Deadline::After(base::FromChrono(timeout)), base::Milliseconds(50),
      [&] {
        (void)reader_.Take([&](const pb::ControlReply& r, const SampleInfo&) {
          if (r.client_id() == client_id_ && r.request_id() == request.request_id()) reply = r;
        });
        return reply.has_value();
      },
      [&](base::Nanos slice) { (void)reader_.Wait(base::Chrono(slice)); });
  if (!got) {
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
  return reply;
}

}  // namespace vdyn::transport
