// The parameters panel: a vehicle's parameters as the transient-local topic has them, editable
// field by field (the message's own descriptor lists them, each labelled in words with its unit
// from the one table the documentation is checked against: limits::ParamWords), sent as a
// set_params request with only the changed fields, and answered: accepted at a step, or rejected
// with the server's reason. The request waits for its reply on a worker thread of its own, so a
// frame never blocks on it.
#pragma once

#include <condition_variable>
#include <cstdint>
#include <map>
#include <mutex>
#include <optional>
#include <string>
#include <thread>

#include "vdyn/transport/control_client.h"
#include "vdyn/transport/dds.h"
#include "vdyn/vehicle_params.pb.h"

namespace vdyn::viewer {

class ParamsEditor {
 public:
  ParamsEditor(transport::Participant& participant, std::string client_id);
  ~ParamsEditor();
  ParamsEditor(const ParamsEditor&) = delete;
  ParamsEditor& operator=(const ParamsEditor&) = delete;

  struct Status {
    enum class State { kIdle, kPending, kAccepted, kRejected, kNoReply };
    State state = State::kIdle;
    std::uint32_t vehicle_id = 0;
    std::string text;  // "accepted at step 1234", the rejection's reason, or why no reply came
  };
  Status status() const;

  // Sends `change` (partial parameters) for a vehicle. False while an earlier request waits.
  bool Submit(std::uint32_t vehicle_id, const std::string& server_id, pb::VehicleParams change);

  // The ImGui panel body for one vehicle (inside a window the caller opened). `current` is the
  // newest from the topic, or null while none has arrived.
  void Draw(std::uint32_t vehicle_id, const std::string& server_id,
            const pb::VehicleParams* current);

  // The fields of `edited` that differ from `current` (both complete or partial), as a partial
  // message; empty when nothing changed.
  static pb::VehicleParams Changes(const pb::VehicleParams& current,
                                   const pb::VehicleParams& edited);

  // A field's label: its words and unit ("vehicle mass, kg"; "lf.radius": "wheel radius, m"),
  // or its path where the table has none.
  static std::string FieldLabel(const std::string& path);

  // The fields the last Draw showed, by path ("mass", "lf.radius"): label and screen rectangle.
  struct DrawnField {
    std::string label;
    float x0 = 0, y0 = 0, x1 = 0, y1 = 0;
    std::string text;  // a read-only text field's value (a tyre's name)
  };
  const std::map<std::string, DrawnField>& drawn() const { return drawn_; }

  std::chrono::milliseconds reply_timeout{3000};

 private:
  void Worker();
  bool EditFields(google::protobuf::Message& m, const std::string& prefix);

  transport::ControlClient client_;
  mutable std::mutex mu_;
  std::condition_variable cv_;
  std::optional<pb::ControlRequest> pending_;
  Status status_;
  bool stop_ = false;
  std::thread worker_;

  // The panel's editing copy for one vehicle, and the parameters it started from (when the topic
  // brings new ones and nothing is being edited, the copy follows them).
  std::uint32_t editing_vehicle_ = 0;
  bool editing_valid_ = false;
  pb::VehicleParams base_;
  pb::VehicleParams edited_;
  std::map<std::string, DrawnField> drawn_;
};

}  // namespace vdyn::viewer
