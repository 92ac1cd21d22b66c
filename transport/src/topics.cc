#include "vdyn/transport/topics.h"

#include <array>
#include <stdexcept>
#include <string>

#include "vdyn/base/hash.h"
#include "vdyn/base/limits.h"

namespace vdyn::transport {
namespace {

constexpr std::int64_t kMs = 1'000'000;

// clang-format off
// name, payload, reliable, depth (0 = all), transient-local, exclusive, deadline, liveliness,
// largest payload (vdyn/base/limits.h)
constexpr std::array<TopicSpec, 9> kTopics = {{
  // State every step: the newest sample is all that matters; never block the 1 kHz loop.
  {TopicId::kState, "vdyn/state", "vdyn.pb.VehicleState", false, 1, false, false, 0, 0, limits::kMaxStateBytes},
  // Driver input: shared ownership, so the server sees every source and itself lets the
  // strongest source whose input is *valid* and live drive (runtime/input_arbiter.h): a rig that
  // crashes, hangs or sends refused input loses the vehicle to a backup after the lease (200 ms).
  // Writers still declare their ownership strength (the server reads it from discovery).
  // Liveliness is asserted by each write (manual by topic).
  {TopicId::kInput, "vdyn/input", "vdyn.pb.DriverInput", true, 1, false, false, 50 * kMs, 200 * kMs, limits::kMaxInputBytes},
  // Requests and replies: every one delivered, in order.
  {TopicId::kControl, "vdyn/control", "vdyn.pb.ControlRequest", true, 0, false, false, 0, 0, limits::kMaxControlBytes},
  {TopicId::kControlReply, "vdyn/control_reply", "vdyn.pb.ControlReply", true, 0, false, false, 0, 0, limits::kMaxReplyBytes},
  // Parameters in effect and the world: a viewer or recorder that joins late gets them at once.
  {TopicId::kParams, "vdyn/params", "vdyn.pb.VehicleParams", true, 1, true, false, 0, 0, limits::kMaxParamsBytes},
  {TopicId::kWorld, "vdyn/world", "vdyn.pb.WorldDescription", true, 1, true, false, 0, 0, limits::kMaxWorldBytes},
  // Session events: every one delivered (a re-simulation needs all of them).
  {TopicId::kEvents, "vdyn/events", "vdyn.pb.SessionEvent", true, 0, false, false, 0, 0, limits::kMaxEventBytes},
  {TopicId::kDiagnostics, "vdyn/diagnostics", "vdyn.pb.Diagnostics", true, 1, false, false, 0, 0, limits::kMaxDiagnosticsBytes},
  // A step's states of every vehicle of a server in one sample (keyed by the server), for the
  // readers of every vehicle: one sample a step to receive and take instead of one per vehicle.
  {TopicId::kStates, "vdyn/states", "vdyn.pb.VehicleStates", false, 1, false, false, 0, 0, limits::kMaxStatesBytes},
}};
// clang-format on

dds_qos_t* BaseQos(const TopicSpec& s) {
  dds_qos_t* q = dds_create_qos();
  // A reliable writer blocks at most 10 ms when the readers have not acknowledged enough
  // (WriterQos gives the topics no 1 kHz loop writes a second).
  dds_qset_reliability(q, s.reliable ? DDS_RELIABILITY_RELIABLE : DDS_RELIABILITY_BEST_EFFORT,
                       DDS_MSECS(10));
  if (s.history_depth == 0) {
    dds_qset_history(q, DDS_HISTORY_KEEP_ALL, 0);
  } else {
    dds_qset_history(q, DDS_HISTORY_KEEP_LAST, s.history_depth);
  }
  dds_qset_durability(q,
                      s.transient_local ? DDS_DURABILITY_TRANSIENT_LOCAL : DDS_DURABILITY_VOLATILE);
  if (s.transient_local) {
    // How many samples per instance a late joiner receives.
    dds_qset_durability_service(q, 0, DDS_HISTORY_KEEP_LAST,
                                s.history_depth == 0 ? 1 : s.history_depth, DDS_LENGTH_UNLIMITED,
                                DDS_LENGTH_UNLIMITED, DDS_LENGTH_UNLIMITED);
  }
  dds_qset_ownership(q, s.exclusive_ownership ? DDS_OWNERSHIP_EXCLUSIVE : DDS_OWNERSHIP_SHARED);
  dds_qset_deadline(q, s.deadline_ns > 0 ? s.deadline_ns : DDS_INFINITY);
  if (s.liveliness_lease_ns > 0) {
    dds_qset_liveliness(q, DDS_LIVELINESS_MANUAL_BY_TOPIC, s.liveliness_lease_ns);
  } else {
    dds_qset_liveliness(q, DDS_LIVELINESS_AUTOMATIC, DDS_INFINITY);
  }
  dds_qset_destination_order(q, DDS_DESTINATIONORDER_BY_RECEPTION_TIMESTAMP);
  dds_qset_resource_limits(q, DDS_LENGTH_UNLIMITED, DDS_LENGTH_UNLIMITED, DDS_LENGTH_UNLIMITED);
  return q;
}

}  // namespace

const TopicSpec& Spec(TopicId id) {
  for (const TopicSpec& s : kTopics) {
    if (s.id == id) return s;
  }
  throw std::logic_error("unknown topic id");
}

std::span<const TopicSpec> AllTopics() {
  return kTopics;
}

dds_qos_t* WriterQos(TopicId id, std::int32_t ownership_strength) {
  const TopicSpec& s = Spec(id);
  dds_qos_t* q = BaseQos(s);
  // Exclusive topics use it to pick a writer; on vdyn/input (shared) the server reads it from
  // discovery and arbitrates itself.
  if (s.exclusive_ownership || id == TopicId::kInput) {
    dds_qset_ownership_strength(q, ownership_strength);
  }
  // Instances stay alive when a writer goes away: a restarted server keeps its keys.
  dds_qset_writer_data_lifecycle(q, false);
  if (s.reliable && id != TopicId::kInput) {
    // Requests, replies, events, parameters, the world and diagnostics are never written from a
    // 1 kHz loop (the server writes them from its publisher thread, clients from their request
    // calls): while a slow reader (a recorder or client under load) has not yet acknowledged the
    // last ~30 kB, Cyclone holds the write, and 10 ms lost a request or a reply now and then
    // (dds_write: Timeout; 2 replies of a burst of 12,000 on a loaded machine). A second waits it
    // out. Driver input keeps 10 ms: a rig writes it from its own 1 kHz loop.
    dds_qset_reliability(q, DDS_RELIABILITY_RELIABLE, DDS_SECS(1));
  }
  return q;
}

dds_qos_t* ReaderQos(TopicId id, ReaderRole role) {
  const TopicSpec& s = Spec(id);
  dds_qos_t* q = BaseQos(s);
  if (id == TopicId::kStates && role == ReaderRole::kDefault) {
    // The newest step, in as many samples as a step of the largest states can split into
    // (StateWriters splits at limits::kMaxStatesBytes; frames of a step hold at most 4 KB a state).
    dds_qset_history(q, DDS_HISTORY_KEEP_LAST, 2);
  } else if (role == ReaderRole::kRecorder && s.history_depth > 0 && id != TopicId::kWorld) {
    // A recorder takes every sample: a deeper (bounded) history per instance absorbs a late take
    // instead of overwriting samples. History is the reader's own business: it matches the
    // same writers.
    dds_qset_history(q, DDS_HISTORY_KEEP_LAST, limits::kRecorderHistoryDepth);
  }
  return q;
}

std::string VehiclePartition(std::uint32_t vehicle_id) {
  return "vdyn.vehicle." + std::to_string(vehicle_id);
}

dds_qos_t* PartitionQos(const std::string& partition) {
  dds_qos_t* q = dds_create_qos();
  const char* names[] = {partition.c_str()};
  dds_qset_partition(q, 1, names);
  return q;
}

std::uint32_t ServerKey(const std::string& server_id) {
  return base::ServerKey(server_id);
}

const TopicSpec* SpecByName(const std::string& name) {
  for (const TopicSpec& s : kTopics) {
    if (name == s.name) return &s;
  }
  return nullptr;
}

}  // namespace vdyn::transport
