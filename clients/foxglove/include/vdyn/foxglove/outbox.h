// One WebSocket client's send queue, so that a slow client slows nothing else: the source thread
// only ever appends here (never waits for a socket), the client's writer takes whole frames out.
//
//   control  what must arrive, in order: JSON (server info, advertise, status, parameters) and
//            message data that is sent once (a world's terrain). Never dropped; over its bound
//            the client is hopelessly behind and is closed.
//   data     message data of subscriptions, bounded in bytes and in age: the oldest goes first
//            (counted, and said to the client in a status warning at most once a second), so a
//            client that catches up gets fresh data, not a burst of old data. A latest-only
//            subscription (scene, transforms) keeps one unsent message, replaced by the newer.
//   time     the server's newest time, latest-only, sent first.
#pragma once

#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <unordered_map>
#include <vector>

#include "vdyn/base/time.h"
#include "vdyn/foxglove/protocol.h"

namespace vdyn::foxglove {

class Outbox {
 public:
  struct Limits {
    std::size_t data_bytes = 4u << 20;
    base::Nanos data_age = base::Milliseconds(250);
    std::size_t control_bytes = 64u << 20;
  };
  explicit Outbox(Limits limits) : limits_(limits) {}

  // A whole WebSocket message that must arrive. False when the control queue would pass its
  // bound (nothing is queued then: the caller closes the client).
  [[nodiscard]] bool PushControl(protocol::WsOpcode opcode, std::string_view payload);
  // Message data that must arrive (a subscriber's first copy of the world).
  [[nodiscard]] bool PushControlData(std::uint32_t subscription_id, std::uint64_t log_time_ns,
                                     const std::shared_ptr<const std::string>& payload);
  // Message data of a subscription; `source_ns` (the DDS source stamp, wall clock) is kept for
  // the latency figures, 0 for none.
  void PushData(std::uint32_t subscription_id, std::uint64_t log_time_ns,
                std::shared_ptr<const std::string> payload, base::MonoTime now,
                std::int64_t source_ns = 0, bool latest_only = false);
  void PushTime(std::uint64_t time_ns);
  // The answer to a ping: only the newest ping's pong is kept until it is sent (RFC 6455 5.5.3
  // allows it), so a client that pings without reading holds one pong here, not a queue of them.
  void PushPong(std::string_view ping_payload);
  // Drops queued data of these subscriptions (unsubscribed, or their channel went).
  void Purge(const std::vector<std::uint32_t>& subscription_ids);

  // The end: a close frame with this payload after what control holds; queued data is dropped
  // and later pushes are ignored.
  void Finish(std::string_view close_payload);
  // Finish was called and everything up to the close frame was taken.
  bool finished() const;

  // For the writer: appends whole frames to `out` until it holds at least `max_bytes` or nothing
  // waits (the time first, then control, then data after dropping what is older than the age
  // bound); the source stamps of the data messages taken go to `stamps`. False when nothing
  // waited.
  bool Take(std::string& out, std::size_t max_bytes, base::MonoTime now,
            std::vector<std::int64_t>& stamps);

  struct Counters {
    std::uint64_t sent_messages = 0;
    std::uint64_t dropped_messages = 0;
    std::uint64_t dropped_bytes = 0;
    std::uint64_t warnings = 0;
    std::size_t queued_bytes = 0;
  };
  Counters counters() const;

  // Calls `wake` after a push when the writer was not yet told that something waits: the writer
  // calls ClearWake() before it takes.
  void SetWake(std::function<void()> wake);
  void ClearWake();

 private:
  struct Item {
    std::uint32_t subscription_id = 0;
    std::uint64_t log_time_ns = 0;
    std::shared_ptr<const std::string> payload;
    base::MonoTime queued;
    std::int64_t source_ns = 0;
    bool latest_only = false;
  };
  static std::size_t Bytes(const Item& i);
  void DropFront(const char* why);
  void DropAged(base::MonoTime now);
  void MaybeWarn(base::MonoTime now);
  void Wake();

  Limits limits_;
  mutable std::mutex mu_;
  std::deque<std::string> control_;  // whole frames
  std::size_t control_bytes_ = 0;
  std::deque<Item> data_;
  std::size_t data_bytes_ = 0;
  std::uint64_t front_seq_ = 0;                              // sequence number of data_.front()
  std::unordered_map<std::uint32_t, std::uint64_t> latest_;  // subscription -> its queued item
  std::optional<std::uint64_t> time_ns_;
  std::optional<std::string> pong_;  // a whole pong frame
  Counters counters_;
  std::uint64_t unreported_messages_ = 0, unreported_bytes_ = 0;
  base::MonoTime first_unreported_{};
  base::MonoTime last_warning_{};
  bool warned_ = false;
  bool finishing_ = false;
  std::function<void()> wake_;
  bool woken_ = false;
};

}  // namespace vdyn::foxglove
