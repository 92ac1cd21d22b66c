// Checks every received message passes before it is used, and the counters of what was dropped.
#pragma once

#include <chrono>
#include <cstdint>
#include <map>
#include <mutex>
#include <string>

#include <google/protobuf/message.h>

namespace vdyn::transport {

// True when every double and float field (nested, repeated included) is finite. On failure,
// `where` (if given) gets the field path, e.g. "wheels[2].fp".
bool AllFinite(const google::protobuf::Message& msg, std::string* where = nullptr);

// Counts dropped or malformed messages by kind and logs each kind once, then at most once every
// 10 s with the count since its last line (a flood of bad input cannot flood the log).
class DropCounters {
 public:
  void Count(const std::string& kind, const std::string& detail = {});
  std::map<std::string, std::uint64_t> Snapshot() const;
  std::uint64_t Total() const;
  std::uint64_t Of(const std::string& kind) const;

 private:
  struct Entry {
    std::uint64_t count = 0;
    std::uint64_t logged = 0;
    std::chrono::steady_clock::time_point last_log{};
  };
  mutable std::mutex mu_;
  std::map<std::string, Entry> entries_;
};

}  // namespace vdyn::transport
