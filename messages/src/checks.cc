#include "vdyn/messages/checks.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <memory>
#include <mutex>
#include <unordered_map>
#include <vector>

#include <google/protobuf/descriptor.h>

#include "vdyn/base/limits.h"
#include "vdyn/messages/wire.h"

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
          const gp::Message& m =
              repeated ? r->GetRepeatedMessage(msg, f, i) : r->GetMessage(msg, f);
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

// What the wire check does with each field of one message type, by field number.
struct Plan {
  enum class Kind : std::uint8_t { kIgnore, kDouble, kFloat, kString, kMessage };
  struct Entry {
    Kind kind = Kind::kIgnore;
    std::uint32_t max_bytes = 0;    // kString
    const Plan* message = nullptr;  // kMessage
  };
  std::vector<Entry> by_number;  // index: field number
  // False for a type with field numbers beyond kMaxPlannedNumber, and for a type containing one:
  // never walked (kept, not freed: a type of a cycle may point to it).
  bool usable = true;
  const Entry& operator[](std::uint32_t n) const {
    static const Entry ignore;
    return n < by_number.size() ? by_number[n] : ignore;
  }
};

// Field numbers above this make a type's table too large: such types get no plan (CheckMessage).
constexpr int kMaxPlannedNumber = 4096;

class Plans {
 public:
  // The plan of `type` and every type it contains, built once; nullptr when it cannot be walked.
  const Plan* Get(const gp::Descriptor& type) {
    std::lock_guard<std::mutex> lock(mu_);
    const Plan* plan = Build(type);
    return plan->usable ? plan : nullptr;
  }

 private:
  const Plan* Build(const gp::Descriptor& type) {
    if (auto it = plans_.find(&type); it != plans_.end()) return it->second.get();
    auto& slot = plans_[&type];  // before the fields: a type that contains itself finds it
    slot = std::make_unique<Plan>();
    Plan* plan = slot.get();
    int top = 0;
    for (int i = 0; i < type.field_count(); ++i) top = std::max(top, type.field(i)->number());
    if (top > kMaxPlannedNumber) {
      plan->usable = false;
      return plan;
    }
    plan->by_number.resize(static_cast<std::size_t>(top) + 1);
    for (int i = 0; i < type.field_count(); ++i) {
      const gp::FieldDescriptor* f = type.field(i);
      Plan::Entry& e = plan->by_number[static_cast<std::size_t>(f->number())];
      switch (f->type()) {
        case gp::FieldDescriptor::TYPE_DOUBLE:
          e.kind = Plan::Kind::kDouble;
          break;
        case gp::FieldDescriptor::TYPE_FLOAT:
          e.kind = Plan::Kind::kFloat;
          break;
        case gp::FieldDescriptor::TYPE_STRING:
          e.kind = Plan::Kind::kString;
          e.max_bytes = static_cast<std::uint32_t>(MaxStringBytes(f->name()));
          break;
        case gp::FieldDescriptor::TYPE_MESSAGE:
          e.kind = Plan::Kind::kMessage;
          e.message = Build(*f->message_type());
          if (!e.message->usable) plan->usable = false;
          break;
        default:
          break;  // integers, enums, bools and bytes hold nothing to check
      }
    }
    return plan;
  }
  std::mutex mu_;
  std::unordered_map<const gp::Descriptor*, std::unique_ptr<Plan>> plans_;
};

template <class T, class Bits>
bool Finite(std::uint64_t bits) {
  return std::isfinite(std::bit_cast<T>(static_cast<Bits>(bits)));
}

// Every value of a packed repeated double (8 bytes each) or float (4) field.
template <class T, class Bits>
bool PackedFinite(std::span<const std::uint8_t> b) {
  if (b.size() % sizeof(T) != 0) return false;
  for (std::size_t i = 0; i < b.size(); i += sizeof(T)) {
    Bits bits;
    std::memcpy(&bits, b.data() + i, sizeof bits);  // little-endian on the wire and here
    if (!std::isfinite(std::bit_cast<T>(bits))) return false;
  }
  return true;
}

// Nested deeper than protobuf's own parser allows: not followed.
constexpr int kMaxDepth = 100;

bool Clean(const Plan& plan, std::span<const std::uint8_t> bytes, int depth) {
  if (depth > kMaxDepth || !plan.usable) return false;
  bool clean = true;
  const bool framed = wire::ForEachField(bytes, [&](const wire::Field& f) {
    const Plan::Entry& e = plan[f.number];
    // A value of a wire type its field does not have is an unknown field to the parser: the
    // message does not hold it.
    switch (e.kind) {
      case Plan::Kind::kIgnore:
        break;
      case Plan::Kind::kDouble:
        if (f.type == 1) clean = Finite<double, std::uint64_t>(f.value);
        if (f.type == 2) clean = PackedFinite<double, std::uint64_t>(f.bytes);
        break;
      case Plan::Kind::kFloat:
        if (f.type == 5) clean = Finite<float, std::uint32_t>(f.value);
        if (f.type == 2) clean = PackedFinite<float, std::uint32_t>(f.bytes);
        break;
      case Plan::Kind::kString:
        if (f.type == 2) clean = f.bytes.size() <= e.max_bytes;
        break;
      case Plan::Kind::kMessage:
        if (f.type == 2) clean = Clean(*e.message, f.bytes, depth + 1);
        break;
    }
    return clean;
  });
  return framed && clean;
}

Plans& AllPlans() {
  static Plans plans;
  return plans;
}

}  // namespace

bool WireClean(const gp::Descriptor& type, std::span<const std::uint8_t> bytes) {
  static_assert(std::endian::native == std::endian::little,
                "the wire's fixed-width values are little-endian");
  const Plan* plan = AllPlans().Get(type);
  return plan != nullptr && Clean(*plan, bytes, 0);
}

std::size_t MaxStringBytes(const std::string& name) {
  if (name == "reason") return limits::kMaxReasonBytes;
  if (name.size() >= 3 && name.compare(name.size() - 3, 3, "_id") == 0) return limits::kMaxIdBytes;
  return limits::kMaxNameBytes;
}

Finding CheckMessage(const gp::Message& msg) {
  return Check(msg, true);
}

bool AllFinite(const gp::Message& msg, std::string* where) {
  const Finding f = Check(msg, false);
  if (f.problem == Problem::kNone) return true;
  if (where != nullptr) *where = f.field;
  return false;
}

}  // namespace vdyn::messages
