// The reply to a control request, made one way by whatever answers requests: the server's session
// and the recorder's player (`vdyn-recorder play` answers pause, resume, step and playback). A
// client matches a reply to its request by the ids echoed here.
#pragma once

#include <string>
#include <string_view>

#include "vdyn/control.pb.h"

namespace vdyn::messages {

// An accepted reply to `request` (nullptr: to no request) from server `server_id`: the request's
// id, client id and vehicle echoed. A client id too long to echo is cut to its limit (such a client
// cannot match it anyway). The caller adds what was applied (step, simulation time).
pb::ControlReply ReplyTo(const pb::ControlRequest* request, std::string_view server_id);

// Turns `reply` into a refusal for `reason`, cut to a reply's limit (limits::kMaxReasonBytes).
void Refuse(pb::ControlReply& reply, std::string_view reason);

}  // namespace vdyn::messages
