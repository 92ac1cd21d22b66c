// Fuzz target: vehicle parameter files, protobuf text format and JSON (io syntax, bridge
// validation, physics Validate). The first byte picks the format. Accepted parameters must give
// a simulator that steps to a finite state.
#include <cstdint>
#include <cstdlib>
#include <string>

#include "vdyn/bridge/params.h"
#include "vdyn/physics/simulator.h"
#include "vdyn/physics/world.h"
#include "flat_world.h"

using vdyn::fuzz::FlatWorld;

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
