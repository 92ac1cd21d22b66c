#include "vdyn/messages/checks.h"

#include <cmath>
#include <vector>

#include "vdyn/base/limits.h"

namespace vdyn::messages {

namespace gp = google::protobuf;

namespace {

// "name", "name[3]", "name.inner" or "name[3].inner" (appends: GCC 12 warns falsely on the
// equivalent chain of operator+ at -O3).
std::string FieldPath(const std::string& name, int index, const std::string& inner) {
  std::string out(name);
  if (index >= 0) out.append("[").append(std::to_string(index)).append("]");
  if (!inner.empty()) out.append(".").append(inner);
  return out;
}

Finding Check(const gp::Message& msg, bool strings) {
  const gp::Reflection* r = msg.GetReflection();
  std::vector<const gp::FieldDescriptor*> fields;
  r->ListFields(msg, &fields);
  for (const gp::FieldDescriptor* f : fields) {
    const bool repeated = f->is_repeated();
    const int n = repeated ? r->FieldSize(msg, f) : 1;
    const auto found = [&](Problem p, int i) {
      return Finding{p, FieldPath(f->name(), repeated ? i : -1, {})};
    };
    switch (f->cpp_type()) {
      case gp::FieldDescriptor::CPPTYPE_DOUBLE:
        for (int i = 0; i < n; ++i) {
          const double v = repeated ? r->GetRepeatedDouble(msg, f, i) : r->GetDouble(msg, f);
          if (!std::isfinite(v)) return found(Problem::kNonFinite, i);
        }
        break;
      case gp::FieldDescriptor::CPPTYPE_FLOAT:
        for (int i = 0; i < n; ++i) {
          const float v = repeated ? r->GetRepeatedFloat(msg, f, i) : r->GetFloat(msg, f);
          if (!std::isfinite(v)) return found(Problem::kNonFinite, i);
        }
        break;
      case gp::FieldDescriptor::CPPTYPE_STRING:
        if (!strings || f->type() == gp::FieldDescriptor::TYPE_BYTES) break;
        for (int i = 0; i < n; ++i) {
          std::string scratch;
          const std::string& v = repeated ? r->GetRepeatedStringReference(msg, f, i, &scratch)
                                          : r->GetStringReference(msg, f, &scratch);
          if (v.size() > MaxStringBytes(f->name())) return found(Problem::kStringTooLong, i);
        }
        break;
      case gp::FieldDescriptor::CPPTYPE_MESSAGE:
        for (int i = 0; i < n; ++i) {
          const gp::Message& m = repeated ? r->GetRepeatedMessage(msg, f, i) : r->GetMessage(msg, f);
          Finding inner = Check(m, strings);
          if (inner.problem != Problem::kNone) {
            inner.field = FieldPath(f->name(), repeated ? i : -1, inner.field);
            return inner;
          }
        }
        break;
      default:
        break;
    }
  }
  return {};
}

}  // namespace

std::size_t MaxStringBytes(const std::string& name) {
  if (name == "reason") return limits::kMaxReasonBytes;
  if (name.size() >= 3 && name.compare(name.size() - 3, 3, "_id") == 0) return limits::kMaxIdBytes;
  return limits::kMaxNameBytes;
}

Finding CheckMessage(const gp::Message& msg) { return Check(msg, true); }

bool AllFinite(const gp::Message& msg, std::string* where) {
  const Finding f = Check(msg, false);
  if (f.problem == Problem::kNone) return true;
  if (where != nullptr) *where = f.field;
  return false;
}

}  // namespace vdyn::messages
