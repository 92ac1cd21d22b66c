// A message type's schema as self-describing bytes: the FileDescriptorSet of its .proto file and
// every file it imports. MCAP recordings (schema encoding "protobuf") and Foxglove's WebSocket
// channels carry this, so a reader decodes a payload with nothing else.
#pragma once

#include <string>

namespace google::protobuf {
class Descriptor;
}

namespace vdyn::messages {

// The FileDescriptorSet (binary) of a message type: its .proto file and every file it imports,
// each after its imports (what `protoc --include_imports --descriptor_set_out` writes).
std::string FileDescriptorSetOf(const google::protobuf::Descriptor* d);

}  // namespace vdyn::messages
