#include "vdyn/transport/state_writers.h"

#include <algorithm>

#include "vdyn/base/limits.h"
#include "vdyn/messages/wire.h"

namespace vdyn::transport {

StateWriters::StateWriters(Participant& participant, DropCounters& drops, Options options)
    : participant_(participant),
      drops_(drops),
      options_(options),
      all_(participant, TopicId::kState, 0, options.sending) {
  drop_create_ = drops_.Register("cannot create a vehicle's state writer (its partition)");
  drop_write_ = drops_.Register("write failed on vdyn/state in a vehicle partition");
  drop_batch_ =
      drops_.Register("cannot create the vdyn/states writer (states go on vdyn/state only)");
  drop_flush_ = drops_.Register("flush failed on vdyn/state");
  try {
    batch_ = std::make_unique<RawWriter>(participant, TopicId::kStates, 0, Sending::kEach);
  } catch (const TransportError& e) {
    // E.g. DDS Security permissions without vdyn/states: readers of every vehicle read
    // vdyn/state instead (a recorder falls back to it).
    drops_.Count(drop_batch_, e.what());
  }
  batched_.reserve(limits::kMaxStatesBytes);
  vehicles_.reserve(512);
  pending_.reserve(512);
  round_ = base::MonotonicNow();
  next_sweep_ = round_ + base::Seconds(1);
}

bool StateWriters::WriteBytes(std::uint32_t key, std::span<const std::uint8_t> payload) {
  bool ok = true;
  if (batch_ && batch_->HasReaders()) {
    // VehicleStates field 1: the state's bytes as they are.
    if (batched_.size() + messages::wire::BytesFieldSize(1, payload.size()) >
        limits::kMaxStatesBytes) {
      ok = WriteBatch() && ok;
    }
    messages::wire::AppendBytesField(batched_, 1, payload);
  }
  if (all_.HasReaders()) {
    if (all_.WriteBytes(key, payload)) {
      ++all_written_;
    } else {
      last_error_ = all_.last_error();
      ok = false;
    }
  }
  auto it = vehicles_.find(key);
  if (it == vehicles_.end()) {
    it = vehicles_.emplace(key, Vehicle{}).first;
    pending_.push_back(key);
  }
  Vehicle& v = it->second;
  v.last_written = round_;
  if (v.writer && v.writer->HasReaders()) {
    if (v.writer->WriteBytes(key, payload)) {
      ++vehicle_written_;
    } else {
      drops_.Count(drop_write_, v.writer->last_error());
    }
  }
  return ok;
}

bool StateWriters::WriteBatch() {
  if (batched_.empty()) return true;
  const bool ok = batch_->WriteBytes(options_.states_key, batched_);
  batched_.clear();
  if (!ok) {
    last_error_ = batch_->last_error();
    return false;
  }
  ++batches_written_;
  return true;
}

bool StateWriters::EndStep() {
  return batched_.size() >= options_.sample_bytes ? WriteBatch() : true;
}

bool StateWriters::Flush() {
  const bool ok = WriteBatch();
  if (!all_.Flush()) drops_.Count(drop_flush_, all_.last_error());
  int created = 0;
  while (!pending_.empty() && created < options_.new_writers_per_flush) {
    const std::uint32_t key = pending_.back();
    pending_.pop_back();
    const auto it = vehicles_.find(key);
    if (it == vehicles_.end() || it->second.writer || it->second.failed) continue;
    ++created;
    Create(key, it->second);
  }
  const base::MonoTime now = base::MonotonicNow();
  round_ = now;
  if (now < next_sweep_) return ok;
  next_sweep_ = now + base::Seconds(1);
  for (auto it = vehicles_.begin(); it != vehicles_.end();) {
    if (now - it->second.last_written > options_.idle) {
      it = vehicles_.erase(it);  // a pending key whose entry is gone is skipped above
    } else {
      ++it;
    }
  }
  return ok;
}

void StateWriters::Create(std::uint32_t key, Vehicle& v) {
  try {
    v.writer = std::make_unique<RawWriter>(participant_, TopicId::kState, 0, Sending::kEach,
                                           VehiclePartition(key));
  } catch (const TransportError& e) {
    // E.g. DDS Security permissions without the vehicle partitions: the vehicle's states still
    // go to everyone; a one-vehicle reader falls back to reading them all.
    v.failed = true;
    drops_.Count(drop_create_, e.what());
  }
}

void StateWriters::Prepare(std::uint32_t key) {
  Vehicle& v = vehicles_[key];
  v.last_written = round_;
  if (!v.writer && !v.failed) Create(key, v);
}

std::size_t StateWriters::vehicle_writers_read() const {
  return static_cast<std::size_t>(std::count_if(
      vehicles_.begin(), vehicles_.end(),
      [](const auto& kv) { return kv.second.writer && kv.second.writer->HasReaders(); }));
}

}  // namespace vdyn::transport
