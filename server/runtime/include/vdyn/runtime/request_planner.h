// Control requests made ready off the stepping thread (the server's request thread): every check
// that does not need the session's live state, and everything a request builds - parameters merged,
// validated and converted (ValidateVehicleParams, ParamsFromProto), a new vehicle's simulator at
// rest with its message buffers grown, a reset's or teleport's resting state, the map nodes the
// session will take - so that Session::Commit, at a step boundary, only swaps.
//
// The planner keeps its own view of the session's vehicles (ids, parameters, spawn poses), changed
// by the requests it plans in the order the session applies them: what it accepts, the session
// applies. The one thing it cannot know is a restore's step against the vehicle's step at the
// boundary; so after planning a restore it plans nothing more until the restore has come back from
// Commit (Settle), applied or refused. Commit also checks that each vehicle is what the plan
// assumed, and refuses with the reason when it is not.
#pragma once

#include <map>
#include <memory>
#include <string>

#include "vdyn/runtime/session.h"

namespace vdyn {

class RequestPlanner {
 public:
  RequestPlanner(std::shared_ptr<const World> world, SessionConfig config);

  // Takes the session's vehicles as they are (at start, before any request is planned).
  void Sync(const Session& session);
  // Whether a vehicle exists as far as the planned requests go.
  bool Knows(std::uint32_t vehicle_id) const { return vehicles_.count(vehicle_id) != 0; }

  struct Plan {
    std::string refusal;                        // refused here: why
    std::unique_ptr<PreparedRequest> prepared;  // else: for Session::Commit
    // A step request's input that cannot be applied (its vehicle, its ranges): the steps run
    // without it; the caller counts it.
    std::string bad_step_input;
    // A hello: nothing to plan or apply; the caller answers it (accepted).
    bool hello = false;
  };
  // Plans a request; the request is shared with the outcome and the events that name it.
  [[nodiscard]] Plan Prepare(std::shared_ptr<const pb::ControlRequest> request);
  // A prepared request back from Commit: a restore's outcome settles the planner's view; what the
  // swap replaced is freed here, with the request.
  void Settle(std::unique_ptr<PreparedRequest> spent);
  // True while a planned restore has not come back: plan nothing until it has.
  bool waiting() const { return waiting_ != nullptr; }

 private:
  struct Known {
    std::shared_ptr<const pb::VehicleParams> params;
    std::shared_ptr<const ValidParams> valid;  // made when first needed
    Pose2 spawn_pose;
  };
  const ValidParams& Valid(Known& k);
  std::string PlanMove(const pb::ControlRequest& r, Known& k, PreparedRequest& p);
  std::string PlanSpawn(const pb::ControlRequest& r, PreparedRequest& p);
  std::string PlanSetParams(const pb::ControlRequest& r, Known& k, PreparedRequest& p);
  std::string PlanRestore(const pb::ControlRequest& r, PreparedRequest& p);

  std::shared_ptr<const World> world_;
  SessionConfig config_;
  double h_ = 0;
  std::map<std::uint32_t, Known> vehicles_;
  const PreparedRequest* waiting_ = nullptr;  // the restore not yet settled
  Known waiting_known_;                       // what it brings when applied
};

}  // namespace vdyn
