// The writers of a process that publishes states (a server's state writer thread, a player of a
// recording): one route per kind of reader, and a reader pays only for what it reads
// (docs/topics.md).
//  - vdyn/states: a step's states of every vehicle in one sample (VehicleStates, keyed by the
//    server), for every reader of all vehicles (recorders, viewers, Python, SessionView).
//  - vdyn/state in a vehicle's partition (VehiclePartition(id)), a writer per vehicle: for the
//    clients that follow one vehicle (rigs, telemetry), which receive no other vehicle's states.
//  - vdyn/state in the default partition, one writer (with Sending::kBatched a round's states share
//    datagrams): the plain per-vehicle topic for a DDS tool with our IDL; no vdyn program reads it.
// Each writes only while a reader is matched (an atomic flag a publication-matched listener keeps:
// no DDS call per state otherwise), so a session of recorders and viewers costs one write a step.
//
// Not thread-safe: one thread writes. Vehicle writers are created by Flush() (a few per call, so
// a burst of new vehicles does not hold up a round of states) and deleted when their vehicle has
// written nothing for `idle` (removed vehicles, a paused clock).
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <unordered_map>
#include <vector>

#include "vdyn/base/time.h"
#include "vdyn/transport/dds.h"
#include "vdyn/transport/drops.h"

namespace vdyn::transport {

class StateWriters {
 public:
  struct Options {
    Sending sending = Sending::kBatched;   // of the all-vehicles writer
    int new_writers_per_flush = 8;         // vehicle writers created per Flush() at most
    base::Nanos idle = base::Seconds(10);  // a vehicle writer unused this long is deleted
    std::uint32_t states_key = 0;          // the vdyn/states key: ServerKey(the writer's id)
    // A vdyn/states sample closes at the end of a step (EndStep) once it holds this many bytes:
    // a writer that fell behind sends several samples of whole steps, not one of up to
    // limits::kMaxStatesBytes. A best-effort sample is lost whole when one of its datagrams is
    // (a receive buffer full, a lossy link): a megabyte sample of 3 vehicles is 200 steps.
    std::size_t sample_bytes = 64 * 1024;
  };
  StateWriters(Participant& participant, DropCounters& drops, Options options);
  StateWriters(Participant& participant, DropCounters& drops)
      : StateWriters(participant, drops, Options{}) {}
  StateWriters(const StateWriters&) = delete;
  StateWriters& operator=(const StateWriters&) = delete;

  // Writes one serialised VehicleState of vehicle `key`: into this round's vdyn/states sample,
  // and on vdyn/state (default partition, the vehicle's partition) while each has a reader. False
  // when a write failed (last_error()); a failed vehicle write is counted in the drops.
  [[nodiscard]] bool WriteBytes(std::uint32_t key, std::span<const std::uint8_t> payload);
  // The states written since the last EndStep are one step's: the vdyn/states sample is written
  // now when it holds Options::sample_bytes or more. False when that write failed (last_error()).
  [[nodiscard]] bool EndStep();
  // Writes this round's vdyn/states sample and sends what the default partition's writer
  // gathered (a failed flush is counted in the drops); then creates vehicle writers for vehicles
  // seen since (at most Options::new_writers_per_flush) and deletes idle ones. False when the
  // vdyn/states write failed (last_error()).
  [[nodiscard]] bool Flush();
  // Creates vehicle `key`'s own writer now (a player that knows its vehicles beforehand, so
  // one-vehicle readers have matched it by the first state).
  void Prepare(std::uint32_t key);

  // Vehicle writers that exist now, and how many of them have a matched reader (diagnostics,
  // tests; the count walks the map).
  std::size_t vehicle_writers() const { return vehicles_.size(); }
  std::size_t vehicle_writers_read() const;
  // States written to vehicle partitions so far; to vdyn/state in the default partition; and
  // vdyn/states samples.
  std::uint64_t vehicle_states_written() const { return vehicle_written_; }
  std::uint64_t all_states_written() const { return all_written_; }
  std::uint64_t batches_written() const { return batches_written_; }
  // Readers of vdyn/state in the default partition matched now (asks DDS).
  std::uint32_t state_readers() { return all_.MatchedReaders(); }
  const std::string& last_error() const { return last_error_; }

 private:
  struct Vehicle {
    std::unique_ptr<RawWriter> writer;  // null until created, or when creating it failed
    base::MonoTime last_written;
    bool failed = false;
  };
  void Create(std::uint32_t key, Vehicle& v);
  bool WriteBatch();

  Participant& participant_;
  DropCounters& drops_;
  Options options_;
  RawWriter all_;
  std::unique_ptr<RawWriter> batch_;   // vdyn/states; null when it cannot be created
  std::vector<std::uint8_t> batched_;  // this round's VehicleStates, encoded
  std::unordered_map<std::uint32_t, Vehicle> vehicles_;
  std::vector<std::uint32_t> pending_;  // seen, no writer yet
  base::MonoTime round_;                // when Flush() last ran: the time of the writes since
  base::MonoTime next_sweep_;
  std::uint64_t vehicle_written_ = 0, all_written_ = 0, batches_written_ = 0;
  std::string last_error_;
  int drop_create_ = -1, drop_write_ = -1, drop_batch_ = -1, drop_flush_ = -1;
};

}  // namespace vdyn::transport
