// DDS entities for vdyn: a participant, and typed writers and readers that carry Protocol
// Buffers messages in the envelope of idl/vdyn_envelope.idl. QoS comes from topics.cc only.
#pragma once

#include <chrono>
#include <cstdint>
#include <algorithm>
#include <functional>
#include <limits>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include <dds/dds.h>
#include <google/protobuf/message.h>

#include "message_checks.h"
#include "topics.h"

namespace vdyn::transport {

class TransportError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// A DDS domain participant and the vdyn topics created in it (once each).
class Participant {
 public:
  explicit Participant(std::uint32_t domain_id);
  ~Participant();
  Participant(const Participant&) = delete;
  Participant& operator=(const Participant&) = delete;

  dds_entity_t handle() const { return participant_; }
  dds_entity_t Topic(TopicId id);
  std::uint32_t domain_id() const { return domain_id_; }

 private:
  dds_entity_t participant_ = 0;
  std::uint32_t domain_id_ = 0;
  dds_entity_t topics_[8] = {};
};

// Writes protobuf messages on one topic. Serialises into a buffer it keeps between writes.
class RawWriter {
 public:
  RawWriter(Participant& participant, TopicId id, std::int32_t ownership_strength = 0);
  ~RawWriter();
  RawWriter(const RawWriter&) = delete;
  RawWriter& operator=(const RawWriter&) = delete;

  // False when the message could not be serialised or DDS refused it (see last_error()).
  bool Write(std::uint32_t key, const google::protobuf::Message& msg);
  // Number of readers matched right now.
  std::uint32_t MatchedReaders() const;
  const std::string& last_error() const { return last_error_; }
  dds_entity_t handle() const { return writer_; }

 private:
  TopicId id_;
  dds_entity_t writer_ = 0;
  std::string buffer_;
  std::string last_error_;
};

// What a reader knows of one received sample besides the message.
struct SampleInfo {
  std::uint32_t key = 0;
  std::int64_t source_timestamp_ns = 0;   // the writer's wall clock
  std::uint64_t publication_handle = 0;   // which writer
};

// Reads one topic. Each sample is checked - envelope type name, protobuf parse, finite numbers -
// and one that fails is dropped and counted in `drops` with its kind; the rest reach the caller.
class RawReader {
 public:
  RawReader(Participant& participant, TopicId id, DropCounters* drops);
  ~RawReader();
  RawReader(const RawReader&) = delete;
  RawReader& operator=(const RawReader&) = delete;

  // Blocks until data is available or the timeout passes; true when data is available.
  bool Wait(std::chrono::nanoseconds timeout);
  // Calls fn from DDS's receive thread as soon as data arrives (the lowest latency: no hand-over
  // to another thread). Take from inside fn, and then from nowhere else: Take is not reentrant.
  void OnDataAvailable(std::function<void()> fn);
  std::uint32_t MatchedWriters() const;
  dds_entity_t handle() const { return reader_; }

 protected:
  // Takes every available sample; for each valid one parses into `scratch` and calls fn.
  template <class F>
  int TakeInto(google::protobuf::Message& scratch, F&& fn, int max_samples);

 private:
  bool Decode(const void* sample, google::protobuf::Message& scratch, SampleInfo& info);

  TopicId id_;
  dds_entity_t reader_ = 0;
  dds_entity_t waitset_ = 0;
  dds_entity_t condition_ = 0;
  DropCounters* drops_;
  std::unique_ptr<std::function<void()>> on_data_;
  static constexpr int kBatch = 64;
};

template <class M>
class Writer : public RawWriter {
 public:
  using RawWriter::RawWriter;
  bool Write(std::uint32_t key, const M& msg) { return RawWriter::Write(key, msg); }
};

template <class M>
class Reader : public RawReader {
 public:
  using RawReader::RawReader;
  // Calls fn(const M&, const SampleInfo&) for every valid sample available now (at most
  // max_samples taken); returns how many valid ones.
  template <class F>
  int Take(F&& fn, int max_samples = std::numeric_limits<int>::max()) {
    return TakeInto(
        scratch_,
        [&](const google::protobuf::Message&, const SampleInfo& info) {
          fn(static_cast<const M&>(scratch_), info);
        },
        max_samples);
  }

 private:
  M scratch_;
};

// --- implementation of the template part -------------------------------------------------------

struct TakeBuffers {
  void* samples[64];
  dds_sample_info_t infos[64];
};

int TakeSamples(dds_entity_t reader, TakeBuffers& b, int max_samples);
void ReturnSamples(dds_entity_t reader, TakeBuffers& b, int n);

template <class F>
int RawReader::TakeInto(google::protobuf::Message& scratch, F&& fn, int max_samples) {
  int delivered = 0;
  int taken = 0;
  TakeBuffers b;
  while (taken < max_samples) {
    const int n = TakeSamples(reader_, b, std::min(kBatch, max_samples - taken));
    if (n <= 0) break;
    taken += n;
    for (int i = 0; i < n; ++i) {
      if (!b.infos[i].valid_data) continue;
      SampleInfo info;
      info.source_timestamp_ns = b.infos[i].source_timestamp;
      info.publication_handle = b.infos[i].publication_handle;
      if (!Decode(b.samples[i], scratch, info)) continue;
      fn(scratch, info);
      ++delivered;
    }
    ReturnSamples(reader_, b, n);
    if (n < kBatch) break;
  }
  return delivered;
}

}  // namespace vdyn::transport
