#include "dds.h"

#include <algorithm>
#include <cstring>

#include "vdyn_envelope.h"

namespace vdyn::transport {
namespace {

std::string DdsError(const char* what, dds_return_t rc) {
  return std::string(what) + ": " + dds_strretcode(rc);
}

}  // namespace

Participant::Participant(std::uint32_t domain_id) : domain_id_(domain_id) {
  participant_ = dds_create_participant(domain_id, nullptr, nullptr);
  if (participant_ < 0) {
    throw TransportError(DdsError("cannot create the DDS participant", participant_));
  }
}

Participant::~Participant() {
  if (participant_ > 0) dds_delete(participant_);
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
      throw TransportError(DdsError((std::string("cannot create topic ") + s.name).c_str(), rc));
    }
  }
  return t;
}

RawWriter::RawWriter(Participant& participant, TopicId id, std::int32_t ownership_strength)
    : id_(id) {
  dds_qos_t* q = WriterQos(id, ownership_strength);
  writer_ = dds_create_writer(participant.handle(), participant.Topic(id), q, nullptr);
  dds_delete_qos(q);
  if (writer_ < 0) {
    throw TransportError(
        DdsError((std::string("cannot create a writer on ") + Spec(id).name).c_str(), writer_));
  }
}

RawWriter::~RawWriter() {
  if (writer_ > 0) dds_delete(writer_);
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
  vdyn_dds_Envelope env;
  env.key = key;
  std::strncpy(env.type_name, s.payload, sizeof env.type_name - 1);
  env.type_name[sizeof env.type_name - 1] = '\0';
  env.payload._maximum = static_cast<std::uint32_t>(buffer_.size());
  env.payload._length = static_cast<std::uint32_t>(buffer_.size());
  env.payload._buffer = reinterpret_cast<std::uint8_t*>(buffer_.data());
  env.payload._release = false;
  const dds_return_t rc = dds_write(writer_, &env);
  if (rc != DDS_RETCODE_OK) {
    last_error_ = DdsError("dds_write", rc);
    return false;
  }
  return true;
}

std::uint32_t RawWriter::MatchedReaders() const {
  dds_publication_matched_status_t st;
  if (dds_get_publication_matched_status(writer_, &st) != DDS_RETCODE_OK) return 0;
  return st.current_count;
}

RawReader::RawReader(Participant& participant, TopicId id, DropCounters* drops)
    : id_(id), drops_(drops) {
  dds_qos_t* q = ReaderQos(id);
  reader_ = dds_create_reader(participant.handle(), participant.Topic(id), q, nullptr);
  dds_delete_qos(q);
  if (reader_ < 0) {
    throw TransportError(
        DdsError((std::string("cannot create a reader on ") + Spec(id).name).c_str(), reader_));
  }
  waitset_ = dds_create_waitset(participant.handle());
  condition_ = dds_create_readcondition(reader_, DDS_ANY_STATE);
  if (waitset_ < 0 || condition_ < 0 || dds_waitset_attach(waitset_, condition_, 0) < 0) {
    throw TransportError(std::string("cannot create a waitset for ") + Spec(id).name);
  }
}

RawReader::~RawReader() {
  if (on_data_ && reader_ > 0) dds_set_listener(reader_, nullptr);  // no callback after this
  if (waitset_ > 0) dds_delete(waitset_);
  if (condition_ > 0) dds_delete(condition_);
  if (reader_ > 0) dds_delete(reader_);
}

bool RawReader::Wait(std::chrono::nanoseconds timeout) {
  dds_attach_t triggered;
  const dds_return_t n = dds_waitset_wait(waitset_, &triggered, 1, timeout.count());
  return n > 0;
}

void RawReader::OnDataAvailable(std::function<void()> fn) {
  on_data_ = std::make_unique<std::function<void()>>(std::move(fn));
  dds_listener_t* l = dds_create_listener(on_data_.get());
  dds_lset_data_available(l, [](dds_entity_t, void* arg) {
    (*static_cast<std::function<void()>*>(arg))();
  });
  const dds_return_t rc = dds_set_listener(reader_, l);
  dds_delete_listener(l);
  if (rc != DDS_RETCODE_OK) throw TransportError(DdsError("dds_set_listener", rc));
}

std::uint32_t RawReader::MatchedWriters() const {
  dds_subscription_matched_status_t st;
  if (dds_get_subscription_matched_status(reader_, &st) != DDS_RETCODE_OK) return 0;
  return st.current_count;
}

bool RawReader::Decode(const void* sample, google::protobuf::Message& scratch, SampleInfo& info) {
  const auto* env = static_cast<const vdyn_dds_Envelope*>(sample);
  const TopicSpec& s = Spec(id_);
  info.key = env->key;
  if (std::strncmp(env->type_name, s.payload, sizeof env->type_name) != 0) {
    if (drops_) drops_->Count(std::string("unknown type on ") + s.name, env->type_name);
    return false;
  }
  if (!scratch.ParseFromArray(env->payload._buffer, static_cast<int>(env->payload._length))) {
    if (drops_) drops_->Count(std::string("malformed payload on ") + s.name);
    return false;
  }
  std::string where;
  if (!AllFinite(scratch, &where)) {
    if (drops_) drops_->Count(std::string("non-finite value on ") + s.name, where);
    return false;
  }
  return true;
}

int TakeSamples(dds_entity_t reader, TakeBuffers& b, int max_samples) {
  for (void*& p : b.samples) p = nullptr;  // loans from DDS
  const auto n_max = static_cast<std::uint32_t>(std::clamp(max_samples, 1, 64));
  const dds_return_t n = dds_take(reader, b.samples, b.infos, n_max, n_max);
  return n < 0 ? 0 : static_cast<int>(n);
}

void ReturnSamples(dds_entity_t reader, TakeBuffers& b, int n) {
  if (n > 0) dds_return_loan(reader, b.samples, n);
}

}  // namespace vdyn::transport
