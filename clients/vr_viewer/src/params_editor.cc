#include "vdyn/viewer/params_editor.h"

#include <imgui.h>

#include <google/protobuf/descriptor.h>
#include <google/protobuf/reflection.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <vector>

#include "vdyn/base/limits.h"

namespace vdyn::viewer {

namespace gp = google::protobuf;

ParamsEditor::ParamsEditor(transport::Participant& participant, std::string client_id)
    : client_(participant, std::move(client_id)) {
  worker_ = std::thread([this] { Worker(); });
}

ParamsEditor::~ParamsEditor() {
  {
    std::lock_guard<std::mutex> lock(mu_);
    stop_ = true;
  }
  cv_.notify_all();
  worker_.join();
}

ParamsEditor::Status ParamsEditor::status() const {
  std::lock_guard<std::mutex> lock(mu_);
  return status_;
}

bool ParamsEditor::Submit(std::uint32_t vehicle_id, const std::string& server_id,
                          pb::VehicleParams change) {
  std::lock_guard<std::mutex> lock(mu_);
  if (pending_ || status_.state == Status::State::kPending) return false;
  pb::ControlRequest req;
  req.set_vehicle_id(vehicle_id);
  req.set_server_id(server_id);
  *req.mutable_set_params()->mutable_params() = std::move(change);
  pending_ = std::move(req);
  status_ = {Status::State::kPending, vehicle_id, "sent, waiting for the reply"};
  cv_.notify_all();
  return true;
}

void ParamsEditor::Worker() {
  std::unique_lock<std::mutex> lock(mu_);
  while (true) {
    cv_.wait(lock, [&] { return stop_ || pending_.has_value(); });
    if (stop_) return;
    pb::ControlRequest req = std::move(*pending_);
    pending_.reset();
    lock.unlock();
    // The first request to a server waits for its answer to a hello (before it has discovered
    // this client, a request reaches no one).
    const auto reply = client_.CallGreeted(req, reply_timeout);
    lock.lock();
    Status s;
    s.vehicle_id = req.vehicle_id();
    if (!reply) {
      s.state = Status::State::kNoReply;
      s.text = client_.last_error();
    } else if (reply->accepted()) {
      s.state = Status::State::kAccepted;
      s.text = "accepted at step " + std::to_string(reply->applied_step());
    } else {
      s.state = Status::State::kRejected;
      s.text = reply->reason().empty() ? "rejected (no reason given)" : reply->reason();
    }
    status_ = std::move(s);
  }
}

pb::VehicleParams ParamsEditor::Changes(const pb::VehicleParams& current,
                                        const pb::VehicleParams& edited) {
  pb::VehicleParams out;
  // Compares field by field through the descriptor (nested wheel messages included).
  std::function<bool(const gp::Message&, const gp::Message&, gp::Message&)> diff =
      [&](const gp::Message& a, const gp::Message& b, gp::Message& o) {
        bool any = false;
        const gp::Descriptor* d = b.GetDescriptor();
        const gp::Reflection* ra = a.GetReflection();
        const gp::Reflection* rb = b.GetReflection();
        const gp::Reflection* ro = o.GetReflection();
        for (int i = 0; i < d->field_count(); ++i) {
          const gp::FieldDescriptor* f = d->field(i);
          if (f->is_repeated()) continue;
          switch (f->cpp_type()) {
            case gp::FieldDescriptor::CPPTYPE_MESSAGE: {
              if (!rb->HasField(b, f)) break;
              gp::Message* sub = ro->MutableMessage(&o, f);
              if (diff(ra->GetMessage(a, f), rb->GetMessage(b, f), *sub)) {
                any = true;
              } else {
                ro->ClearField(&o, f);
              }
              break;
            }
            case gp::FieldDescriptor::CPPTYPE_DOUBLE:
              if (rb->HasField(b, f) &&
                  (!ra->HasField(a, f) || ra->GetDouble(a, f) != rb->GetDouble(b, f))) {
                ro->SetDouble(&o, f, rb->GetDouble(b, f));
                any = true;
              }
              break;
            case gp::FieldDescriptor::CPPTYPE_UINT32:
              if (rb->HasField(b, f) &&
                  (!ra->HasField(a, f) || ra->GetUInt32(a, f) != rb->GetUInt32(b, f))) {
                ro->SetUInt32(&o, f, rb->GetUInt32(b, f));
                any = true;
              }
              break;
            case gp::FieldDescriptor::CPPTYPE_BOOL:
              if (rb->HasField(b, f) &&
                  (!ra->HasField(a, f) || ra->GetBool(a, f) != rb->GetBool(b, f))) {
                ro->SetBool(&o, f, rb->GetBool(b, f));
                any = true;
              }
              break;
            case gp::FieldDescriptor::CPPTYPE_ENUM:
              if (rb->HasField(b, f) &&
                  (!ra->HasField(a, f) || ra->GetEnumValue(a, f) != rb->GetEnumValue(b, f))) {
                ro->SetEnumValue(&o, f, rb->GetEnumValue(b, f));
                any = true;
              }
              break;
            default:
              break;
          }
        }
        return any;
      };
  diff(current, edited, out);
  return out;
}

namespace {

// The field's words under its input, its name and range when hovered.
void Hover(const std::string& path) {
  if (!ImGui::IsItemHovered()) return;
  ImGui::BeginTooltip();
  if (const limits::Range* r = limits::ParamRange(path)) {
    ImGui::Text("%s  in %s", path.c_str(), limits::Describe(*r).c_str());
  } else {
    ImGui::TextUnformatted(path.c_str());
  }
  ImGui::EndTooltip();
}

}  // namespace

std::string ParamsEditor::FieldLabel(const std::string& path) {
  const std::string_view words = limits::ParamWords(path);
  return words.empty() ? path : std::string(words);
}

bool ParamsEditor::EditFields(gp::Message& m, const std::string& prefix) {
  bool changed = false;
  const gp::Descriptor* d = m.GetDescriptor();
  const gp::Reflection* r = m.GetReflection();
  for (int i = 0; i < d->field_count(); ++i) {
    const gp::FieldDescriptor* f = d->field(i);
    if (f->is_repeated()) continue;
    const std::string path = prefix + f->name();
    // The label shown is the field in words with its unit; the ImGui id is its path.
    const std::string label = FieldLabel(path) + "##" + path;
    ImGui::PushID(f->number());
    bool open = false;
    std::string text;
    switch (f->cpp_type()) {
      case gp::FieldDescriptor::CPPTYPE_DOUBLE: {
        double v = r->GetDouble(m, f);
        ImGui::SetNextItemWidth(110);
        if (ImGui::InputDouble(label.c_str(), &v, 0.0, 0.0, "%.6g")) {
          r->SetDouble(&m, f, v);
          changed = true;
        }
        break;
      }
      case gp::FieldDescriptor::CPPTYPE_UINT32: {
        int v = static_cast<int>(r->GetUInt32(m, f));
        ImGui::SetNextItemWidth(110);
        if (ImGui::InputInt(label.c_str(), &v, 1, 1)) {
          r->SetUInt32(&m, f, static_cast<std::uint32_t>(std::max(v, 0)));
          changed = true;
        }
        break;
      }
      case gp::FieldDescriptor::CPPTYPE_BOOL: {
        bool v = r->GetBool(m, f);
        if (ImGui::Checkbox(label.c_str(), &v)) {
          r->SetBool(&m, f, v);
          changed = true;
        }
        break;
      }
      case gp::FieldDescriptor::CPPTYPE_ENUM: {
        const gp::EnumDescriptor* e = f->enum_type();
        const gp::EnumValueDescriptor* cur = r->GetEnum(m, f);
        ImGui::SetNextItemWidth(200);
        if (ImGui::BeginCombo(label.c_str(), cur->name().c_str())) {
          for (int k = 0; k < e->value_count(); ++k) {
            const gp::EnumValueDescriptor* ev = e->value(k);
            if (ImGui::Selectable(ev->name().c_str(), ev == cur)) {
              r->SetEnum(&m, f, ev);
              changed = true;
            }
          }
          ImGui::EndCombo();
        }
        break;
      }
      case gp::FieldDescriptor::CPPTYPE_STRING:  // read only, where given: a tyre's name
        if (f->has_presence() ? !r->HasField(m, f) : r->GetString(m, f).empty()) {
          ImGui::PopID();
          continue;  // not drawn: no rectangle of its own
        }
        text = r->GetString(m, f);
        ImGui::Text("%s: %s", FieldLabel(path).c_str(), text.c_str());
        break;
      case gp::FieldDescriptor::CPPTYPE_MESSAGE: {
        // A group with a name (a wheel's Magic Formula tyre) shows it on the closed group too.
        const gp::Message& sub = r->GetMessage(m, f);
        const gp::FieldDescriptor* name = sub.GetDescriptor()->FindFieldByName("name");
        if (name != nullptr && name->cpp_type() == gp::FieldDescriptor::CPPTYPE_STRING &&
            !name->is_repeated()) {
          text = sub.GetReflection()->GetString(sub, name);
        }
        const std::string shown =
            text.empty() ? label : FieldLabel(path) + ": " + text + "##" + path;
        open = ImGui::TreeNode(shown.c_str());
        break;
      }
      default:
        ImGui::PopID();
        continue;
    }
    const ImVec2 lo = ImGui::GetItemRectMin(), hi = ImGui::GetItemRectMax();
    drawn_[path] = {FieldLabel(path), lo.x, lo.y, hi.x, hi.y, std::move(text)};
    Hover(path);
    if (open) {
      changed |= EditFields(*r->MutableMessage(&m, f), path + ".");
      ImGui::TreePop();
    }
    ImGui::PopID();
  }
  return changed;
}

namespace {

// Set scalar fields, nested messages' fields counted one by one.
int CountFields(const gp::Message& m) {
  std::vector<const gp::FieldDescriptor*> fields;
  m.GetReflection()->ListFields(m, &fields);
  int n = 0;
  for (const gp::FieldDescriptor* f : fields) {
    n += f->cpp_type() == gp::FieldDescriptor::CPPTYPE_MESSAGE
             ? CountFields(m.GetReflection()->GetMessage(m, f))
             : 1;
  }
  return n;
}

}  // namespace

void ParamsEditor::Draw(std::uint32_t vehicle_id, const std::string& server_id,
                        const pb::VehicleParams* current) {
  if (current == nullptr) {
    ImGui::TextWrapped("No parameters of vehicle %u yet (they come on vdyn/params).", vehicle_id);
    return;
  }
  const bool untouched = Changes(base_, edited_).ByteSizeLong() == 0;
  if (!editing_valid_ || editing_vehicle_ != vehicle_id ||
      (untouched && Changes(base_, *current).ByteSizeLong() > 0)) {
    base_ = edited_ = *current;
    editing_vehicle_ = vehicle_id;
    editing_valid_ = true;
  }
  const pb::VehicleParams changes = Changes(*current, edited_);
  const bool dirty = changes.ByteSizeLong() > 0;
  const Status s = status();
  const bool busy = s.state == Status::State::kPending;
  ImGui::BeginDisabled(!dirty || busy);
  if (ImGui::Button("Apply")) Submit(vehicle_id, server_id, changes);
  ImGui::EndDisabled();
  ImGui::SameLine();
  if (ImGui::Button("Revert")) base_ = edited_ = *current;
  ImGui::SameLine();
  if (dirty) {
    ImGui::TextDisabled("(%d changed)", CountFields(changes));
  } else {
    ImGui::TextDisabled("(unchanged)");
  }
  if (s.state != Status::State::kIdle && s.vehicle_id == vehicle_id) {
    const ImVec4 colour = s.state == Status::State::kAccepted  ? ImVec4(0.4f, 0.9f, 0.4f, 1)
                          : s.state == Status::State::kPending ? ImVec4(0.9f, 0.9f, 0.6f, 1)
                                                               : ImVec4(1.0f, 0.45f, 0.4f, 1);
    ImGui::PushStyleColor(ImGuiCol_Text, colour);
    ImGui::TextWrapped("%s%s", s.state == Status::State::kRejected ? "rejected: " : "",
                       s.text.c_str());
    ImGui::PopStyleColor();
  }
  ImGui::Separator();
  ImGui::BeginChild("fields", ImVec2(0, 0), false);
  drawn_.clear();
  EditFields(edited_, "");
  ImGui::EndChild();
}

}  // namespace vdyn::viewer
