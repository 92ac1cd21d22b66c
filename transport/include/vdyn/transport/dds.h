// DDS entities for vdyn: a participant, and typed writers and readers that carry Protocol
// Buffers messages in the envelope of idl/vdyn_envelope.idl. QoS comes from topics.cc only.
// Every DDS return code is checked: construction throws TransportError with the call and the
// reason; a failed write, take or wait is reported (last_error(), a drop counter), never ignored.
#pragma once

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <limits>
#include <memory>
#include <mutex>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include <dds/dds.h>
#include <google/protobuf/arena.h>
#include <google/protobuf/message.h>

#include "vdyn/transport/drops.h"
#include "vdyn/transport/topics.h"

namespace vdyn::transport {

class TransportError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// "what: reason" for a DDS return code.
std::string DdsError(std::string_view what, dds_return_t rc);

// What a reader concludes about one envelope (its type name and payload) on a topic: the checks
// every received sample passes, in order, without DDS (readers use it; so do the fuzz targets).
struct Decoded {
  enum class Outcome {
    kOk,
    kUnknownType,  // the type name is not the topic's payload
    kOversized,    // larger than the topic allows (not parsed)
    kMalformed,    // does not parse as the payload
    kNonFinite,    // a NaN or an infinity somewhere
    kLongString,   // a string field longer than its limit
  } outcome = Outcome::kOk;
  std::string field;  // the offending field, for kNonFinite and kLongString
};
Decoded DecodeEnvelope(TopicId topic, std::string_view type_name,
                       std::span<const std::uint8_t> payload, google::protobuf::Message& into);

// A participant's GUID as DDS gives it: unique on the network, the same seen from everywhere, and
// ordered (std::array compares bytewise), so every process breaks a tie the same way.
using Guid = std::array<std::uint8_t, 16>;

struct ParticipantOptions {
  // The sockets' receive buffer (0: Cyclone DDS's default, 1 MiB; the kernel caps it at
  // net.core.rmem_max): for a process that takes a burst of traffic it must not lose, such as a
  // recorder. Set through the domain's configuration, so it applies when this participant
  // creates the domain in this process (the first on that domain id); CYCLONEDDS_URI still has
  // the last word.
  std::size_t receive_buffer_bytes = 0;
  // Text in the participant's USER_DATA: every other participant on the domain sees it when it
  // discovers this one, before any topic matches, and nothing records it (a server's claim on its
  // vehicles; ParticipantReader reads it).
  std::string user_data;
};

// A DDS domain participant and the vdyn topics created in it (once each).
class Participant {
 public:
  explicit Participant(std::uint32_t domain_id);
  Participant(std::uint32_t domain_id, std::size_t receive_buffer_bytes);
  Participant(std::uint32_t domain_id, const ParticipantOptions& options);
  ~Participant();
  Participant(const Participant&) = delete;
  Participant& operator=(const Participant&) = delete;

  dds_entity_t handle() const { return participant_; }
  dds_entity_t Topic(TopicId id);
  std::uint32_t domain_id() const { return domain_id_; }
  Guid guid() const { return guid_; }
  // Replaces the USER_DATA text; discovery announces the change to every participant. False on
  // error (last_error() says).
  [[nodiscard]] bool SetUserData(std::string_view text);
  const std::string& last_error() const { return last_error_; }

 private:
  // One participant fewer on the domain; the last one deletes a domain this process created.
  static void LeaveDomain(std::uint32_t domain_id);
  dds_entity_t participant_ = 0;
  std::uint32_t domain_id_ = 0;
  Guid guid_{};
  dds_entity_t topics_[9] = {};  // one per TopicId
  std::string last_error_;
};

// The participants on the domain as discovery sees them (DDS's built-in DCPSParticipant topic),
// this process's own included, with their USER_DATA text.
class ParticipantReader {
 public:
  explicit ParticipantReader(Participant& participant);
  ~ParticipantReader();
  ParticipantReader(const ParticipantReader&) = delete;
  ParticipantReader& operator=(const ParticipantReader&) = delete;

  struct Peer {
    Guid guid{};
    std::string user_data;
    bool alive = true;  // false: it has gone (deleted, or its lease ran out)
  };
  // Appends every change since the last call to `out`, oldest first. False on a DDS error
  // (last_error() says; what was taken before it is in `out`).
  [[nodiscard]] bool Take(std::vector<Peer>& out);
  // Blocks until a change is available or the timeout passes; true when one is. A DDS error is
  // false, with last_error() set.
  [[nodiscard]] bool Wait(std::chrono::nanoseconds timeout);
  const std::string& last_error() const { return last_error_; }

 private:
  dds_entity_t reader_ = 0;
  dds_entity_t waitset_ = 0;
  dds_entity_t condition_ = 0;
  std::string last_error_;
};

// How a writer's samples go out. kEach: every write is its own datagram, sent before Write()
// returns. kBatched: writes gather in the writer's packet (several samples per datagram, up to
// Cyclone's message size) until Flush() or until the packet is full; for a burst of samples
// written together, e.g. every vehicle's state of one step. Cyclone DDS 0.10 switches batching
// on for the whole process (dds_write_set_batch), so once a kBatched writer exists every kEach
// writer flushes after each write itself and keeps its behaviour.
enum class Sending { kEach, kBatched };

// Writes protobuf messages on one topic. Serialises into a buffer it keeps between writes (no
// allocation once the buffer has grown to the message's size). With a `partition` the writer
// lives in that partition (a publisher of its own) and only readers there match it; without,
// in the default partition.
class RawWriter {
 public:
  RawWriter(Participant& participant, TopicId id, std::int32_t ownership_strength = 0,
            Sending sending = Sending::kEach, const std::string& partition = {});
  ~RawWriter();
  RawWriter(const RawWriter&) = delete;
  RawWriter& operator=(const RawWriter&) = delete;

  // False when the message is not the topic's payload, cannot be serialised, is larger than the
  // topic allows, or DDS refused it (see last_error()).
  [[nodiscard]] bool Write(std::uint32_t key, const google::protobuf::Message& msg);
  // Writes an already serialised payload of the topic's type as it is (a recording played back).
  [[nodiscard]] bool WriteBytes(std::uint32_t key, std::span<const std::uint8_t> payload);
  // Ends the instance `key` (disposed and unregistered): a reader joining later no longer gets its
  // last sample from a transient-local history (readers take no sample for it: Take skips
  // samples without data).
  [[nodiscard]] bool Dispose(std::uint32_t key);
  // Sends what a kBatched writer has gathered (nothing to do for kEach). False when the writer
  // could not be flushed (last_error()). Cyclone DDS 0.10.2's dds_write_flush returns nothing: it
  // does nothing, silently, when it cannot lock the writer, so the writer is checked first.
  [[nodiscard]] bool Flush();
  // Waits until every matched reliable reader has acknowledged what was written, at most
  // `timeout`; false on timeout or error (last_error() says which).
  [[nodiscard]] bool WaitForAcks(std::chrono::nanoseconds timeout);
  // Number of readers matched right now (0 when the status cannot be read; last_error() says).
  std::uint32_t MatchedReaders();
  // Whether a reader is matched, as a publication-matched listener last set it: an atomic load,
  // no DDS call (for a hot thread that writes only while someone reads).
  bool HasReaders() const { return match_.count.load(std::memory_order_relaxed) > 0; }
  const std::string& last_error() const { return last_error_; }
  dds_entity_t handle() const { return writer_; }
  TopicId topic() const { return id_; }
  // The writer's instance handle, as a reader sees it in SampleInfo::publication_handle.
  std::uint64_t InstanceHandle() const;

 private:
  // The end of a write or dispose: flushed where each write goes out at once, the error kept.
  bool Sent(dds_return_t rc, const char* what, const TopicSpec& s);
  TopicId id_;
  Sending sending_ = Sending::kEach;
  dds_entity_t publisher_ = 0;  // with a partition
  dds_entity_t writer_ = 0;
  struct Match {
    std::atomic<std::uint32_t> count{0};
  };
  Match match_;  // kept by the publication-matched listener
  std::string buffer_;
  std::string last_error_;
};

// What a reader knows of one received sample besides the message.
struct SampleInfo {
  std::uint32_t key = 0;
  std::int64_t source_timestamp_ns = 0;  // the writer's wall clock
  std::uint64_t publication_handle = 0;  // which writer
};

// One sample as it arrived: the envelope's key and type name and the payload's bytes.
struct RawSample {
  std::string_view type_name;
  std::span<const std::uint8_t> payload;
  SampleInfo info;
};

// Reads one topic. Each sample is checked - envelope type name, payload size, protobuf parse,
// finite numbers, string lengths - and one that fails is dropped and counted in `drops` with its
// kind; the rest reach the caller.
//
// With a `partition` the reader lives there (a subscriber of its own) and receives only what
// writers in that partition send: TopicId::kState in VehiclePartition(id) is one vehicle's states,
// filtered before they are sent, not after they arrive.
class RawReader {
 public:
  RawReader(Participant& participant, TopicId id, DropCounters* drops,
            ReaderRole role = ReaderRole::kDefault, const std::string& partition = {});
  ~RawReader();
  RawReader(const RawReader&) = delete;
  RawReader& operator=(const RawReader&) = delete;

  // Blocks until data is available or the timeout passes; true when data is available.
  [[nodiscard]] bool Wait(std::chrono::nanoseconds timeout);
  // Calls fn from DDS's receive thread as soon as data arrives (the lowest latency: no hand-over
  // to another thread). Take from inside fn, and then from nowhere else: Take is not reentrant.
  // Cyclone DDS calls a listener from each of its receive threads (unicast and multicast: a
  // reader with writers on both); the calls are serialised here, so fn never runs twice at once.
  void OnDataAvailable(std::function<void()> fn);
  std::uint32_t MatchedWriters();
  // The writers matched now and ever (the latter counts a writer that went and one that came
  // between two looks, which the former alone would not show); zeros on error.
  struct WriterMatches {
    std::uint32_t now = 0;
    std::uint32_t ever = 0;
  };
  WriterMatches Matches();
  // The instance handles of the writers matched right now into `out`; false on error (then
  // last_error() says, and `out` is empty: not "no writers").
  [[nodiscard]] bool MatchedWriterHandles(std::vector<std::uint64_t>& out);
  // The ownership strength a matched writer declared in its QoS (0 when it declared none or is
  // not matched).
  std::int32_t WriterStrength(std::uint64_t publication_handle);
  // The GUID of the participant a matched writer belongs to; nullopt when it is not matched.
  std::optional<Guid> WriterParticipant(std::uint64_t publication_handle);
  dds_entity_t handle() const { return reader_; }
  TopicId topic() const { return id_; }
  const std::string& last_error() const { return last_error_; }

  // Called for every sample this reader drops, with why (the drop kind, e.g. "non-finite value
  // on vdyn/input", and a detail such as the field) and the parsed message when it did parse
  // (a server answers a refused request, or blames the source of a refused input).
  std::function<void(const SampleInfo&, std::string_view kind, std::string_view detail,
                     const google::protobuf::Message* parsed)>
      on_refused;
  // Called, while a Take runs, for each instance its writer disposed (a removed vehicle's
  // transient-local parameters): the instance's key. A reader that keeps the last sample of
  // each instance forgets it here.
  std::function<void(std::uint32_t key)> on_disposed;

  // Takes every available sample (at most max_samples) and hands each valid one to fn as raw
  // bytes, unparsed: the envelope's type name must be the topic's and the size within its limit.
  // Returns how many were handed over.
  // Samples DDS reports lost to this reader so far (best-effort gaps, overwritten history).
  std::uint64_t SamplesLost();
  [[nodiscard]] int TakeRaw(const std::function<void(const RawSample&)>& fn,
                            int max_samples = std::numeric_limits<int>::max());

 protected:
  // Takes every available sample; for each valid one parses into next() (a message to parse into,
  // empty) and calls fn with it.
  template <class Next, class F>
  int TakeInto(Next&& next, F&& fn, int max_samples);
  // Removes the OnDataAvailable listener, waiting for a call in progress (Cyclone DDS's
  // dds_set_listener does); nothing when there is none. A derived reader whose listener uses its
  // own members calls it in its destructor.
  void DetachListener();

 private:
  static constexpr int kBatch = 64;
  struct Batch {
    void* samples[kBatch];
    dds_sample_info_t infos[kBatch];
  };
  int TakeBatch(Batch& b, int max_samples);
  void ReturnBatch(Batch& b, int n);
  bool Envelope(const void* sample, const dds_sample_info_t& si, RawSample& out);
  // An invalid sample (no data): on_disposed when it says its instance was disposed.
  void Disposed(const void* sample, const dds_sample_info_t& si);
  void Refused(const SampleInfo& info, int slot, const char* kind, std::string_view detail,
               const google::protobuf::Message* parsed);
  bool Decode(const RawSample& raw, google::protobuf::Message& scratch);

  TopicId id_;
  dds_entity_t participant_ = 0;
  dds_entity_t subscriber_ = 0;  // with a partition
  dds_entity_t reader_ = 0;
  dds_entity_t waitset_ = 0;  // made by the first Wait()
  dds_entity_t condition_ = 0;
  DropCounters* drops_;
  // Drop kinds, registered at construction so counting never allocates.
  int drop_unknown_type_ = -1, drop_oversized_ = -1, drop_malformed_ = -1, drop_nonfinite_ = -1,
      drop_long_string_ = -1, drop_dds_error_ = -1;
  struct Listener {
    std::mutex mu;  // one call at a time (see OnDataAvailable)
    std::function<void()> fn;
  };
  std::unique_ptr<Listener> on_data_;
  std::string last_error_;
};

// Waits on several readers at once (one thread serving several topics).
class Waitset {
 public:
  // A failed wait is counted in `drops` ("DDS error in a waitset"), when given.
  explicit Waitset(Participant& participant, DropCounters* drops = nullptr);
  ~Waitset();
  Waitset(const Waitset&) = delete;
  Waitset& operator=(const Waitset&) = delete;
  void Attach(RawReader& reader);
  // Blocks until one of the readers has data or the timeout passes; true when one has. An error
  // is false, with last_error() set and counted.
  [[nodiscard]] bool Wait(std::chrono::nanoseconds timeout);
  const std::string& last_error() const { return last_error_; }
  std::uint64_t errors() const { return errors_; }

 private:
  dds_entity_t waitset_ = 0;
  std::vector<dds_entity_t> conditions_;
  DropCounters* drops_ = nullptr;
  int drop_error_ = -1;
  std::uint64_t errors_ = 0;
  std::string last_error_;
};

template <class M>
class Writer : public RawWriter {
 public:
  using RawWriter::RawWriter;
  [[nodiscard]] bool Write(std::uint32_t key, const M& msg) { return RawWriter::Write(key, msg); }
};

// A message to parse into, over and over, on an arena whose first block is ours. A proto3
// message's Clear() deletes its sub-messages and the next parse allocates them again (a state has
// 30 of them: a quarter of its parse was malloc and free); here each Fresh() resets the arena and
// makes the message anew, which costs a pointer bump per sub-message and frees nothing while it
// fits the first block. Fresh() ends the life of the message it returned before.
template <class M>
class ArenaMessage {
 public:
  explicit ArenaMessage(std::size_t first_block_bytes)
      : block_(std::make_unique_for_overwrite<char[]>(first_block_bytes)),  // untouched until used
        arena_(Options(block_.get(), first_block_bytes)),
        msg_(google::protobuf::Arena::CreateMessage<M>(&arena_)) {}
  ArenaMessage(const ArenaMessage&) = delete;
  ArenaMessage& operator=(const ArenaMessage&) = delete;

  M& Fresh() {
    arena_.Reset();
    msg_ = google::protobuf::Arena::CreateMessage<M>(&arena_);
    return *msg_;
  }
  const M& get() const { return *msg_; }

 private:
  static google::protobuf::ArenaOptions Options(char* block, std::size_t bytes) {
    google::protobuf::ArenaOptions o;
    o.initial_block = block;
    o.initial_block_size = bytes;
    return o;
  }
  std::unique_ptr<char[]> block_;
  google::protobuf::Arena arena_;
  M* msg_;
};

template <class M>
class Reader : public RawReader {
 public:
  Reader(Participant& participant, TopicId id, DropCounters* drops,
         ReaderRole role = ReaderRole::kDefault, const std::string& partition = {})
      : RawReader(participant, id, drops, role, partition), scratch_(FirstBlockBytes(id)) {}
  // A listener's Take parses into scratch_, which goes before ~RawReader runs: the listener is
  // detached first (a state arriving meanwhile crashed net_bench's subscribers as they ended).
  ~Reader() { DetachListener(); }
  Reader(const Reader&) = delete;
  Reader& operator=(const Reader&) = delete;
  // Calls fn(const M&, const SampleInfo&) for every valid sample available now (at most
  // max_samples taken); returns how many valid ones. The message lives until fn returns.
  template <class F>
  [[nodiscard]] int Take(F&& fn, int max_samples = std::numeric_limits<int>::max()) {
    return TakeInto(
        [this]() -> google::protobuf::Message& { return scratch_.Fresh(); },
        [&](const google::protobuf::Message&, const SampleInfo& info) { fn(scratch_.get(), info); },
        max_samples);
  }

 private:
  // Twice the largest payload of the topic (a parsed message takes more room than its bytes),
  // between 16 KiB and 2 MiB: a larger message (a world's meshes) takes further blocks, freed
  // at the next sample.
  static std::size_t FirstBlockBytes(TopicId id) {
    return std::clamp<std::size_t>(2 * Spec(id).max_payload_bytes, 16 * 1024, 2 * 1024 * 1024);
  }
  ArenaMessage<M> scratch_;
};

// --- implementation of the template part -------------------------------------------------------

template <class Next, class F>
int RawReader::TakeInto(Next&& next, F&& fn, int max_samples) {
  int delivered = 0;
  int taken = 0;
  Batch b;
  while (taken < max_samples) {
    const int n = TakeBatch(b, std::min(kBatch, max_samples - taken));
    if (n <= 0) break;
    taken += n;
    for (int i = 0; i < n; ++i) {
      if (!b.infos[i].valid_data) {
        Disposed(b.samples[i], b.infos[i]);
        continue;
      }
      RawSample raw;
      if (!Envelope(b.samples[i], b.infos[i], raw)) continue;
      google::protobuf::Message& scratch = next();
      if (!Decode(raw, scratch)) continue;
      fn(scratch, raw.info);
      ++delivered;
    }
    ReturnBatch(b, n);
    if (n < kBatch) break;
  }
  return delivered;
}

}  // namespace vdyn::transport
