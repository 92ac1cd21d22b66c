#include "vdyn/base/file.h"
#include "vdyn/base/limits.h"
#include "vdyn/base/text.h"
#include "vdyn/io/vehicle_params.h"

#include "vdyn/io/tire_file.h"

#include <fstream>
#include <sstream>

#include <google/protobuf/text_format.h>
#include <google/protobuf/util/json_util.h>

#include "vdyn/messages/text_format.h"

namespace vdyn {
namespace {

namespace gp = google::protobuf;

pb::WheelParams MakeWheel(double z_offset, double stiffness, double damping, double cornering,
                          double longitudinal, double nominal_load, double spin_inertia) {
  pb::WheelParams w;
  w.set_z_offset(z_offset);
  w.set_spring_stiffness(stiffness);
  w.set_damper_coefficient(damping);
  w.set_free_length(0.35);
  w.set_radius(0.32);
  w.set_cornering_stiffness(cornering);
  w.set_bump_stop_length(0.06);
  w.set_bump_stop_stiffness(300000.0);
  w.set_longitudinal_stiffness(longitudinal);
  w.set_nominal_load(nominal_load);
  w.set_spin_inertia(spin_inertia);
  w.set_min_length(0.03);
  w.set_max_length(0.33);
  w.set_camber(0.0);
  return w;
}

}  // namespace

pb::VehicleParams DefaultVehicleParams() {
  pb::VehicleParams p;
  p.set_mass(1500.0);
  p.set_ixx(550.0);
  p.set_iyy(2400.0);
  p.set_izz(2700.0);
  p.set_b(1.2);
  p.set_c(1.5);
  p.set_b_l(0.78);
  p.set_b_p(0.78);
  // Front: 4.09 kN static load per wheel, 1.35 Hz ride, damping ratio ~0.3. The tire stiffnesses
  // are given at the static load (nominal_load); C_kappa ~ 20 Fz. The front wheels are driven.
  *p.mutable_lf() = MakeWheel(0.02, 30000.0, 2200.0, 65000.0, 80000.0, 4087.5, 1.2);
  *p.mutable_rf() = MakeWheel(0.02, 30000.0, 2200.0, 65000.0, 80000.0, 4087.5, 1.2);
  // Rear: 3.27 kN static load per wheel, 1.38 Hz ride; stiffer tires make the car understeer.
  *p.mutable_lr() = MakeWheel(0.02, 25000.0, 1800.0, 75000.0, 65000.0, 3270.0, 1.0);
  *p.mutable_rr() = MakeWheel(0.02, 25000.0, 1800.0, 75000.0, 65000.0, 3270.0, 1.0);
  p.set_mu(0.9);
  p.set_cx(0.30);
  p.set_rho(1.225);
  p.set_sx(2.2);
  p.set_ha(0.10);
  p.set_rolling_resistance(0.012);
  p.set_drive_force_max(6000.0);
  p.set_drive_front_fraction(1.0);
  p.set_brake_force_max(15000.0);
  p.set_brake_front_fraction(0.65);
  p.set_steering_lock(0.6);
  p.set_yaw_mode(pb::YAW_MODE_DYNAMIC);
  p.set_tire_law(pb::TIRE_LAW_FIALA);
  p.set_tire_slip_speed(0.5);
  p.set_cruise_kp(0.6);
  p.set_cruise_ki(0.15);
  p.set_body_front(2.2);
  p.set_body_rear(2.5);
  p.set_body_half_width(0.9);
  p.set_body_probe_height(0.0);
  p.set_wall_stiffness(5.0e6);
  p.set_wall_damping(0.5);
  p.set_wall_friction(0.3);
  p.set_gravity(9.81);
  p.set_steering_trail(0.04);
  p.set_steering_ratio(15.0);
  p.set_model(pb::VEHICLE_MODEL_FULL);
  // The full model: a 110 kW petrol engine, six gears, front-wheel drive (drive_front_fraction).
  p.set_mu_slide_ratio(0.8);
  p.set_tire_load_sensitivity(2.0);
  p.set_tire_contact_half_length(0.09);
  p.set_tire_relaxation_long(0.15);
  p.set_tire_relaxation_lat(0.4);
  p.set_tire_low_speed_damping(6000.0);
  p.set_tire_vertical_stiffness(250000.0);
  p.set_engine_power_max(110000.0);
  p.set_engine_rpm_power_max(6000.0);
  p.set_engine_rpm_idle(800.0);
  p.set_engine_rpm_limit(6800.0);
  p.set_engine_inertia(0.2);
  p.set_engine_brake_torque(60.0);
  p.set_clutch_torque_max(350.0);
  p.set_clutch_engage_rpm(1400.0);
  p.set_clutch_stick_angle(0.3);
  p.set_brake_stick_angle(0.01);
  p.set_stick_damping_time(0.002);
  p.set_gear_count(6);
  p.set_gear_ratio_first(3.6);
  p.set_gear_ratio_top(0.84);
  p.set_gear_ratio_reverse(3.4);
  p.set_final_drive_ratio(4.0);
  p.set_drivetrain_efficiency(0.9);
  p.set_shift_up_rpm(6000.0);
  p.set_shift_down_rpm(2500.0);
  p.set_shift_time(0.25);
  p.set_differential(pb::DIFFERENTIAL_OPEN);
  p.set_handbrake_force_max(8000.0);
  p.set_abs(true);
  p.set_traction_control(true);
  p.set_caster_trail(0.02);
  p.set_scrub_radius(0.01);
  p.set_ackermann(0.5);
  p.set_steering_inertia(0.04);
  p.set_steering_friction(0.8);
  p.set_steering_damping(0.1);
  p.set_steering_follow_frequency(300.0);
  return p;
}

pb::VehicleParams MergeVehicleParams(const pb::VehicleParams& base,
                                     const pb::VehicleParams& update) {
  pb::VehicleParams out = base;
  out.MergeFrom(update);  // proto3 `optional`: only fields present in `update` override
  // A tyre with a name (a file's) replaces the wheel's whole; one without merges its coefficients
  // (a live change of a few); an empty one removes the tyre (the wheel goes back to the brush law).
  const pb::WheelParams* from[] = {&update.lf(), &update.rf(), &update.lr(), &update.rr()};
  pb::WheelParams* to[] = {out.mutable_lf(), out.mutable_rf(), out.mutable_lr(), out.mutable_rr()};
  for (int w = 0; w < 4; ++w) {
    if (!from[w]->has_magic_formula()) continue;
    const pb::MagicFormulaTire& tire = from[w]->magic_formula();
    if (tire.ByteSizeLong() == 0) {
      to[w]->clear_magic_formula();
    } else if (!tire.name().empty()) {
      *to[w]->mutable_magic_formula() = tire;
    }
  }
  return out;
}

pb::VehicleParams ParseVehicleParamsText(const std::string& text, bool json,
                                         const std::string& source_name,
                                         const pb::VehicleParams& base,
                                         const std::filesystem::path* folder) {
  pb::VehicleParams update;
  if (json) {
    gp::util::JsonParseOptions options;
    options.ignore_unknown_fields = false;
    const auto status = gp::util::JsonStringToMessage(text, &update, options);
    if (!status.ok()) {
      throw ParamsError(source_name + ": not valid vehicle parameters JSON: " +
                        std::string(status.message()));
    }
  } else {
    std::string errors;
    if (!messages::ParseTextFormat(text, update, &errors)) {
      throw ParamsError(source_name + ": " + errors);
    }
  }
  if (folder != nullptr) {
    try {
      ResolveTireFiles(update, *folder);
    } catch (const TireFileError& e) {
      throw ParamsError(source_name + ": tire_file: " + e.what());
    }
  }
  return MergeVehicleParams(base, update);
}

pb::VehicleParams ReadVehicleParamsFile(const std::filesystem::path& path,
                                        const pb::VehicleParams& base) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) {
    throw ParamsError(path.string() + ": is a directory, not a vehicle parameter file");
  }
  if (!std::filesystem::exists(path, ec)) {
    throw ParamsError(path.string() + ": no such vehicle parameter file");
  }
  const base::FileText file =
      base::ReadFileBounded(path, limits::kMaxTextFileBytes, "vehicle parameter file");
  if (!file.error.empty()) throw ParamsError(path.string() + ": " + file.error);
  const bool json = path.extension() == ".json";
  const std::filesystem::path folder = path.parent_path();
  return ParseVehicleParamsText(file.text, json, path.string(), base, &folder);
}

std::string DumpVehicleParamsText(const pb::VehicleParams& msg) {
  std::string body;
  gp::TextFormat::Printer printer;
  printer.SetUseShortRepeatedPrimitives(true);
  printer.PrintToString(msg, &body);
  // A wheel on a tyre file rolls on its UNLOADED_RADIUS: said, since its radius field (kept so
  // that the dump reads back as it is) is not what it rolls on.
  std::string tyres;
  const std::pair<const char*, const pb::WheelParams*> wheels[] = {
      {"lf", &msg.lf()}, {"rf", &msg.rf()}, {"lr", &msg.lr()}, {"rr", &msg.rr()}};
  for (const auto& [name, w] : wheels) {
    if (!w->has_magic_formula()) continue;
    tyres += std::string("# ") + name + " rolls on its tyre file's UNLOADED_RADIUS (" +
             base::FormatNumber(w->magic_formula().unloaded_radius()) + " m), not on its radius\n";
  }
  return "# vdyn vehicle parameters (protobuf text format, vdyn.pb.VehicleParams).\n"
         "# SI units; field meanings in proto/vdyn/vehicle_params.proto and docs/model.md.\n"
         "# Pass back with --vehicle FILE; a file may list only the fields it changes.\n" +
         tyres + body;
}

}  // namespace vdyn
