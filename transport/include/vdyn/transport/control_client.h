// A client's side of control requests: send one, wait for its reply (bounded), never hang.
#pragma once

#include <chrono>
#include <cstdint>
#include <optional>
#include <set>
#include <string>

#include "vdyn/transport/dds.h"
#include "vdyn/control.pb.h"

namespace vdyn::transport {

// Waits until a server (the one named `server_id`, or any) has matched every reader this
// participant made before the call: a sample written to a reader it does not know yet goes to no
// one, and under load discovery reaches one side seconds before the other. Seen through a new
// reader of the world: this participant announces its readers in order, on one reliable stream,
// so once that server's world (transient-local) arrives there, it knows the earlier readers too.
// True then, or at once when the participant may not read the world (DDS Security); false after
// the timeout.
[[nodiscard]] bool WaitUntilServerKnowsReaders(Participant& participant,
                                               std::chrono::milliseconds timeout,
                                               const std::string& server_id = {});

class ControlClient {
 public:
  ControlClient(Participant& participant, std::string client_id);

  // Sends `request` (its request_id and client_id are set here) and waits up to `timeout` for
  // the reply. Without a reply in time: nullopt and last_error() says so.
  [[nodiscard]] std::optional<pb::ControlReply> Call(pb::ControlRequest request,
                                                     std::chrono::milliseconds timeout);
  // Waits until a server (the one named `server_id`, or any) answers a hello request, sent again
  // every kHelloInterval until one is answered: then that server takes this client's requests
  // and reaches its reply reader. Matching alone does not show it: a request or reply written
  // before the other side has discovered its writer's peer reaches no one, and a recorder's
  // reader of requests matches this client's writer as a server's does. False after the timeout.
  [[nodiscard]] bool WaitForServer(std::chrono::milliseconds timeout,
                                   const std::string& server_id = {});
  // Call, once this client's hello to the request's server (its server_id, or any server) has
  // been answered: the first request to a server waits for that (WaitForServer, up to `timeout`
  // more), later ones go at once. Without an answer to the hello: nullopt, last_error() says
  // why, and the request is not sent.
  [[nodiscard]] std::optional<pb::ControlReply> CallGreeted(pb::ControlRequest request,
                                                            std::chrono::milliseconds timeout);
  // The server that answered the last successful WaitForServer.
  const std::string& answering_server() const { return answering_server_; }
  static constexpr std::chrono::milliseconds kHelloInterval{250};
  const std::string& last_error() const { return last_error_; }

 private:
  std::string client_id_;
  DropCounters drops_;
  Writer<pb::ControlRequest> writer_;
  Reader<pb::ControlReply> reader_;
  std::uint64_t next_id_ = 1;
  std::string last_error_;
  std::string answering_server_;
  std::set<std::string> greeted_;  // server ids (or "" = any) whose hello was answered
};

}  // namespace vdyn::transport
