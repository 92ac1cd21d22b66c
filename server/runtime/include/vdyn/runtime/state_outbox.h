// The state writes of the 1 kHz loop, off the loop: Cyclone DDS allocates inside dds_write (a
// serialised sample, an instance lookup), so the loop copies each state, encoded by the stepping
// threads, into a preallocated frame of a lock-free queue and a writer thread of its own puts the
// frames on vdyn/state (best effort, keep last 1), batched: a step's states leave together. A
// vehicle's state also goes to its own partition while someone reads there
// (transport/state_writers.h). The loop neither allocates nor blocks; a full queue drops the state
// and counts it.
#pragma once

#include <array>
#include <atomic>
#include <cstdint>
#include <span>
#include <thread>

#include "vdyn/base/doorbell.h"
#include "vdyn/base/limits.h"
#include "vdyn/base/spsc_queue.h"
#include "vdyn/state.pb.h"
#include "vdyn/transport/dds.h"
#include "vdyn/transport/state_writers.h"

namespace vdyn {

class StateOutbox {
 public:
  StateOutbox(transport::Participant& participant, transport::DropCounters& drops,
              std::size_t frames = 512);
  ~StateOutbox();
  StateOutbox(const StateOutbox&) = delete;
  StateOutbox& operator=(const StateOutbox&) = delete;

  // Loop thread: copies a state's wire bytes (encoded on the stepping threads,
  // Session::StepEncoded) into a free frame for the writer. False (and counted) when the queue is
  // full or the state is larger than a frame (`bytes` empty: it did not fit its buffer).
  bool PushEncoded(std::uint32_t key, std::span<const std::uint8_t> bytes);
  // Loop thread, after a step's pushes: wakes the writer, which writes every frame pushed so far
  // and then sends them together (several states per datagram; one sendmsg per datagram and
  // reader, not per state).
  void Send();
  // Waits until every frame handed over has been written (or `timeout`); true when drained.
  bool Drain(base::Nanos timeout);

  std::uint64_t written() const { return written_.load(std::memory_order_relaxed); }
  std::uint64_t write_failures() const { return failures_.load(std::memory_order_relaxed); }
  // States handed over by Push, and those Push refused (queue full, larger than a frame).
  std::uint64_t pushed() const { return pushed_.load(std::memory_order_relaxed); }
  std::uint64_t refused() const { return refused_.load(std::memory_order_relaxed); }

  static constexpr std::size_t kFrameBytes = 8192;

 private:
  struct Frame {
    std::uint32_t key = 0;
    std::uint32_t size = 0;
    std::array<std::uint8_t, kFrameBytes> bytes;
  };
  void WriterLoop();

  transport::StateWriters writer_;  // all vehicles batched; a vehicle's partition while read
  transport::DropCounters& drops_;
  int drop_full_ = -1, drop_large_ = -1, drop_write_ = -1;
  base::SpscQueue<Frame> frames_;
  base::Doorbell bell_;
  std::atomic<bool> stop_{false};
  std::atomic<std::uint64_t> written_{0};
  std::atomic<std::uint64_t> failures_{0};
  std::atomic<std::uint64_t> pushed_{0};
  std::atomic<std::uint64_t> refused_{0};
  std::thread thread_;
};

}  // namespace vdyn
