// Driver input from a client: a writer on vdyn/input with the client's source id, ownership
// strength, sequence and stamp, and the conversion of a maneuver's row into a message, clamped to
// the table of limits.
#pragma once

#include <cstdint>
#include <string>

#include "vdyn/base/time.h"
#include "vdyn/input.pb.h"
#include "vdyn/io/maneuver.h"
#include "vdyn/transport/dds.h"

namespace vdyn::client {

// The physics fields of a message from a maneuver's input (km/h for the set speed, as the
// message carries it), clamped to the limits.
void FillFromManeuver(const ManeuverInput& in, pb::DriverInput& out);

// Clamps the physics fields of `in` to the limits (non-finite values become 0; the steering angle
// to the road-wheel or hand-wheel range its steer_mode names; a steer mode that is none becomes
// STEER_ROAD_WHEEL with steer 0); returns how many fields had to change.
int ClampToLimits(pb::DriverInput& in);

class InputPublisher {
 public:
  InputPublisher(transport::Participant& participant, std::uint32_t vehicle_id,
                 std::string source_id, std::int32_t strength);
  // Sets vehicle, source, the next sequence number and the stamp (now, monotonic) and writes.
  [[nodiscard]] bool Publish(pb::DriverInput& msg);
  // The same with the time the input was read (a device's sample), for latency measurements.
  [[nodiscard]] bool Publish(pb::DriverInput& msg, base::MonoTime sampled);
  std::uint64_t sent() const { return sequence_; }
  const std::string& last_error() const { return writer_.last_error(); }
  std::uint32_t vehicle_id() const { return vehicle_id_; }
  std::uint32_t MatchedReaders() { return writer_.MatchedReaders(); }

 private:
  transport::Writer<pb::DriverInput> writer_;
  std::uint32_t vehicle_id_;
  std::string source_id_;
  std::uint64_t sequence_ = 0;
};

}  // namespace vdyn::client
