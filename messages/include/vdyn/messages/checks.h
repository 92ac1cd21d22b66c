// What every received message must pass before anyone uses it: finite numbers everywhere and
// string fields of bounded length (the table of limits). One reflective pass over the message.
#pragma once

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

// True when every double and float field is finite; `where` gets the first bad field's path.
bool AllFinite(const google::protobuf::Message& msg, std::string* where = nullptr);

// The longest a string field may be, by its name: ids (*_id) limits::kMaxIdBytes, "reason"
// limits::kMaxReasonBytes, anything else limits::kMaxNameBytes.
std::size_t MaxStringBytes(const std::string& field_name);

}  // namespace vdyn::messages
