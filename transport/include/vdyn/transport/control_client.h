// A client's side of control requests: send one, wait for its reply (bounded), never hang.
#pragma once

#include <chrono>
#include <cstdint>
#include <optional>
#include <string>

#include "vdyn/transport/dds.h"
#include "vdyn/control.pb.h"

namespace vdyn::transport {

class ControlClient {
 public:
  ControlClient(Participant& participant, std::string client_id);

  // Sends `request` (its request_id and client_id are set here) and waits up to `timeout` for
  // the reply. Without a reply in time: nullopt and last_error() says so.
  [[nodiscard]] std::optional<pb::ControlReply> Call(pb::ControlRequest request,
                                                     std::chrono::milliseconds timeout);
  // Waits until a server's reader has matched this client's writer (a request sent before that
  // could be lost on a volatile topic) and the server has matched this client's reply reader (a
  // reply written before that goes to no one: under load, discovery reaches one side seconds
  // before the other). The second is seen through a reader of the world made after the reply
  // reader: this participant announces its readers in order, on one reliable stream, so once a
  // server's world (transient-local) arrives there, that server knows the reply reader too (a
  // participant not permitted to read the world, under DDS Security, skips this). False after the
  // timeout.
  [[nodiscard]] bool WaitForServer(std::chrono::milliseconds timeout);
  const std::string& last_error() const { return last_error_; }

 private:
  Participant& participant_;
  std::string client_id_;
  DropCounters drops_;
  Writer<pb::ControlRequest> writer_;
  Reader<pb::ControlReply> reader_;
  std::uint64_t next_id_ = 1;
  std::string last_error_;
};

}  // namespace vdyn::transport
