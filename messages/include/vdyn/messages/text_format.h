// A message from protobuf's text format (parameter files, wheel mappings), with every syntax
// error the parser found as "line L, column C: what" (1-based, joined by "; "): what a person
// needs to find the mistake in the file.
#pragma once

#include <string>

namespace google::protobuf {
class Message;
}

namespace vdyn::messages {

// Parses `text` into `m` (cleared first). True when it parsed; else `*errors` says where and why
// ("cannot parse" when the parser gave no reason).
[[nodiscard]] bool ParseTextFormat(const std::string& text, google::protobuf::Message& m,
                                   std::string* errors);

}  // namespace vdyn::messages
