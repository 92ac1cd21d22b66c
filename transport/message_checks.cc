#include "message_checks.h"

#include <cmath>

#include <spdlog/spdlog.h>

namespace vdyn::transport {

namespace gp = google::protobuf;

namespace {
// "name", "name[3]", "name.inner" or "name[3].inner" (appends: GCC 12 warns falsely on the
// equivalent chain of operator+ at -O3).
std::string FieldPath(const std::string& name, int index, const std::string& inner) {
  std::string out(name);
  if (index >= 0) {
    out.append("[").append(std::to_string(index)).append("]");
  }
  if (!inner.empty()) out.append(".").append(inner);
  return out;
}
}  // namespace

bool AllFinite(const gp::Message& msg, std::string* where) {
  const gp::Reflection* r = msg.GetReflection();
  std::vector<const gp::FieldDescriptor*> fields;
  r->ListFields(msg, &fields);
  for (const gp::FieldDescriptor* f : fields) {
    const auto bad = [&](int index) {
      if (where != nullptr) *where = FieldPath(f->name(), index, {});
      return false;
    };
    // The first non-finite element of a double or float field (-2: none); -1 for a single value.
    const auto first_bad = [&](auto get_one, auto get_repeated) {
      if (!f->is_repeated()) return std::isfinite((r->*get_one)(msg, f)) ? -2 : -1;
      for (int i = 0; i < r->FieldSize(msg, f); ++i) {
        if (!std::isfinite((r->*get_repeated)(msg, f, i))) return i;
      }
      return -2;
    };
    int index = -2;
    switch (f->cpp_type()) {
      case gp::FieldDescriptor::CPPTYPE_DOUBLE:
        index = first_bad(&gp::Reflection::GetDouble, &gp::Reflection::GetRepeatedDouble);
        if (index != -2) return bad(index);
        break;
      case gp::FieldDescriptor::CPPTYPE_FLOAT:
        index = first_bad(&gp::Reflection::GetFloat, &gp::Reflection::GetRepeatedFloat);
        if (index != -2) return bad(index);
        break;
      case gp::FieldDescriptor::CPPTYPE_MESSAGE:
        if (f->is_repeated()) {
          for (int i = 0; i < r->FieldSize(msg, f); ++i) {
            std::string inner;
            if (!AllFinite(r->GetRepeatedMessage(msg, f, i), &inner)) {
              if (where != nullptr) *where = FieldPath(f->name(), i, inner);
              return false;
            }
          }
        } else {
          std::string inner;
          if (!AllFinite(r->GetMessage(msg, f), &inner)) {
            if (where != nullptr) *where = FieldPath(f->name(), -1, inner);
            return false;
          }
        }
        break;
      default:
        break;
    }
  }
  return true;
}

void DropCounters::Count(const std::string& kind, const std::string& detail) {
  std::uint64_t since = 0;
  bool log = false;
  {
    std::lock_guard<std::mutex> lock(mu_);
    Entry& e = entries_[kind];
    ++e.count;
    const auto now = std::chrono::steady_clock::now();
    if (e.logged == 0 || now - e.last_log >= std::chrono::seconds(10)) {
      since = e.count - e.logged;
      e.logged = e.count;
      e.last_log = now;
      log = true;
    }
  }
  if (log) {
    spdlog::warn("dropped: {}{}{} ({} since the last report of this kind)", kind,
                 detail.empty() ? "" : ": ", detail, since);
  }
}

std::map<std::string, std::uint64_t> DropCounters::Snapshot() const {
  std::lock_guard<std::mutex> lock(mu_);
  std::map<std::string, std::uint64_t> out;
  for (const auto& [k, e] : entries_) out[k] = e.count;
  return out;
}

std::uint64_t DropCounters::Total() const {
  std::lock_guard<std::mutex> lock(mu_);
  std::uint64_t n = 0;
  for (const auto& [k, e] : entries_) n += e.count;
  return n;
}

std::uint64_t DropCounters::Of(const std::string& kind) const {
  std::lock_guard<std::mutex> lock(mu_);
  const auto it = entries_.find(kind);
  return it == entries_.end() ? 0 : it->second.count;
}

}  // namespace vdyn::transport
