#include "vdyn/foxglove/outbox.h"

#include <algorithm>
#include <cstdio>

namespace vdyn::foxglove {

using protocol::WsOpcode;

std::size_t Outbox::Bytes(const Item& i) {
  const std::size_t n = protocol::kMessageDataHeaderBytes + i.payload->size();
  return protocol::FrameHeaderBytes(n) + n;
}

void Outbox::SetWake(std::function<void()> wake) {
  std::lock_guard lock(mu_);
  wake_ = std::move(wake);
}

void Outbox::ClearWake() {
  std::lock_guard lock(mu_);
  woken_ = false;
}

void Outbox::Wake() {
  // Called with mu_ held; the wake function only posts to the writer's thread.
  if (!woken_ && wake_) {
    woken_ = true;
    wake_();
  }
}

bool Outbox::PushControl(WsOpcode opcode, std::string_view payload) {
  std::string frame;
  frame.reserve(protocol::FrameHeaderBytes(payload.size()) + payload.size());
  protocol::AppendFrameHeader(frame, opcode, payload.size());
  frame.append(payload);
  std::lock_guard lock(mu_);
  if (finishing_) return true;
  if (control_bytes_ + frame.size() > limits_.control_bytes) return false;
  control_bytes_ += frame.size();
  control_.push_back(std::move(frame));
  Wake();
  return true;
}

void Outbox::PushPong(std::string_view ping_payload) {
  std::string frame;
  protocol::AppendFrameHeader(frame, WsOpcode::kPong, ping_payload.size());
  frame.append(ping_payload);
  std::lock_guard lock(mu_);
  if (finishing_) return;
  pong_ = std::move(frame);
  Wake();
}

void Outbox::Finish(std::string_view close_payload) {
  std::string frame;
  protocol::AppendFrameHeader(frame, WsOpcode::kClose, close_payload.size());
  frame.append(close_payload);
  std::lock_guard lock(mu_);
  if (finishing_) return;
  finishing_ = true;
  control_bytes_ += frame.size();
  control_.push_back(std::move(frame));
  data_.clear();
  data_bytes_ = 0;
  latest_.clear();
  pong_.reset();
  time_ns_.reset();
  Wake();
}

bool Outbox::finished() const {
  std::lock_guard lock(mu_);
  return finishing_ && control_.empty();
}

bool Outbox::PushControlData(std::uint32_t subscription_id, std::uint64_t log_time_ns,
                             const std::shared_ptr<const std::string>& payload) {
  const std::size_t n = protocol::kMessageDataHeaderBytes + payload->size();
  std::string frame;
  frame.reserve(protocol::FrameHeaderBytes(n) + n);
  protocol::AppendFrameHeader(frame, WsOpcode::kBinary, n);
  std::uint8_t header[protocol::kMessageDataHeaderBytes];
  protocol::WriteMessageDataHeader(header, subscription_id, log_time_ns);
  frame.append(reinterpret_cast<const char*>(header), sizeof header);
  frame.append(*payload);
  std::lock_guard lock(mu_);
  if (finishing_) return true;
  if (control_bytes_ + frame.size() > limits_.control_bytes) return false;
  control_bytes_ += frame.size();
  control_.push_back(std::move(frame));
  Wake();
  return true;
}

void Outbox::PushData(std::uint32_t subscription_id, std::uint64_t log_time_ns,
                      std::shared_ptr<const std::string> payload, base::MonoTime now,
                      std::int64_t source_ns, bool latest_only) {
  Item item{subscription_id, log_time_ns, std::move(payload), now, source_ns, latest_only};
  const std::size_t bytes = Bytes(item);
  std::lock_guard lock(mu_);
  if (finishing_) return;
  if (latest_only) {
    const auto it = latest_.find(subscription_id);
    if (it != latest_.end() && it->second >= front_seq_) {
      // An unsent one waits: the newer takes its place (and keeps its turn).
      Item& old = data_[static_cast<std::size_t>(it->second - front_seq_)];
      data_bytes_ = data_bytes_ - Bytes(old) + bytes;
      old = std::move(item);
      Wake();
      return;
    }
  }
  data_.push_back(std::move(item));
  data_bytes_ += bytes;
  if (latest_only) latest_[subscription_id] = front_seq_ + data_.size() - 1;
  DropAged(now);
  while (data_bytes_ > limits_.data_bytes && data_.size() > 1) DropFront("bytes");
  MaybeWarn(now);
  Wake();
}

void Outbox::PushTime(std::uint64_t time_ns) {
  std::lock_guard lock(mu_);
  if (finishing_) return;
  time_ns_ = time_ns;
  Wake();
}

void Outbox::Purge(const std::vector<std::uint32_t>& subscription_ids) {
  std::lock_guard lock(mu_);
  std::deque<Item> kept;
  std::size_t bytes = 0;
  latest_.clear();
  for (Item& i : data_) {
    if (std::find(subscription_ids.begin(), subscription_ids.end(), i.subscription_id) !=
        subscription_ids.end()) {
      continue;
    }
    bytes += Bytes(i);
    if (i.latest_only) latest_[i.subscription_id] = front_seq_ + kept.size();
    kept.push_back(std::move(i));
  }
  data_ = std::move(kept);
  data_bytes_ = bytes;
}

void Outbox::DropFront(const char*) {
  const Item& i = data_.front();
  const std::size_t b = Bytes(i);
  if (i.latest_only) {
    const auto it = latest_.find(i.subscription_id);
    if (it != latest_.end() && it->second == front_seq_) latest_.erase(it);
  }
  data_bytes_ -= b;
  data_.pop_front();
  ++front_seq_;
  ++counters_.dropped_messages;
  counters_.dropped_bytes += b;
  ++unreported_messages_;
  unreported_bytes_ += b;
}

void Outbox::DropAged(base::MonoTime now) {
  while (!data_.empty() && now - data_.front().queued > limits_.data_age) DropFront("age");
}

void Outbox::MaybeWarn(base::MonoTime now) {
  if (unreported_messages_ == 0 || finishing_) return;
  if (warned_ && now - last_warning_ < base::Seconds(1)) return;
  char text[320];
  std::snprintf(text, sizeof text,
                "vdyn-foxglove: this connection reads slower than its subscriptions arrive: %llu "
                "message%s (%.1f kB) dropped, oldest first (send queue bound %.0f kB, %.0f ms); "
                "it gets the newest",
                static_cast<unsigned long long>(unreported_messages_),
                unreported_messages_ == 1 ? "" : "s", static_cast<double>(unreported_bytes_) / 1e3,
                static_cast<double>(limits_.data_bytes) / 1e3, limits_.data_age.millis());
  const std::string json = protocol::StatusJson(protocol::StatusLevel::kWarning, text);
  std::string frame;
  protocol::AppendFrameHeader(frame, WsOpcode::kText, json.size());
  frame += json;
  // A warning is never a reason to close: it may pass the control bound.
  control_bytes_ += frame.size();
  control_.push_back(std::move(frame));
  unreported_messages_ = 0;
  unreported_bytes_ = 0;
  last_warning_ = now;
  warned_ = true;
  ++counters_.warnings;
}

bool Outbox::Take(std::string& out, std::size_t max_bytes, base::MonoTime now,
                  std::vector<std::int64_t>& stamps) {
  std::lock_guard lock(mu_);
  DropAged(now);
  MaybeWarn(now);
  if (!time_ns_ && !pong_ && control_.empty() && data_.empty()) return false;
  if (pong_) {
    out += *pong_;
    pong_.reset();
    ++counters_.sent_messages;
  }
  if (time_ns_) {
    std::uint8_t t[protocol::kTimeBytes];
    protocol::WriteTime(t, *time_ns_);
    protocol::AppendFrameHeader(out, WsOpcode::kBinary, sizeof t);
    out.append(reinterpret_cast<const char*>(t), sizeof t);
    time_ns_.reset();
  }
  while (!control_.empty() && out.size() < max_bytes) {
    out += control_.front();
    control_bytes_ -= control_.front().size();
    control_.pop_front();
    ++counters_.sent_messages;
  }
  while (!data_.empty() && out.size() < max_bytes) {
    Item& i = data_.front();
    const std::size_t n = protocol::kMessageDataHeaderBytes + i.payload->size();
    protocol::AppendFrameHeader(out, WsOpcode::kBinary, n);
    std::uint8_t header[protocol::kMessageDataHeaderBytes];
    protocol::WriteMessageDataHeader(header, i.subscription_id, i.log_time_ns);
    out.append(reinterpret_cast<const char*>(header), sizeof header);
    out.append(*i.payload);
    if (i.source_ns != 0) stamps.push_back(i.source_ns);
    if (i.latest_only) {
      const auto it = latest_.find(i.subscription_id);
      if (it != latest_.end() && it->second == front_seq_) latest_.erase(it);
    }
    data_bytes_ -= Bytes(i);
    data_.pop_front();
    ++front_seq_;
    ++counters_.sent_messages;
  }
  return true;
}

Outbox::Counters Outbox::counters() const {
  std::lock_guard lock(mu_);
  Counters c = counters_;
  c.queued_bytes = data_bytes_ + control_bytes_ + (pong_ ? pong_->size() : 0);
  return c;
}

}  // namespace vdyn::foxglove
