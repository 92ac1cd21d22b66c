#include "vdyn/foxglove/params.h"

#include <cmath>
#include <cstdlib>

#include <google/protobuf/descriptor.h>
#include <google/protobuf/message.h>

namespace vdyn::foxglove {
namespace {

namespace gp = google::protobuf;

void Collect(const gp::Message& m, const std::string& prefix,
             std::vector<protocol::Parameter>& out) {
  std::vector<const gp::FieldDescriptor*> fields;
  m.GetReflection()->ListFields(m, &fields);
  const gp::Reflection* r = m.GetReflection();
  for (const gp::FieldDescriptor* f : fields) {
    if (f->is_repeated()) continue;
    const std::string name = prefix + f->name();
    switch (f->cpp_type()) {
      case gp::FieldDescriptor::CPPTYPE_MESSAGE:
        Collect(r->GetMessage(m, f), name + "/", out);
        break;
      case gp::FieldDescriptor::CPPTYPE_DOUBLE:
        out.push_back({name, r->GetDouble(m, f)});
        break;
      case gp::FieldDescriptor::CPPTYPE_FLOAT:
        out.push_back({name, static_cast<double>(r->GetFloat(m, f))});
        break;
      case gp::FieldDescriptor::CPPTYPE_UINT32:
        out.push_back({name, static_cast<std::int64_t>(r->GetUInt32(m, f))});
        break;
      case gp::FieldDescriptor::CPPTYPE_INT32:
        out.push_back({name, static_cast<std::int64_t>(r->GetInt32(m, f))});
        break;
      case gp::FieldDescriptor::CPPTYPE_BOOL:
        out.push_back({name, r->GetBool(m, f)});
        break;
      case gp::FieldDescriptor::CPPTYPE_ENUM:
        out.push_back({name, r->GetEnum(m, f)->name()});
        break;
      case gp::FieldDescriptor::CPPTYPE_STRING:
        out.push_back({name, r->GetString(m, f)});
        break;
      default:
        break;
    }
  }
}

std::string TypeName(const protocol::ParameterValue& v) {
  switch (v.index()) {
    case 0:
      return "a number";
    case 1:
      return "a whole number";
    case 2:
      return "a boolean";
    default:
      return "a string";
  }
}

std::optional<double> Number(const protocol::ParameterValue& v) {
  if (const auto* d = std::get_if<double>(&v)) return *d;
  if (const auto* i = std::get_if<std::int64_t>(&v)) return static_cast<double>(*i);
  return std::nullopt;
}

}  // namespace

std::vector<protocol::Parameter> ParametersOf(std::uint32_t vehicle_id,
                                              const pb::VehicleParams& params) {
  std::vector<protocol::Parameter> out;
  Collect(params, "vehicle/" + std::to_string(vehicle_id) + "/", out);
  return out;
}

std::optional<ParameterName> ParseParameterName(const std::string& name) {
  static constexpr std::string_view kPrefix = "vehicle/";
  if (name.compare(0, kPrefix.size(), kPrefix) != 0) return std::nullopt;
  const std::size_t slash = name.find('/', kPrefix.size());
  if (slash == std::string::npos || slash == kPrefix.size() || slash + 1 >= name.size()) {
    return std::nullopt;
  }
  const std::string id = name.substr(kPrefix.size(), slash - kPrefix.size());
  if (id.size() > 10 || id.find_first_not_of("0123456789") != std::string::npos)
    return std::nullopt;
  const unsigned long long v = std::strtoull(id.c_str(), nullptr, 10);
  if (v > 0xffffffffull) return std::nullopt;
  return ParameterName{static_cast<std::uint32_t>(v), name.substr(slash + 1)};
}

std::string SetParameter(pb::VehicleParams& params, const std::string& path,
                         const protocol::ParameterValue& value) {
  // The field first, from the descriptors alone: a name that does not resolve changes nothing.
  std::vector<const gp::FieldDescriptor*> chain;
  const gp::Descriptor* d = pb::VehicleParams::descriptor();
  for (std::size_t at = 0;;) {
    const std::size_t slash = path.find('/', at);
    const gp::FieldDescriptor* f =
        d == nullptr ? nullptr
                     : d->FindFieldByName(path.substr(
                           at, slash == std::string::npos ? std::string::npos : slash - at));
    if (f == nullptr || f->is_repeated()) return "no parameter '" + path + "'";
    chain.push_back(f);
    if (slash == std::string::npos) break;
    d = f->cpp_type() == gp::FieldDescriptor::CPPTYPE_MESSAGE ? f->message_type() : nullptr;
    at = slash + 1;
  }
  const gp::FieldDescriptor* f = chain.back();
  const std::string wrong = "'" + path + "' takes ";
  const auto number = Number(value);
  const gp::EnumValueDescriptor* e = nullptr;
  switch (f->cpp_type()) {
    case gp::FieldDescriptor::CPPTYPE_DOUBLE:
      if (!number) return wrong + "a number, not " + TypeName(value);
      break;
    case gp::FieldDescriptor::CPPTYPE_UINT32:
      if (!number || !(*number >= 0 && *number <= 4294967295.0) || std::floor(*number) != *number) {
        return wrong + "a whole number in 0..4294967295";
      }
      break;
    case gp::FieldDescriptor::CPPTYPE_BOOL:
      if (!std::holds_alternative<bool>(value)) return wrong + "a boolean, not " + TypeName(value);
      break;
    case gp::FieldDescriptor::CPPTYPE_ENUM: {
      const auto* s = std::get_if<std::string>(&value);
      e = s != nullptr ? f->enum_type()->FindValueByName(*s) : nullptr;
      if (e == nullptr) {
        std::string names;
        for (int i = 0; i < f->enum_type()->value_count(); ++i) {
          names += (i ? ", " : "") + f->enum_type()->value(i)->name();
        }
        return wrong + "one of " + names;
      }
      break;
    }
    default:
      return "parameter '" + path + "' cannot be set here";
  }
  gp::Message* m = &params;
  for (std::size_t i = 0; i + 1 < chain.size(); ++i)
    m = m->GetReflection()->MutableMessage(m, chain[i]);
  const gp::Reflection* r = m->GetReflection();
  switch (f->cpp_type()) {
    case gp::FieldDescriptor::CPPTYPE_DOUBLE:
      r->SetDouble(m, f, *number);
      break;
    case gp::FieldDescriptor::CPPTYPE_UINT32:
      r->SetUInt32(m, f, static_cast<std::uint32_t>(*number));
      break;
    case gp::FieldDescriptor::CPPTYPE_BOOL:
      r->SetBool(m, f, std::get<bool>(value));
      break;
    default:
      r->SetEnum(m, f, e);
      break;
  }
  return {};
}

}  // namespace vdyn::foxglove
