// The state writes of the 1 kHz loop, off the loop: Cyclone DDS allocates inside dds_write (a
// serialised sample, an instance lookup), so each state is encoded, by the thread that stepped
// its vehicle, into a preallocated frame of a lock-free queue, and a writer thread of its own
// hands the frames to transport::StateWriters: a step's states in one vdyn/states sample for the
// readers of every vehicle, each vehicle's in its partition while someone follows it, and
// vdyn/state in the default partition while a DDS tool reads it (docs/topics.md). The loop
// neither allocates nor blocks; a full queue drops the state and counts it.
#pragma once

#include <array>
#include <atomic>
#include <cstdint>
#include <mutex>
#include <span>
#include <thread>

#include "vdyn/base/doorbell.h"
#include "vdyn/base/limits.h"
#include "vdyn/base/spsc_queue.h"
#include "vdyn/runtime/pacing.h"
#include "vdyn/runtime/session.h"
#include "vdyn/state.pb.h"
#include "vdyn/transport/dds.h"
#include "vdyn/transport/state_writers.h"

namespace vdyn {

class StateOutbox final : public StateFrames {
 public:
  // `vehicles`: the vehicles known before the first step; their own partition writers are
  // created here, before the writer thread starts, so a session that starts with many vehicles
  // does not spend its first rounds creating writers while its states queue up (256 vehicles:
  // 32 rounds of 8 writers, thousands of states refused at the start).
  // `states_key`: the key of this server's vdyn/states samples (transport::ServerKey).
  StateOutbox(transport::Participant& participant, transport::DropCounters& drops,
              std::uint32_t states_key, std::size_t frames = 512,
              std::span<const std::uint32_t> vehicles = {});
  ~StateOutbox();
  StateOutbox(const StateOutbox&) = delete;
  StateOutbox& operator=(const StateOutbox&) = delete;

  // A step's states (Session::StepInto): the loop thread opens frames for them, the stepping
  // threads encode each state into its frame, the loop thread closes them (publishes them to the
  // writer, and counts the states there was no room for). An empty frame (a contained step, a
  // state larger than a frame, counted) is skipped by the writer.
  std::size_t Open(std::size_t n) override;
  std::span<std::uint8_t> Buffer(std::size_t i) override;
  void Fill(std::size_t i, std::uint32_t key, std::size_t size, bool too_large) override;
  void Close(std::size_t n) override;
  // Loop thread, after a step's frames are closed: wakes the writer, which writes every frame
  // handed over so far and then sends them together (one vdyn/states sample; on vdyn/state in
  // the default partition several states per datagram).
  void Send();
  // Waits until every frame handed over has been written (or `timeout`); true when drained.
  [[nodiscard]] bool Drain(base::Nanos timeout);
  // Gives the writer thread the nice value `nice` (setpriority); what it has now, in words (the
  // server's "scheduling" line), with the reason when the system refused (no CAP_SYS_NICE).
  std::string SetWriterNice(int nice);
  // The writer thread's nice value, in words: what it inherited (e.g. `nice -n 19 vdyn-server`)
  // when SetWriterNice was not called.
  std::string WriterNice();

  std::uint64_t written() const { return written_.load(std::memory_order_relaxed); }
  std::uint64_t write_failures() const { return failures_.load(std::memory_order_relaxed); }
  // States handed over by Close, and those refused (queue full, larger than a frame).
  std::uint64_t pushed() const { return pushed_.load(std::memory_order_relaxed); }
  std::uint64_t refused() const { return refused_.load(std::memory_order_relaxed); }
  // The writer's rounds, in microseconds (the server's --stats-out; bench/net_bench): from the
  // loop's hand-over (Send) to the writer thread starting its round (its wake-up), and from there
  // to the round's states sent (every write and the flush: on loopback without multicast the
  // kernel's delivery to each reader is in it), as wall time and as the writer thread's CPU time.
  struct Times {
    std::uint64_t rounds = 0;
    double wake_p50 = 0, wake_p99 = 0, send_p50 = 0, send_p99 = 0, send_cpu_p50 = 0,
           send_cpu_p99 = 0;
  };
  Times WriterTimes() const;

  // A frame is one page. The largest VehicleState (every field set, four wheels, a 64-byte
  // server id) encodes to about 2.2 KB; 1.1 KB is typical.
  static constexpr std::size_t kFrameBytes = 4096 - 12;

 private:
  struct Frame {
    std::uint32_t key = 0;
    std::uint32_t size = 0;
    std::uint32_t step_end = 0;  // the last frame of its step (Close): StateWriters::EndStep
    std::array<std::uint8_t, kFrameBytes> bytes;
  };
  static_assert(sizeof(Frame) == 4096);
  void WriterLoop();

  transport::StateWriters writer_;  // every route, each written while it has a reader
  transport::DropCounters& drops_;
  int drop_full_ = -1, drop_large_ = -1, drop_write_ = -1, drop_batch_ = -1;
  base::SpscQueue<Frame> frames_;
  base::Doorbell bell_;
  std::atomic<bool> stop_{false};
  std::atomic<std::uint64_t> written_{0};
  std::atomic<std::uint64_t> failures_{0};
  std::atomic<std::uint64_t> pushed_{0};
  std::atomic<std::uint64_t> refused_{0};
  std::size_t open_ = 0;                    // frames opened for this step
  std::atomic<std::size_t> empty_{0};       // of them, left empty
  std::atomic<int> writer_tid_{0};          // set by the writer thread as it starts
  std::atomic<std::int64_t> handed_ns_{0};  // monotonic time of the newest Send
  mutable std::mutex times_mu_;             // the writer's, once a round, and WriterTimes()
  Histogram wake_us_, send_us_, send_cpu_us_;
  std::thread thread_;
};

}  // namespace vdyn
