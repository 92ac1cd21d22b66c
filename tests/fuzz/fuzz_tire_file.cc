// Fuzz target: Magic Formula tyre files (.tir: io syntax and units, the bridge's checks of the
// coefficients, physics Validate). An accepted tyre on every wheel of the default car must give a
// simulator that steps to a finite state, and its curves must be computable.
#include <cstdint>
#include <cstdlib>
#include <string>

#include "vdyn/bridge/params.h"
#include "vdyn/bridge/tire_curves.h"
#include "vdyn/io/tire_file.h"
#include "vdyn/physics/simulator.h"
#include "vdyn/physics/world.h"
#include "flat_world.h"

using vdyn::fuzz::FlatWorld;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  try {
    const vdyn::pb::MagicFormulaTire tire = vdyn::ParseTireFile(text, "fuzz.tir");
    const vdyn::MagicFormula mf = vdyn::MagicFormulaFromProto(tire);
    if (vdyn::TireCurvesCsv(mf, {mf.fnomin}).empty()) std::abort();
    vdyn::pb::VehicleParams p = vdyn::DefaultVehicleParams();
    for (auto* w : {p.mutable_lf(), p.mutable_rf(), p.mutable_lr(), p.mutable_rr()}) {
      *w->mutable_magic_formula() = tire;
    }
    vdyn::Simulator sim(FlatWorld(), vdyn::ParamsFromProto(p));
    sim.Spawn(FlatWorld()->spawn, 10.0);
    vdyn::DriverInput in;
    in.throttle = 1.0;
    in.steer = 0.1;
    sim.SetInput(in);
    for (int i = 0; i < 50; ++i) {
      if (sim.Step() != vdyn::StepStatus::kOk) break;  // contained, counted: allowed
    }
    if (!sim.state().x.allFinite()) std::abort();
  } catch (const vdyn::ParamsError&) {  // TireFileError is one
  } catch (const vdyn::WorldError&) {
  } catch (const std::invalid_argument&) {
  }
  return 0;
}
