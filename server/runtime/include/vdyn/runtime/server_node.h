// The networked server: a Session driven over DDS in real time or in lockstep.
//
//  receiver   takes driver inputs and control requests from DDS, decodes and checks them (sizes,
//             finite numbers, ranges, keys); every request goes on to the request thread
//  requests   makes each request ready (RequestPlanner: parameters validated and converted, a new
//             vehicle built at rest, a teleport's state found), or refuses it with the reason
//  loop       (SCHED_FIFO where permitted) at each step boundary: the inputs, at most 16 ready
//             requests (Session::Commit: a swap each), then Session::StepInto - its part of the
//             vehicles, the other parts on the session's stepping workers (step_pool.h, the same
//             scheduling), each state encoded into its frame of the state outbox - and the frames
//             handed to the writer; no lock, no allocation, nothing logged
//  states     the state outbox's writer: every step's states on vdyn/states (the readers of every
//             vehicle), each vehicle's in its partition (its followers), and on vdyn/state in the
//             default partition while a DDS tool reads it; best-effort topics (state_outbox.h)
//  publisher  replies, parameters, world, events, diagnostics and the status line: every reliable
//             write, and every log line
//
// The threads hand work to each other through bounded lock-free queues (vdyn/base/spsc_queue.h)
// and ring doorbells. On the request path each stage takes only what the next has room for, so
// a burst waits (in the control reader's history) and every request is answered once, or counted
// as unanswered with the reason; elsewhere a full queue drops and counts, it never blocks the
// loop. Shutdown drains what is queued for at most a deadline, whatever a reader does.
#pragma once

#include <array>
#include <atomic>
#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include "vdyn/base/doorbell.h"
#include "vdyn/base/spsc_queue.h"
#include "vdyn/base/time.h"
#include "vdyn/control.pb.h"
#include "vdyn/diagnostics.pb.h"
#include "vdyn/runtime/claim.h"
#include "vdyn/runtime/input_arbiter.h"
#include "vdyn/runtime/pacing.h"
#include "vdyn/runtime/request_planner.h"
#include "vdyn/runtime/session.h"
#include "vdyn/runtime/state_outbox.h"
#include "vdyn/transport/dds.h"
#include "vdyn/transport/security_log.h"
#include "vdyn/world.pb.h"

namespace vdyn {

struct ServerOptions {
  enum class Mode { kRealtime, kLockstep };
  Mode mode = Mode::kRealtime;
  std::uint32_t domain_id = 0;
  std::vector<std::uint32_t> vehicle_ids = {1};
  double start_speed_mps = 0;  // the start vehicles' speed along their heading
  SessionConfig session;
  // Durations are base::Nanos (built with base::FromSeconds from a user's seconds).
  base::Nanos duration{0};  // real time: stop after this much simulated time (0: never)
  // Lockstep: give up without a request this long.
  base::Nanos lockstep_timeout = base::Seconds(10);
  int rt_priority = 50;
  // The state writer thread's nice value in real time (0: left as it is). -10 put it ahead of
  // 8 rigs and a recorder on 2 vCPUs (no state refused, against 0.49-0.70 M at 0), and starved
  // them instead; under the sanitizer suite's load it slowed the tests' rigs and recorders.
  int state_writer_nice = 0;
  std::int64_t max_lag_steps = 1000;  // beyond this backlog the schedule is rebased
  bool status_line = false;           // a terminal line of speed, step rate and lateness
  std::string stats_out;              // real time: write a run summary here at the end
  base::Nanos shutdown_deadline = base::Milliseconds(2000);  // the publisher's drain at the end
  // At start, how long to listen for other servers on the domain (a vehicle id or a server id
  // already in use is refused) once one has been discovered; with none, 300 ms.
  base::Nanos discovery = base::Milliseconds(1500);
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

  // One reporting window of the loop, handed to the publisher (plain data, no allocation: each
  // slot of the report queue holds room for as many vehicles as the server may run, made at
  // construction).
  struct VehicleReport {
    std::uint32_t id = 0;
    bool safe_state = false;
    double input_age_ms = -1;
    char source[72] = {};
    std::uint64_t nonfinite_steps = 0;
    std::uint64_t under_ground_steps = 0;
    std::uint64_t runaway_steps = 0;
    std::uint64_t sanitized_inputs = 0;
    std::uint64_t invariant_failures = 0;
    char last_invariant_failure[160] = {};
    double speed_kmh = 0;
  };
  struct WindowReport {
    std::int64_t wall_ns = 0;  // length of the window
    std::int64_t cpu_ns = 0;   // process CPU in the window
    std::int64_t sim_time_ns = 0;
    std::int64_t steps = 0;
    std::int64_t window_steps = 0;
    std::uint64_t steps_caught_up = 0;
    std::uint64_t max_lag_steps = 0;
    LatenessWindow lateness;
    std::size_t n_vehicles = 0;           // the first n of `vehicles` hold this window's
    std::vector<VehicleReport> vehicles;  // sized once, to the most vehicles the server runs
  };

 private:
  struct Outgoing {
    transport::TopicId topic = transport::TopicId::kControlReply;
    std::uint32_t key = 0;
    std::unique_ptr<google::protobuf::Message> msg;
  };
  // A request taken from DDS, for the request thread: refused already (why), or to plan.
  struct Incoming {
    std::shared_ptr<const pb::ControlRequest> request;
    std::uint64_t writer = 0;  // the DDS writer it came from (its client)
    std::string refusal;
  };
  // A step request waits for its steps: `remaining` counts down as they run, in order.
  struct DeferredReply {
    std::uint32_t remaining = 0;
    std::uint64_t writer = 0;
    RequestOutcome outcome;
  };

  // Loop thread.
  void Send(transport::TopicId topic, std::uint32_t key,
            std::unique_ptr<google::protobuf::Message> msg);
  void OnEvent(SessionEventRecord&& r);
  bool Boundary();                  // true when a control request was applied
  void Answer(RequestOutcome&& o);  // room checked before
  void NoRoomToAnswer();            // counts a request that could not be handed on
  std::size_t OutcomeRoom() const { return outcomes_.capacity() - outcomes_.size(); }
  void StepOnce();
  void SendDueStepReplies();
  void CancelStepReplies(RequestOutcome::Why why);
  void ClientGone(std::uint64_t writer);
  // Receiver thread: a real-time session's pausing client has gone; resume (clears pause_writer).
  void ResumeForGoneClient(std::uint64_t& pause_writer);
  // After the loop: what is still waiting is answered (the server stops).
  void AnswerWhatIsLeft();
  void PushReport(base::MonoTime now);
  int RunRealtime(const std::atomic<bool>& stop);
  int RunLockstep(const std::atomic<bool>& stop);
  void WriteStats(base::MonoTime start, base::MonoTime end, base::Nanos start_cpu) const;

  // Start: another server on the domain that runs one of our vehicles, or has our id, or claims
  // them at the same moment and wins the tie (claim.h). Empty when this server may run.
  // FindClash's last word on the claims of servers started at the same moment (claim.h): the
  // reason this server gives way, or empty when it runs.
  std::string SettleClaims(const ServerClaim& mine, const transport::Guid& own_guid,
                           const std::map<transport::Guid, ServerClaim>& claims) const;
  std::string FindClash();
  ServerClaim Claim(bool running) const;
  // Receiver thread: a loop of rounds, each round's stages below (receiver state in the .cc).
  struct Receiver;
  void ReceiverLoop();
  void ReceiveOtherServers(Receiver& rx, base::MonoTime now);
  bool ReceiveInputs(Receiver& rx, base::MonoTime now);  // true: an input handed to the loop
  void ReceiveRequests(Receiver& rx, base::MonoTime now, bool stopping);
  void ReceiverHousekeeping(Receiver& rx, base::MonoTime now);
  void InputRefusedByReader(const transport::SampleInfo& info, std::string_view kind,
                            std::string_view detail, const google::protobuf::Message* m);
  void RequestRefusedByReader(Receiver& rx, std::string_view kind, std::string_view detail,
                              const google::protobuf::Message* m);
  void Refuse(const pb::ControlRequest& r, const std::string& why);
  // Request thread.
  void RequestLoop();
  bool ForThisServer(const pb::ControlRequest& r) const;
  // Answers `r` from the request thread: refused with `why`, or accepted when `why` is empty.
  void AnswerHere(const std::shared_ptr<const pb::ControlRequest>& r, std::string why);
  // Publisher thread.
  void PublisherLoop();
  bool PublishOne(transport::TopicId topic, std::uint32_t key, const google::protobuf::Message& m,
                  base::MonoTime give_up);
  void PublishOutcome(RequestOutcome& o, base::MonoTime now);
  void PublishReport(WindowReport& r);

  std::shared_ptr<const World> world_;
  ServerOptions options_;
  transport::DropCounters drops_{/*deferred=*/true};
  // What DDS Security refuses (Cyclone only logs it), counted in drops_: installed before the
  // participant exists and removed after it has gone.
  transport::SecurityLog security_log_{drops_};
  transport::Participant participant_;
  std::unique_ptr<StateOutbox> states_;
  std::vector<std::unique_ptr<transport::RawWriter>> writers_;  // by TopicId
  transport::Reader<pb::DriverInput> input_reader_;
  transport::Reader<pb::ControlRequest> control_reader_;
  std::unique_ptr<Session> session_;

  // The request path (every request gets one reply, or is counted unanswered with the reason):
  //   receiver -> incoming_ -> request thread (RequestPlanner) -> prepared_ -> loop (Commit)
  //   loop -> outcomes_ -> publisher (the reply);  loop -> spent_ -> request thread (freed)
  //   request thread -> answers_ -> publisher (refusals decided before the loop)
  // Each stage takes only what the next has room for: a burst waits in the control reader's
  // history, nothing is dropped.
  base::SpscQueue<pb::DriverInput> inputs_{1024};
  base::SpscQueue<Incoming> incoming_{256};
  base::SpscQueue<std::unique_ptr<PreparedRequest>> prepared_{256};
  base::SpscQueue<std::unique_ptr<PreparedRequest>> spent_{512};
  base::SpscQueue<RequestOutcome> outcomes_{1024};
  base::SpscQueue<RequestOutcome> answers_{1024};
  // Receiver -> loop: clients (control writers) that have gone away.
  base::SpscQueue<std::uint64_t> gone_clients_{64};
  // Loop -> publisher.
  base::SpscQueue<Outgoing> outbox_{1024};
  base::SpscQueue<SessionEventRecord> events_{4096};
  base::SpscQueue<WindowReport> reports_{8};
  base::Doorbell publisher_bell_;
  base::Doorbell loop_bell_;
  base::Doorbell request_bell_;   // rung for the request thread (work, or room)
  base::Doorbell receiver_bell_;  // rung for the receiver (room in incoming_)
  std::atomic<bool> receiver_stop_{false};
  std::atomic<bool> requests_stop_{false};
  std::atomic<bool> publisher_stop_{false};
  std::atomic<std::int64_t> publisher_deadline_ns_{0};
  std::atomic<std::int64_t> sim_time_ns_{0};      // the loop's, for answers given elsewhere
  std::atomic<std::int64_t> last_request_ns_{0};  // when the receiver last took a request
  std::thread receiver_;
  std::thread requests_;
  std::thread publisher_;
  std::unique_ptr<RequestPlanner> planner_;  // the request thread's

  // Request accounting, for the diagnostics: taken from DDS for this server, answered (a reply
  // written), unanswered (with the reason in drops_), and meant for another server.
  std::atomic<std::uint64_t> requests_received_{0};
  std::atomic<std::uint64_t> replies_sent_{0};
  std::atomic<std::uint64_t> requests_unanswered_{0};
  std::atomic<std::uint64_t> requests_for_others_{0};

  std::vector<DeferredReply> deferred_step_replies_;

  // Receiver's: input arbitration and what other servers run; copies for the publisher.
  InputArbiter arbiter_{OwnershipLease(base::FromSeconds(options_.session.watchdog_s))};
  std::mutex sources_mu_;
  std::vector<InputArbiter::Source> sources_copy_;
  struct OtherVehicle {
    std::string server_id;
    base::MonoTime seen;
  };
  std::map<std::uint32_t, OtherVehicle> others_;

  // Drop kinds counted on the loop thread (registered up front: counting allocates nothing).
  int drop_rebase_ = -1, drop_events_full_ = -1, drop_outbox_full_ = -1, drop_inputs_full_ = -1,
      drop_key_mismatch_ = -1, drop_out_of_range_ = -1, drop_rejected_ = -1, drop_step_input_ = -1,
      drop_unknown_buttons_ = -1, drop_unanswered_gone_ = -1, drop_unanswered_write_ = -1,
      drop_unanswered_stopped_ = -1, drop_unanswered_room_ = -1, drop_session_refused_input_ = -1;

  // Loop statistics: the current window and the whole run.
  std::string scheduling_;
  LatenessWindow lateness_;
  Histogram lateness_all_;
  Histogram request_boundaries_;  // how long requests held each boundary that applied some, us
  std::uint64_t steps_caught_up_ = 0;
  std::uint64_t max_lag_steps_seen_ = 0;
  std::uint64_t schedule_rebases_ = 0;
  base::MonoTime window_start_;
  base::Nanos window_start_cpu_;
  std::int64_t window_start_steps_ = 0;
  // Publisher's view for the status line.
  std::int64_t last_status_ns_ = 0;
  // Publisher thread: each vehicle's non-finite and under-ground steps already said in the log.
  std::map<std::uint32_t, std::array<std::uint64_t, 3>> contained_said_;
};

}  // namespace vdyn
