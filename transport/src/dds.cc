#include "vdyn/transport/dds.h"

#include <algorithm>
#include <atomic>
#include <cstdlib>
#include <cstring>
#include <map>
#include <mutex>

#include "vdyn/base/text.h"
#include "vdyn/messages/checks.h"
#include "vdyn_envelope.h"

namespace vdyn::transport {

std::string DdsError(std::string_view what, dds_return_t rc) {
  return std::string(what) + ": " + dds_strretcode(rc);
}

Decoded DecodeEnvelope(TopicId topic, std::string_view type_name,
                       std::span<const std::uint8_t> payload, google::protobuf::Message& into) {
  const TopicSpec& s = Spec(topic);
  Decoded d;
  if (type_name != s.payload || into.GetDescriptor()->full_name() != s.payload) {
    d.outcome = Decoded::Outcome::kUnknownType;
  } else if (payload.size() > s.max_payload_bytes) {
    d.outcome = Decoded::Outcome::kOversized;
  } else if (!into.ParseFromArray(payload.data(), static_cast<int>(payload.size()))) {
    d.outcome = Decoded::Outcome::kMalformed;
  } else if (!messages::WireClean(*into.GetDescriptor(), payload)) {
    // Something to report (or not sure): the reflective pass decides and names the field.
    const messages::Finding f = messages::CheckMessage(into);
    if (f.problem == messages::Problem::kNonFinite) d.outcome = Decoded::Outcome::kNonFinite;
    if (f.problem == messages::Problem::kStringTooLong) d.outcome = Decoded::Outcome::kLongString;
    d.field = f.field;
  }
  return d;
}

Participant::Participant(std::uint32_t domain_id) : Participant(domain_id, ParticipantOptions{}) {}

Participant::Participant(std::uint32_t domain_id, std::size_t receive_buffer_bytes)
    : Participant(domain_id, ParticipantOptions{receive_buffer_bytes, {}}) {}

namespace {

// The domains this process created itself (with a configuration), and the participants on each:
// deleting a domain deletes every participant in it, so the last participant on it deletes it,
// not the one that created it (a Python script's second client died with its first).
struct OwnedDomain {
  dds_entity_t handle = 0;
  int participants = 0;
};
std::mutex g_domains_mu;
std::map<std::uint32_t, OwnedDomain> g_domains;

}  // namespace

Participant::Participant(std::uint32_t domain_id, const ParticipantOptions& options)
    : domain_id_(domain_id) {
  std::unique_lock domains(g_domains_mu);
  OwnedDomain& owned = g_domains[domain_id];
  ++owned.participants;
  struct Leave {  // undone when the constructor throws
    std::uint32_t id;
    bool armed = true;
    ~Leave() {
      if (armed) Participant::LeaveDomain(id);
    }
  };
  if (options.receive_buffer_bytes > 0 && owned.handle == 0) {
    // Ours first, then the user's configuration, so that the user's settings win.
    std::string config = "<Internal><SocketReceiveBufferSize min=\"default\" max=\"" +
                         std::to_string(options.receive_buffer_bytes) + "B\"/></Internal>";
    if (const char* uri = std::getenv("CYCLONEDDS_URI"); uri != nullptr && *uri != '\0') {
      config += ",";
      config += uri;
    }
    // Fails when the domain exists in this process already (another participant made it): then
    // this one joins it as it is.
    const dds_entity_t d = dds_create_domain(domain_id, config.c_str());
    if (d > 0) owned.handle = d;
  }
  domains.unlock();
  Leave leave{domain_id};
  dds_qos_t* q = nullptr;
  if (!options.user_data.empty()) {
    q = dds_create_qos();
    dds_qset_userdata(q, options.user_data.data(), options.user_data.size());
  }
  participant_ = dds_create_participant(domain_id, q, nullptr);
  if (q != nullptr) dds_delete_qos(q);
  if (participant_ < 0) {
    const dds_entity_t rc = participant_;
    participant_ = 0;
    throw TransportError(
        DdsError("cannot create the DDS participant on domain " + std::to_string(domain_id), rc));
  }
  dds_guid_t g;
  if (const dds_return_t rc = dds_get_guid(participant_, &g); rc != DDS_RETCODE_OK) {
    dds_delete(participant_);
    participant_ = 0;
    throw TransportError(DdsError("dds_get_guid of the participant", rc));
  }
  std::memcpy(guid_.data(), g.v, guid_.size());
  leave.armed = false;
}

void Participant::LeaveDomain(std::uint32_t domain_id) {
  std::lock_guard lock(g_domains_mu);
  const auto it = g_domains.find(domain_id);
  if (it == g_domains.end() || --it->second.participants > 0) return;
  if (it->second.handle > 0) dds_delete(it->second.handle);
  g_domains.erase(it);
}

bool Participant::SetUserData(std::string_view text) {
  dds_qos_t* q = dds_create_qos();
  const dds_return_t get = dds_get_qos(participant_, q);
  if (get != DDS_RETCODE_OK) {
    dds_delete_qos(q);
    last_error_ = DdsError("dds_get_qos of the participant", get);
    return false;
  }
  dds_qset_userdata(q, text.data(), text.size());
  const dds_return_t rc = dds_set_qos(participant_, q);
  dds_delete_qos(q);
  if (rc != DDS_RETCODE_OK) {
    last_error_ = DdsError("dds_set_qos (user data) of the participant", rc);
    return false;
  }
  return true;
}

ParticipantReader::ParticipantReader(Participant& participant) {
  reader_ =
      dds_create_reader(participant.handle(), DDS_BUILTIN_TOPIC_DCPSPARTICIPANT, nullptr, nullptr);
  if (reader_ < 0) {
    throw TransportError(
        DdsError("cannot create a reader of the discovered participants", reader_));
  }
  waitset_ = dds_create_waitset(participant.handle());
  if (waitset_ < 0) {
    dds_delete(reader_);
    throw TransportError(DdsError("cannot create a waitset for the participants", waitset_));
  }
  condition_ = dds_create_readcondition(reader_, DDS_ANY_STATE);
  const dds_return_t rc = condition_ < 0 ? condition_ : dds_waitset_attach(waitset_, condition_, 0);
  if (rc < 0) {
    dds_delete(waitset_);
    dds_delete(reader_);
    throw TransportError(DdsError("cannot wait on the discovered participants", rc));
  }
}

ParticipantReader::~ParticipantReader() {
  if (waitset_ > 0) dds_delete(waitset_);
  if (condition_ > 0) dds_delete(condition_);
  if (reader_ > 0) dds_delete(reader_);
}

bool ParticipantReader::Wait(std::chrono::nanoseconds timeout) {
  dds_attach_t triggered;
  const dds_return_t n = dds_waitset_wait(waitset_, &triggered, 1, timeout.count());
  if (n < 0) {
    last_error_ = DdsError("dds_waitset_wait", n);
    return false;
  }
  return n > 0;
}

bool ParticipantReader::Take(std::vector<Peer>& out) {
  constexpr int kBatch = 16;
  while (true) {
    void* samples[kBatch] = {};
    dds_sample_info_t infos[kBatch];
    const dds_return_t n = dds_take(reader_, samples, infos, kBatch, kBatch);
    if (n < 0) {
      last_error_ = DdsError("dds_take of the discovered participants", n);
      return false;
    }
    for (int i = 0; i < n; ++i) {
      const auto* p = static_cast<const dds_builtintopic_participant_t*>(samples[i]);
      Peer peer;
      std::memcpy(peer.guid.data(), p->key.v, peer.guid.size());
      peer.alive = infos[i].instance_state == DDS_ALIVE_INSTANCE_STATE;
      void* value = nullptr;
      std::size_t size = 0;
      if (infos[i].valid_data && p->qos != nullptr && dds_qget_userdata(p->qos, &value, &size) &&
          value != nullptr) {
        peer.user_data.assign(static_cast<const char*>(value), size);
      }
      dds_free(value);
      out.push_back(std::move(peer));
    }
    if (n > 0) {
      if (const dds_return_t rc = dds_return_loan(reader_, samples, n); rc != DDS_RETCODE_OK) {
        last_error_ = DdsError("dds_return_loan of the discovered participants", rc);
        return false;
      }
    }
    if (n < kBatch) return true;
  }
}

Participant::~Participant() {
  if (participant_ > 0) dds_delete(participant_);  // deletes every child entity too
  LeaveDomain(domain_id_);
}

dds_entity_t Participant::Topic(TopicId id) {
  auto& t = topics_[static_cast<int>(id)];
  if (t == 0) {
    const TopicSpec& s = Spec(id);
    dds_qos_t* q = ReaderQos(id);
    t = dds_create_topic(participant_, &vdyn_dds_Envelope_desc, s.name, q, nullptr);
    dds_delete_qos(q);
    if (t < 0) {
      const dds_entity_t rc = t;
      t = 0;
      throw TransportError(DdsError(std::string("cannot create topic ") + s.name, rc));
    }
  }
  return t;
}

namespace {
// Set once a kBatched writer exists in this process (before batching is switched on, so no kEach
// write is left waiting in a packet).
std::atomic<bool> g_batching{false};
}  // namespace

RawWriter::RawWriter(Participant& participant, TopicId id, std::int32_t ownership_strength,
                     Sending sending, const std::string& partition)
    : id_(id), sending_(sending) {
  if (sending == Sending::kBatched) {
    g_batching.store(true);
    // Every domain of the process, existing writers included; a writer created afterwards in
    // these domains starts batched (the setting is read at creation).
    dds_write_set_batch(true);
  }
  dds_entity_t parent = participant.handle();
  if (!partition.empty()) {
    dds_qos_t* pq = PartitionQos(partition);
    publisher_ = dds_create_publisher(participant.handle(), pq, nullptr);
    dds_delete_qos(pq);
    if (publisher_ < 0) {
      const dds_entity_t rc = publisher_;
      publisher_ = 0;
      throw TransportError(DdsError("cannot create a publisher in partition " + partition, rc));
    }
    parent = publisher_;
  }
  // The listener is set with the writer, so no match is missed between creation and setting it.
  dds_listener_t* l = dds_create_listener(&match_);
  if (l == nullptr) throw TransportError("dds_create_listener failed");
  dds_lset_publication_matched(l, [](dds_entity_t, dds_publication_matched_status_t st, void* arg) {
    auto* m = static_cast<Match*>(arg);
    m->count.store(st.current_count, std::memory_order_relaxed);
  });
  dds_qos_t* q = WriterQos(id, ownership_strength);
  writer_ = dds_create_writer(parent, participant.Topic(id), q, l);
  dds_delete_qos(q);
  dds_delete_listener(l);
  if (writer_ < 0) {
    const dds_entity_t rc = writer_;
    writer_ = 0;
    if (publisher_ > 0) dds_delete(publisher_);
    throw TransportError(DdsError(std::string("cannot create a writer on ") + Spec(id).name +
                                      (partition.empty() ? "" : " in partition " + partition),
                                  rc));
  }
}

RawWriter::~RawWriter() {
  if (writer_ > 0) dds_delete(writer_);  // waits for a listener call in progress
  if (publisher_ > 0) dds_delete(publisher_);
}

bool RawWriter::Write(std::uint32_t key, const google::protobuf::Message& msg) {
  const TopicSpec& s = Spec(id_);
  if (msg.GetDescriptor()->full_name() != s.payload) {
    last_error_ = "a " + msg.GetDescriptor()->full_name() + " does not belong on " + s.name;
    return false;
  }
  if (!msg.SerializeToString(&buffer_)) {
    last_error_ = "cannot serialise " + msg.GetDescriptor()->full_name();
    return false;
  }
  return WriteBytes(key, {reinterpret_cast<const std::uint8_t*>(buffer_.data()), buffer_.size()});
}

namespace {
// One sample's envelope for `key`, without its payload.
vdyn_dds_Envelope EnvelopeOf(std::uint32_t key, const TopicSpec& s) {
  vdyn_dds_Envelope env{};
  env.key = key;
  std::strncpy(env.type_name, s.payload, sizeof env.type_name - 1);
  env.type_name[sizeof env.type_name - 1] = '\0';
  return env;
}
}  // namespace

bool RawWriter::Dispose(std::uint32_t key) {
  const TopicSpec& s = Spec(id_);
  vdyn_dds_Envelope env = EnvelopeOf(key, s);
  dds_return_t rc = dds_dispose(writer_, &env);
  if (rc == DDS_RETCODE_OK) rc = dds_unregister_instance(writer_, &env);
  return Sent(rc, "dds_dispose on ", s);
}

bool RawWriter::WriteBytes(std::uint32_t key, std::span<const std::uint8_t> payload) {
  const TopicSpec& s = Spec(id_);
  if (payload.size() > s.max_payload_bytes) {
    last_error_ = "a " + std::to_string(payload.size()) + "-byte " + s.payload +
                  " is larger than " + s.name + " allows (" + std::to_string(s.max_payload_bytes) +
                  " bytes)";
    return false;
  }
  vdyn_dds_Envelope env = EnvelopeOf(key, s);
  env.payload._maximum = static_cast<std::uint32_t>(payload.size());
  env.payload._length = static_cast<std::uint32_t>(payload.size());
  // dds_write copies (serialises) the sample; the buffer stays ours.
  env.payload._buffer = const_cast<std::uint8_t*>(payload.data());
  env.payload._release = false;
  return Sent(dds_write(writer_, &env), "dds_write on ", s);
}

bool RawWriter::Sent(dds_return_t rc, const char* what, const TopicSpec& s) {
  if (sending_ == Sending::kEach && g_batching.load(std::memory_order_relaxed)) {
    dds_write_flush(writer_);
  }
  if (rc != DDS_RETCODE_OK) {
    last_error_ = DdsError(std::string(what) + s.name, rc);
    return false;
  }
  return true;
}

bool RawWriter::Flush() {
  if (sending_ != Sending::kBatched) return true;
  // dds_write_flush (void in Cyclone DDS 0.10.2) sends nothing when it cannot lock the writer; a
  // status read fails in the same case and says why.
  std::uint32_t status = 0;
  if (const dds_return_t rc = dds_get_status_changes(writer_, &status); rc != DDS_RETCODE_OK) {
    last_error_ = DdsError(std::string("dds_write_flush on ") + Spec(id_).name, rc);
    return false;
  }
  dds_write_flush(writer_);
  return true;
}

bool RawWriter::WaitForAcks(std::chrono::nanoseconds timeout) {
  const dds_return_t rc = dds_wait_for_acks(writer_, timeout.count());
  if (rc == DDS_RETCODE_OK) return true;
  last_error_ = DdsError(std::string("dds_wait_for_acks on ") + Spec(id_).name, rc);
  return false;
}

std::uint64_t RawWriter::InstanceHandle() const {
  dds_instance_handle_t h = 0;
  if (dds_get_instance_handle(writer_, &h) != DDS_RETCODE_OK) return 0;
  return h;
}

std::uint32_t RawWriter::MatchedReaders() {
  dds_publication_matched_status_t st;
  const dds_return_t rc = dds_get_publication_matched_status(writer_, &st);
  if (rc != DDS_RETCODE_OK) {
    last_error_ = DdsError("dds_get_publication_matched_status", rc);
    return 0;
  }
  return st.current_count;
}

RawReader::RawReader(Participant& participant, TopicId id, DropCounters* drops, ReaderRole role,
                     const std::string& partition)
    : id_(id), drops_(drops) {
  const std::string name = Spec(id).name;
  dds_entity_t parent = participant.handle();
  if (!partition.empty()) {
    dds_qos_t* sq = PartitionQos(partition);
    subscriber_ = dds_create_subscriber(participant.handle(), sq, nullptr);
    dds_delete_qos(sq);
    if (subscriber_ < 0) {
      const dds_entity_t rc = subscriber_;
      subscriber_ = 0;
      throw TransportError(DdsError("cannot create a subscriber in partition " + partition, rc));
    }
    parent = subscriber_;
  }
  dds_qos_t* q = ReaderQos(id, role);
  reader_ = dds_create_reader(parent, participant.Topic(id), q, nullptr);
  dds_delete_qos(q);
  if (reader_ < 0) {
    const dds_entity_t rc = reader_;
    reader_ = 0;
    if (subscriber_ > 0) dds_delete(subscriber_);
    subscriber_ = 0;
    throw TransportError(DdsError("cannot create a reader on " + name +
                                      (partition.empty() ? "" : " in partition " + partition),
                                  rc));
  }
  participant_ = participant.handle();
  if (drops_ != nullptr) {
    drop_unknown_type_ = drops_->Register("unknown type on " + name);
    drop_oversized_ = drops_->Register("oversized payload on " + name);
    drop_malformed_ = drops_->Register("malformed payload on " + name);
    drop_nonfinite_ = drops_->Register("non-finite value on " + name);
    drop_long_string_ = drops_->Register("oversized string on " + name);
    drop_dds_error_ = drops_->Register("DDS error on " + name);
  }
}

void RawReader::DetachListener() {
  if (!on_data_ || reader_ <= 0) return;
  dds_set_listener(reader_, nullptr);  // no callback after this
  on_data_.reset();
}

RawReader::~RawReader() {
  DetachListener();
  if (waitset_ > 0) dds_delete(waitset_);
  if (condition_ > 0) dds_delete(condition_);
  if (reader_ > 0) dds_delete(reader_);
  if (subscriber_ > 0) dds_delete(subscriber_);
}

bool RawReader::Wait(std::chrono::nanoseconds timeout) {
  // The waitset and its read condition are made by the first Wait: a reader served by a listener
  // (OnDataAvailable) or another Waitset never has them, and Cyclone then signals no condition of
  // this reader's for every sample that arrives (about 1 us a sample on its receive thread).
  if (waitset_ == 0) {
    const std::string name = Spec(id_).name;
    const dds_entity_t ws = dds_create_waitset(participant_);
    const dds_entity_t c = ws < 0 ? ws : dds_create_readcondition(reader_, DDS_ANY_STATE);
    const dds_return_t rc = c < 0 ? c : dds_waitset_attach(ws, c, 0);
    if (rc < 0) {
      if (c > 0) dds_delete(c);
      if (ws > 0) dds_delete(ws);
      last_error_ = DdsError("cannot wait on " + name, rc);
      if (drops_ != nullptr) drops_->Count(drop_dds_error_, "dds_waitset_wait");
      return false;
    }
    waitset_ = ws;
    condition_ = c;
  }
  dds_attach_t triggered;
  const dds_return_t n = dds_waitset_wait(waitset_, &triggered, 1, timeout.count());
  if (n < 0) {
    last_error_ = DdsError("dds_waitset_wait", n);
    if (drops_ != nullptr) drops_->Count(drop_dds_error_, "dds_waitset_wait");
    return false;
  }
  return n > 0;
}

void RawReader::OnDataAvailable(std::function<void()> fn) {
  on_data_ = std::make_unique<Listener>();
  on_data_->fn = std::move(fn);
  dds_listener_t* l = dds_create_listener(on_data_.get());
  if (l == nullptr) throw TransportError("dds_create_listener failed");
  dds_lset_data_available(l, [](dds_entity_t, void* arg) {
    auto* listener = static_cast<Listener*>(arg);
    std::lock_guard lock(listener->mu);
    listener->fn();
  });
  const dds_return_t rc = dds_set_listener(reader_, l);
  dds_delete_listener(l);
  if (rc != DDS_RETCODE_OK) throw TransportError(DdsError("dds_set_listener", rc));
}

std::uint64_t RawReader::SamplesLost() {
  dds_sample_lost_status_t st;
  const dds_return_t rc = dds_get_sample_lost_status(reader_, &st);
  if (rc != DDS_RETCODE_OK) {
    last_error_ = DdsError("dds_get_sample_lost_status", rc);
    return 0;
  }
  return st.total_count;
}

std::uint32_t RawReader::MatchedWriters() {
  return Matches().now;
}

RawReader::WriterMatches RawReader::Matches() {
  dds_subscription_matched_status_t st;
  const dds_return_t rc = dds_get_subscription_matched_status(reader_, &st);
  if (rc != DDS_RETCODE_OK) {
    last_error_ = DdsError("dds_get_subscription_matched_status", rc);
    return {};
  }
  return {st.current_count, st.total_count};
}

Waitset::Waitset(Participant& participant, DropCounters* drops) : drops_(drops) {
  waitset_ = dds_create_waitset(participant.handle());
  if (waitset_ < 0) throw TransportError(DdsError("cannot create a waitset", waitset_));
  if (drops_ != nullptr) drop_error_ = drops_->Register("DDS error in a waitset");
}

Waitset::~Waitset() {
  for (dds_entity_t c : conditions_) {
    dds_waitset_detach(waitset_, c);
    dds_delete(c);
  }
  if (waitset_ > 0) dds_delete(waitset_);
}

void Waitset::Attach(RawReader& reader) {
  const dds_entity_t c = dds_create_readcondition(reader.handle(), DDS_ANY_STATE);
  if (c < 0) throw TransportError(DdsError("cannot create a read condition", c));
  conditions_.push_back(c);
  if (const dds_return_t rc = dds_waitset_attach(waitset_, c, 0); rc != DDS_RETCODE_OK) {
    throw TransportError(DdsError("cannot attach a read condition", rc));
  }
}

bool Waitset::Wait(std::chrono::nanoseconds timeout) {
  dds_attach_t triggered[8];
  const dds_return_t n = dds_waitset_wait(waitset_, triggered, 8, timeout.count());
  if (n < 0) {
    last_error_ = DdsError("dds_waitset_wait", n);
    ++errors_;
    if (drops_ != nullptr) drops_->Count(drop_error_, last_error_);
    return false;
  }
  return n > 0;
}

bool RawReader::MatchedWriterHandles(std::vector<std::uint64_t>& out) {
  out.clear();
  std::vector<dds_instance_handle_t> handles(64);
  while (true) {
    const dds_return_t n = dds_get_matched_publications(reader_, handles.data(), handles.size());
    if (n < 0) {
      last_error_ = DdsError("dds_get_matched_publications", n);
      return false;
    }
    if (static_cast<std::size_t>(n) <= handles.size()) {
      out.assign(handles.begin(), handles.begin() + n);
      return true;
    }
    handles.resize(static_cast<std::size_t>(n));
  }
}

std::int32_t RawReader::WriterStrength(std::uint64_t publication_handle) {
  dds_builtintopic_endpoint_t* ep = dds_get_matched_publication_data(reader_, publication_handle);
  if (ep == nullptr) return 0;
  std::int32_t strength = 0;
  if (ep->qos == nullptr || !dds_qget_ownership_strength(ep->qos, &strength)) strength = 0;
  dds_builtintopic_free_endpoint(ep);
  return strength;
}

std::optional<Guid> RawReader::WriterParticipant(std::uint64_t publication_handle) {
  dds_builtintopic_endpoint_t* ep = dds_get_matched_publication_data(reader_, publication_handle);
  if (ep == nullptr) return std::nullopt;
  Guid guid{};
  static_assert(sizeof ep->participant_key.v == sizeof guid);
  std::memcpy(guid.data(), ep->participant_key.v, guid.size());
  dds_builtintopic_free_endpoint(ep);
  return guid;
}

int RawReader::TakeBatch(Batch& b, int max_samples) {
  for (void*& p : b.samples) p = nullptr;  // loans from DDS
  const auto n_max = static_cast<std::uint32_t>(std::clamp(max_samples, 1, kBatch));
  const dds_return_t n = dds_take(reader_, b.samples, b.infos, n_max, n_max);
  if (n < 0) {
    last_error_ = DdsError("dds_take", n);
    if (drops_ != nullptr) drops_->Count(drop_dds_error_, "dds_take");
    return 0;
  }
  return static_cast<int>(n);
}

void RawReader::ReturnBatch(Batch& b, int n) {
  if (n <= 0) return;
  const dds_return_t rc = dds_return_loan(reader_, b.samples, n);
  if (rc != DDS_RETCODE_OK) {
    last_error_ = DdsError("dds_return_loan", rc);
    if (drops_ != nullptr) drops_->Count(drop_dds_error_, "dds_return_loan");
  }
}

void RawReader::Refused(const SampleInfo& info, int slot, const char* kind, std::string_view detail,
                        const google::protobuf::Message* parsed) {
  if (drops_ != nullptr) drops_->Count(slot, detail);
  if (on_refused) on_refused(info, std::string(kind) + " on " + Spec(id_).name, detail, parsed);
}

void RawReader::Disposed(const void* sample, const dds_sample_info_t& si) {
  if (!on_disposed || si.instance_state != DDS_NOT_ALIVE_DISPOSED_INSTANCE_STATE) return;
  on_disposed(static_cast<const vdyn_dds_Envelope*>(sample)->key);  // its key fields are set
}

bool RawReader::Envelope(const void* sample, const dds_sample_info_t& si, RawSample& out) {
  const auto* env = static_cast<const vdyn_dds_Envelope*>(sample);
  const TopicSpec& s = Spec(id_);
  out.info.key = env->key;
  out.info.source_timestamp_ns = si.source_timestamp;
  out.info.publication_handle = si.publication_handle;
  out.type_name = std::string_view(env->type_name, strnlen(env->type_name, sizeof env->type_name));
  if (out.type_name != s.payload) {
    Refused(out.info, drop_unknown_type_, "unknown type", out.type_name, nullptr);
    return false;
  }
  if (env->payload._length > s.max_payload_bytes) {
    Refused(out.info, drop_oversized_, "oversized payload",
            std::to_string(env->payload._length) + " bytes", nullptr);
    return false;
  }
  out.payload = {env->payload._buffer, env->payload._length};
  return true;
}

bool RawReader::Decode(const RawSample& raw, google::protobuf::Message& scratch) {
  // The envelope's type name and size were checked by Envelope(); here the payload.
  const Decoded d = DecodeEnvelope(id_, raw.type_name, raw.payload, scratch);
  switch (d.outcome) {
    case Decoded::Outcome::kOk:
      return true;
    case Decoded::Outcome::kNonFinite:
      Refused(raw.info, drop_nonfinite_, "non-finite value", d.field, &scratch);
      return false;
    case Decoded::Outcome::kLongString:
      Refused(raw.info, drop_long_string_, "oversized string", d.field, &scratch);
      return false;
    case Decoded::Outcome::kUnknownType:
      Refused(raw.info, drop_unknown_type_, "unknown type", raw.type_name, nullptr);
      return false;
    case Decoded::Outcome::kOversized:
      Refused(raw.info, drop_oversized_, "oversized payload", {}, nullptr);
      return false;
    case Decoded::Outcome::kMalformed:
      break;
  }
  Refused(raw.info, drop_malformed_, "malformed payload", {}, nullptr);
  return false;
}

int RawReader::TakeRaw(const std::function<void(const RawSample&)>& fn, int max_samples) {
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
      fn(raw);
      ++delivered;
    }
    ReturnBatch(b, n);
    if (n < kBatch) break;
  }
  return delivered;
}

}  // namespace vdyn::transport
