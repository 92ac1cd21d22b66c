// The networked server: a Session driven over DDS in real time or in lockstep.
//
//  sim thread:  [boundary: take control requests and inputs] -> Session::Step -> state writes
//  publisher:   replies, events, params, world, diagnostics (reliable writes, off the 1 kHz loop)
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "dds.h"
#include "pacing.h"
#include "session.h"
#include "vdyn/control.pb.h"
#include "vdyn/diagnostics.pb.h"
#include "vdyn/world.pb.h"

namespace vdyn {

struct ServerOptions {
  enum class Mode { kRealtime, kLockstep };
  Mode mode = Mode::kRealtime;
  std::uint32_t domain_id = 0;
  std::vector<std::uint32_t> vehicle_ids = {1};
  SessionConfig session;
  double duration_s = 0;          // real time: stop after this much simulated time (0: never)
  double lockstep_timeout_s = 10;  // lockstep: give up without a request for this long
  int rt_priority = 50;
  std::int64_t max_lag_steps = 1000;  // beyond this backlog the schedule is rebased
  bool status_line = false;       // a terminal line of speed, step rate and lateness
  std::string stats_out;          // real time: write a run summary here at the end
};

class ServerNode {
 public:
  ServerNode(std::shared_ptr<const World> world, ServerOptions options);
  ~ServerNode();
  ServerNode(const ServerNode&) = delete;
  ServerNode& operator=(const ServerNode&) = delete;

  // Runs until `stop` is set, the duration is reached or (lockstep) the client is gone.
  // Returns the process exit code: 0 done, 3 lockstep timeout.
  int Run(const std::atomic<bool>& stop);

  transport::DropCounters& drops() { return drops_; }

 private:
  struct Outgoing {
    transport::TopicId topic;
    std::uint32_t key;
    std::unique_ptr<google::protobuf::Message> msg;
  };

  void Enqueue(transport::TopicId topic, std::uint32_t key,
               std::unique_ptr<google::protobuf::Message> msg);
  void PublisherLoop();
  void OnEvent(const pb::SessionEvent& e);
  // Takes control requests and inputs; returns true when a control request arrived.
  bool Boundary();
  void HandleRequest(const pb::ControlRequest& r);
  void StepOnce();
  void ReportWindow(std::int64_t now_ns);
  void PrintStatus(std::int64_t now_ns);
  int RunRealtime(const std::atomic<bool>& stop);
  int RunLockstep(const std::atomic<bool>& stop);
  void WriteStats(std::int64_t start_ns, std::int64_t end_ns, std::int64_t start_cpu_ns) const;

  std::shared_ptr<const World> world_;
  ServerOptions options_;
  transport::DropCounters drops_;
  transport::Participant participant_;
  transport::Writer<pb::VehicleState> state_writer_;
  std::map<transport::TopicId, std::unique_ptr<transport::RawWriter>> writers_;
  transport::Reader<pb::DriverInput> input_reader_;
  transport::Reader<pb::ControlRequest> control_reader_;
  std::unique_ptr<Session> session_;

  // Step replies wait until their steps are done: each is due when the session's step count
  // reaches its target.
  struct DeferredReply {
    std::int64_t target_steps;
    pb::ControlReply reply;
  };
  std::vector<DeferredReply> deferred_step_replies_;
  void SendDueStepReplies();
  void CancelStepReplies(const std::string& why);

  // Publisher thread: replies, params, world and diagnostics go before events, so a slow
  // recorder never delays an answer.
  std::mutex mu_;
  std::condition_variable cv_;
  std::deque<Outgoing> urgent_;
  std::deque<Outgoing> events_;
  bool publisher_stop_ = false;
  std::thread publisher_;
  static constexpr std::size_t kMaxQueue = 200'000;

  // Statistics of the current 1 s window and since start.
  std::string scheduling_;
  LatenessWindow lateness_;
  Histogram lateness_all_;  // the whole run
  std::uint64_t steps_caught_up_ = 0;
  std::uint64_t max_lag_steps_seen_ = 0;
  std::uint64_t schedule_rebases_ = 0;
  std::int64_t window_start_ns_ = 0;
  std::int64_t window_start_cpu_ns_ = 0;
  std::int64_t window_start_steps_ = 0;
  std::int64_t last_status_ns_ = 0;
  double last_p50_us_ = 0, last_p99_us_ = 0, last_max_us_ = 0, last_rate_hz_ = 0;
};

}  // namespace vdyn
