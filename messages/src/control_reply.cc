#include "vdyn/messages/control_reply.h"

#include "vdyn/base/limits.h"
#include "vdyn/base/text.h"

namespace vdyn::messages {

pb::ControlReply ReplyTo(const pb::ControlRequest* request, std::string_view server_id) {
  pb::ControlReply reply;
  if (request != nullptr) {
    reply.set_request_id(request->request_id());
    // A longer id (refused) cut where a character starts: the refusal stays a valid message.
    reply.set_client_id(std::string(base::CutUtf8(request->client_id(), limits::kMaxIdBytes)));
    reply.set_vehicle_id(request->vehicle_id());
  }
  reply.set_server_id(std::string(server_id));
  reply.set_accepted(true);
  return reply;
}

void Refuse(pb::ControlReply& reply, std::string_view reason) {
  reply.set_accepted(false);
  // Cut where a character starts, and said (a cut inside one made the message's string invalid
  // UTF-8, which a receiver's parse refuses; a cut mid-word read as the whole reason).
  reply.set_reason(base::CutText(reason, limits::kMaxReasonBytes));
}

}  // namespace vdyn::messages
