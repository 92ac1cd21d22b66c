// The writers of vdyn/state in a process that publishes states (a server's state writer thread,
// a player of a recording): a reader pays only for what it reads.
//
// Every state goes to one all-vehicles writer in the default partition (what recorders, viewers
// and any DDS tool with our IDL read); with Sending::kBatched a step's states share datagrams.
// Each vehicle also has a writer of its own in its partition (VehiclePartition(id)), and its
// states go there too, but only while a reader is matched there (an atomic flag a
// publication-matched listener keeps: no DDS call per state). A client that follows one vehicle
// reads in that partition and receives that vehicle's states and no others.
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
  };
  StateWriters(Participant& participant, DropCounters& drops, Options options);
  StateWriters(Participant& participant, DropCounters& drops)
      : StateWriters(participant, drops, Options{}) {}
  StateWriters(const StateWriters&) = delete;
  StateWriters& operator=(const StateWriters&) = delete;

  // Writes one serialised VehicleState of vehicle `key`: to everyone, and to the vehicle's
  // readers when it has any. False when the all-vehicles write failed (last_error()); a failed
  // vehicle write is counted in the drops.
  bool WriteBytes(std::uint32_t key, std::span<const std::uint8_t> payload);
  // Sends what the all-vehicles writer gathered, then creates vehicle writers for vehicles seen
  // since (at most Options::new_writers_per_flush) and deletes idle ones.
  void Flush();
  // Creates vehicle `key`'s own writer now (a player that knows its vehicles beforehand, so
  // one-vehicle readers have matched it by the first state).
  void Prepare(std::uint32_t key);

  // Vehicle writers that exist now, and how many of them have a matched reader (diagnostics,
  // tests; the count walks the map).
  std::size_t vehicle_writers() const { return vehicles_.size(); }
  std::size_t vehicle_writers_read() const;
  // States written to vehicle partitions so far.
  std::uint64_t vehicle_states_written() const { return vehicle_written_; }
  const std::string& last_error() const { return all_.last_error(); }

 private:
  struct Vehicle {
    std::unique_ptr<RawWriter> writer;  // null until created, or when creating it failed
    base::MonoTime last_written;
    bool failed = false;
  };
  void Create(std::uint32_t key, Vehicle& v);

  Participant& participant_;
  DropCounters& drops_;
  Options options_;
  RawWriter all_;
  std::unordered_map<std::uint32_t, Vehicle> vehicles_;
  std::vector<std::uint32_t> pending_;  // seen, no writer yet
  base::MonoTime round_;                // when Flush() last ran: the time of the writes since
  base::MonoTime next_sweep_;
  std::uint64_t vehicle_written_ = 0;
  int drop_create_ = -1, drop_write_ = -1;
};

}  // namespace vdyn::transport
