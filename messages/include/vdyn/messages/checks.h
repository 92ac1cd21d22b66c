// What every received message must pass before anyone uses it: finite numbers everywhere and
// string fields of bounded length (the table of limits). One reflective pass over the message.
#pragma once

#include <cstdint>
#include <span>
#include <string>

#include <google/protobuf/message.h>

namespace vdyn::messages {

enum class Problem {
  kNone,
  kNonFinite,      // a double or float field holds NaN or an infinity
  kStringTooLong,  // an id longer than limits::kMaxIdBytes, other text than kMaxNameBytes/Reason
};

struct Finding {
  Problem problem = Problem::kNone;
  std::string field;  // path, e.g. "wheels[2].fp" or "client_id"
};

// Checks the whole message (nested and repeated fields included); the first problem found.
Finding CheckMessage(const google::protobuf::Message& msg);

// The same check on the serialised message, without reflection: true when every double and
// float on the wire is finite and every string within its limit, which makes the message parsed
// from these bytes pass CheckMessage (its values are among those on the wire). False when not
// sure (a bad value somewhere, even one a later occurrence of the field replaced, or bytes it
// does not follow): then CheckMessage decides and names the field. A received state is checked
// this way at a fraction of the reflective pass's cost.
bool WireClean(const google::protobuf::Descriptor& type, std::span<const std::uint8_t> bytes);

// The longest a string field may be, by its name: ids (*_id) limits::kMaxIdBytes, "reason"
// limits::kMaxReasonBytes, anything else limits::kMaxNameBytes.
std::size_t MaxStringBytes(const std::string& field_name);

}  // namespace vdyn::messages
