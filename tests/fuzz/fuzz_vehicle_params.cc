// Fuzz target: vehicle parameter files, protobuf text format and JSON (io syntax, bridge
// validation, physics Validate). The first byte picks the format. Accepted parameters must give
// a simulator that steps to a finite state.
#include <cstdint>
#include <cstdlib>
#include <string>

#include "vdyn/bridge/params.h"
#include "vdyn/physics/simulator.h"
#include "vdyn/physics/world.h"

namespace {

const std::shared_ptr<const vdyn::World>& FlatWorld() {
  static const std::shared_ptr<const vdyn::World> world = vdyn::BuildBuiltinWorld("flat");
  return world;
}

}  // namespace

// Once before the first input, outside libFuzzer's per-input (wall-clock) timeout.
extern "C" int LLVMFuzzerInitialize(int*, char***) {
  (void)FlatWorld();
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size == 0) return 0;
  const bool json = (data[0] & 1) != 0;
  const std::string text(reinterpret_cast<const char*>(data) + 1, size - 1);
  try {
    const vdyn::pb::VehicleParams p = vdyn::ParseVehicleParams(text, json, "fuzz");
    const vdyn::ValidParams valid = vdyn::ParamsFromProto(p);
    vdyn::Simulator sim(FlatWorld(), valid);
    for (int i = 0; i < 50; ++i) {
      if (sim.Step() != vdyn::StepStatus::kOk) break;  // contained, counted: allowed
    }
    if (!sim.state().x.allFinite()) std::abort();
  } catch (const vdyn::ParamsError&) {
  } catch (const vdyn::WorldError&) {
  } catch (const std::invalid_argument&) {
  }
  return 0;
}
