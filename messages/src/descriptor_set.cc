#include "vdyn/messages/descriptor_set.h"

#include <functional>
#include <set>

#include <google/protobuf/descriptor.h>
#include <google/protobuf/descriptor.pb.h>

namespace vdyn::messages {

std::string FileDescriptorSetOf(const google::protobuf::Descriptor* d) {
  google::protobuf::FileDescriptorSet set;
  std::set<std::string> done;
  std::function<void(const google::protobuf::FileDescriptor*)> add =
      [&](const google::protobuf::FileDescriptor* f) {
        if (!done.insert(f->name()).second) return;
        for (int i = 0; i < f->dependency_count(); ++i) add(f->dependency(i));
        f->CopyTo(set.add_file());
      };
  add(d->file());
  return set.SerializeAsString();
}

}  // namespace vdyn::messages
