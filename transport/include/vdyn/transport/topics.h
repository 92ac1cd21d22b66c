// The topics of vdyn and their QoS: the one place where both are set (docs/topics.md).
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>

#include <dds/dds.h>

namespace vdyn::transport {

enum class TopicId {
  kState,         // VehicleState, every step
  kInput,         // DriverInput from rigs, keyboards, players
  kControl,       // ControlRequest to servers
  kControlReply,  // ControlReply from servers
  kParams,        // VehicleParams in effect (complete), per vehicle
  kWorld,         // WorldDescription, per server
  kEvents,        // SessionEvent: what a re-simulation needs
  kDiagnostics,   // Diagnostics, per server, 1 Hz
  kStates,        // VehicleStates: a step's states of every vehicle of a server, one sample
};

struct TopicSpec {
  TopicId id;
  const char* name;     // DDS topic name
  const char* payload;  // full protobuf message name carried in the envelope
  bool reliable;
  int history_depth;     // KEEP_LAST depth; 0 means KEEP_ALL
  bool transient_local;  // late joiners get the last samples at once
  bool exclusive_ownership;
  std::int64_t deadline_ns;          // 0: none
  std::int64_t liveliness_lease_ns;  // 0: none (automatic, infinite); else manual by topic:
                                     // every write asserts the writer's liveliness
  std::size_t max_payload_bytes;     // a larger sample is refused (written or received)
};

const TopicSpec& Spec(TopicId id);
std::span<const TopicSpec> AllTopics();

// Writer and reader QoS of a topic, for use with dds_create_writer/reader; the caller deletes
// the returned object with dds_delete_qos. `ownership_strength` applies to exclusive topics.
// Who reads: a client or the server (the newest sample of a keep-last topic is what matters), or
// a recorder (every sample matters: keep-last topics keep limits::kRecorderHistoryDepth samples
// per instance, world descriptions one).
enum class ReaderRole { kDefault, kRecorder };

dds_qos_t* WriterQos(TopicId id, std::int32_t ownership_strength = 0);
dds_qos_t* ReaderQos(TopicId id, ReaderRole role = ReaderRole::kDefault);

// The partition of one vehicle's own state writer, "vdyn.vehicle.<id>": a reader that follows one
// vehicle subscribes there and receives that vehicle's states and no others. Everything else,
// and every state too, travels in the default partition (docs/topics.md, "Partitions").
std::string VehiclePartition(std::uint32_t vehicle_id);
// The QoS of a publisher or subscriber whose writers or readers live in `partition` (for use
// with dds_create_publisher/subscriber; the caller deletes it with dds_delete_qos).
dds_qos_t* PartitionQos(const std::string& partition);

// The envelope key of a server's own topics (world, diagnostics): vdyn/base/hash.h's ServerKey.
std::uint32_t ServerKey(const std::string& server_id);
// The spec of the topic named `name` ("vdyn/state"), or nullptr.
const TopicSpec* SpecByName(const std::string& name);

}  // namespace vdyn::transport
