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

// A varint at p (at most 10 bytes, not past end); p moves past it.
inline bool ReadVarint(const std::uint8_t*& p, const std::uint8_t* end, std::uint64_t& out) {
  out = 0;
  for (int shift = 0; shift < 64; shift += 7) {
    if (p >= end) return false;
    const std::uint8_t b = *p++;
    out |= static_cast<std::uint64_t>(b & 0x7f) << shift;
    if ((b & 0x80) == 0) return true;
  }
  return false;
}

// One message's fields, as wire::ForEachField reads them (the same framing rules: a truncated
// varint, a length past the end, field number 0 or a wire type proto3 does not use is not clean),
// written out here because every state a reader takes goes through it: a state's 180 fields, with
// a one-byte tag each, cost half of the protobuf parse through the generic walker and its Field.
bool Clean(const Plan& plan, const std::uint8_t* p, const std::uint8_t* end, int depth) {
  if (depth > kMaxDepth || !plan.usable) return false;
  const Plan::Entry* entries = plan.by_number.data();
  const std::size_t n_entries = plan.by_number.size();
  static const Plan::Entry ignore;
  while (p < end) {
    std::uint64_t tag = *p;
    if (tag < 0x80) {
      ++p;
    } else if (!ReadVarint(p, end, tag)) {
      return false;
    }
    const auto number = static_cast<std::uint32_t>(tag >> 3);
    if (number == 0) return false;
    const Plan::Entry& e = number < n_entries ? entries[number] : ignore;
    // A value of a wire type its field does not have is an unknown field to the parser: the
    // message does not hold it.
    switch (tag & 7) {
      case 0: {
        std::uint64_t v = 0;
        if (!ReadVarint(p, end, v)) return false;
        break;
      }
      case 1: {
        if (end - p < 8) return false;
        if (e.kind == Plan::Kind::kDouble) {
          std::uint64_t bits;
          std::memcpy(&bits, p, sizeof bits);  // little-endian on the wire and here
          if (!Finite<double, std::uint64_t>(bits)) return false;
        }
        p += 8;
        break;
      }
      case 5: {
        if (end - p < 4) return false;
        if (e.kind == Plan::Kind::kFloat) {
          std::uint32_t bits;
          std::memcpy(&bits, p, sizeof bits);
          if (!Finite<float, std::uint32_t>(bits)) return false;
        }
        p += 4;
        break;
      }
      case 2: {
        std::uint64_t n = 0;
        if (!ReadVarint(p, end, n) || n > static_cast<std::uint64_t>(end - p)) return false;
        const std::span<const std::uint8_t> b(p, static_cast<std::size_t>(n));
        switch (e.kind) {
          case Plan::Kind::kIgnore:
            break;
          case Plan::Kind::kDouble:
            if (!PackedFinite<double, std::uint64_t>(b)) return false;
            break;
          case Plan::Kind::kFloat:
            if (!PackedFinite<float, std::uint32_t>(b)) return false;
            break;
          case Plan::Kind::kString:
            if (n > e.max_bytes) return false;
            break;
          case Plan::Kind::kMessage:
            if (!Clean(*e.message, p, p + n, depth + 1)) return false;
            break;
        }
        p += n;
        break;
      }
      default:
        return false;  // groups (3, 4) are not used by proto3; anything else is not protobuf
    }
  }
  return true;
}

Plans& AllPlans() {
  static Plans plans;
  return plans;
}

}  // namespace

bool WireClean(const gp::Descriptor& type, std::span<const std::uint8_t> bytes) {
  static_assert(std::endian::native == std::endian::little,
                "the wire's fixed-width values are little-endian");
  // The plan of the type this thread checked last, without the lock (plans live as long as the
  // process, like the map's keys: a reader checks one type over and over).
  thread_local const gp::Descriptor* last_type = nullptr;
  thread_local const Plan* last_plan = nullptr;
  if (&type != last_type) {
    last_plan = AllPlans().Get(type);
    last_type = &type;
  }
  return last_plan != nullptr && Clean(*last_plan, bytes.data(), bytes.data() + bytes.size(), 0);
}

std::size_t MaxStringBytes(const std::string& name) {
  if (name == "reason") return limits::kMaxReasonBytes;
  if (name.size() >= 3 && name.compare(name.size() - 3, 3, "_id") == 0) return limits::kMaxIdBytes;
  return limits::kMaxNameBytes;
}

Finding CheckMessage(const gp::Message& msg) {
  return Check(msg, true);
}

}  // namespace vdyn::messages
