// Test helpers over the transport layer: a bounded wait on a DDS reader; a server that only
// answers requests.
#pragma once

#include <chrono>
#include <string>
#include <vector>

#include "vdyn/base/deadline.h"
#include "vdyn/control.pb.h"
#include "vdyn/transport/dds.h"
#include "vdyn/transport/drops.h"

namespace vdyn::testing {

// Waits on a reader until `done` says so or the timeout passes, handing every sample to `on`
// (base::PollUntil, the one bounded wait: it looks once more after its last wait).
template <class M, class On, class Done>
bool ReadUntil(transport::Reader<M>& reader, std::chrono::milliseconds timeout, On on, Done done) {
  return base::PollUntil(
      base::Deadline::After(base::FromChrono(timeout)), base::Milliseconds(50), done,
      [&](base::Nanos slice) {
        (void)reader.Wait(base::Chrono(slice));
        (void)reader.Take([&](const M& m, const transport::SampleInfo&) { on(m); });
      });
}

// Sends (a round of states, a step) and then waits on `waitable` (a reader, a SessionView: any
// Wait(std::chrono::nanoseconds)) for a slice, until `done` says so or the timeout passes: a
// writer that goes on until its reader has matched and taken something.
template <class Waitable, class Send, class Done>
bool SendUntil(Waitable& waitable, std::chrono::milliseconds timeout, Send send, Done done) {
  return base::PollUntil(base::Deadline::After(base::FromChrono(timeout)), base::Milliseconds(10),
                         done, [&](base::Nanos slice) {
                           send();
                           (void)waitable.Wait(base::Chrono(slice));
                         });
}

// A stand-in for a server's request handling: keeps every request it reads, in order, and
// accepts each (at step 7) as server `id`. Nothing is applied.
class AnsweringPeer {
 public:
  AnsweringPeer(transport::Participant& participant, std::string id)
      : id_(std::move(id)),
        requests_(participant, transport::TopicId::kControl, &drops_),
        replies_(participant, transport::TopicId::kControlReply) {}
  // Answers until `done` says so or the timeout passes.
  template <class Done>
  bool ServeUntil(std::chrono::milliseconds timeout, Done done) {
    return ReadUntil(
        requests_, timeout,
        [&](const pb::ControlRequest& r) {
          seen.push_back(r);
          pb::ControlReply a;
          a.set_request_id(r.request_id());
          a.set_client_id(r.client_id());
          a.set_vehicle_id(r.vehicle_id());
          a.set_server_id(id_);
          a.set_accepted(true);
          a.set_applied_step(7);
          (void)replies_.Write(0, a);
        },
        done);
  }
  std::vector<pb::ControlRequest> seen;

 private:
  std::string id_;
  transport::DropCounters drops_;
  transport::Reader<pb::ControlRequest> requests_;
  transport::Writer<pb::ControlReply> replies_;
};

}  // namespace vdyn::testing
