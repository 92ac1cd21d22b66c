#include "vdyn/wheel_input/mapping.h"

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>

#include <google/protobuf/text_format.h>

#include "vdyn/base/file.h"
#include "vdyn/base/limits.h"
#include "vdyn/messages/text_format.h"

namespace vdyn::wheel_input {
namespace {

namespace gp = google::protobuf;

// A pedal's travel must span at least this many raw units: a calibration that saw no movement
// would otherwise divide by (almost) zero.
constexpr std::int64_t kMinSpan = 1000;

// The distance between two raw values, in 64 bits: values from a file may be any int32.
std::int64_t Span(std::int32_t a, std::int32_t b) {
  const std::int64_t d = std::int64_t{b} - std::int64_t{a};
  return d < 0 ? -d : d;
}

void CheckRange(std::vector<std::string>& why, const std::string& field, const limits::Range& r,
                double v) {
  std::string s = limits::Check(r, v);
  if (!s.empty()) why.push_back(field + ": " + s);
}

// A whole-number field (raw values, indices): the value as the file holds it, not as a double
// (2147483647, not 2.147483647e9).
void CheckWhole(std::vector<std::string>& why, const std::string& field, const limits::Range& r,
                std::int64_t v) {
  if (limits::Check(r, static_cast<double>(v)).empty()) return;
  why.push_back(field + ": " + std::string(r.what) + " must be in " + limits::Describe(r) +
                ", got " + std::to_string(v));
}

void CheckAxis(std::vector<std::string>& why, const std::string& field, int axis, int axes) {
  CheckWhole(why, field, limits::kAxisIndex, axis);
  if (axes >= 0 && axis >= axes) {
    why.push_back(field + ": axis " + std::to_string(axis) + " but the device has " +
                  std::to_string(axes) + " axes");
  }
}

void CheckPedal(std::vector<std::string>& why, const std::string& name, const pb::PedalAxis& p,
                int axes, int pedal_axes) {
  if (!p.has_axis()) return;
  const int n = p.on_pedal_device() ? pedal_axes : axes;
  CheckAxis(why, name + ".axis", p.axis(), n);
  if (!p.has_rest() || !p.has_full()) {
    why.push_back(name + ": needs rest and full raw values");
    return;
  }
  CheckWhole(why, name + ".rest", limits::kRawAxis, p.rest());
  CheckWhole(why, name + ".full", limits::kRawAxis, p.full());
  if (Span(p.rest(), p.full()) < kMinSpan) {
    why.push_back(name + ": rest " + std::to_string(p.rest()) + " and full " +
                  std::to_string(p.full()) + " are less than " + std::to_string(kMinSpan) +
                  " raw units apart");
  }
  if (p.has_dead_zone()) CheckRange(why, name + ".dead_zone", limits::kDeadZone, p.dead_zone());
  if (p.has_gamma()) CheckRange(why, name + ".gamma", limits::kPedalGamma, p.gamma());
}

}  // namespace

std::string VidPid(std::uint16_t vendor_id, std::uint16_t product_id) {
  char buf[16];
  std::snprintf(buf, sizeof buf, "%04x:%04x", vendor_id, product_id);
  return buf;
}

std::vector<std::string> ValidateMapping(const pb::WheelMapping& m, int axes, int buttons) {
  std::vector<std::string> why;
  const auto& s = m.steer();
  if (!s.has_axis() || !s.has_left() || !s.has_right() || !s.has_range_deg()) {
    why.push_back("steer: needs axis, left, right and range_deg");
  } else {
    CheckAxis(why, "steer.axis", s.axis(), axes);
    CheckWhole(why, "steer.left", limits::kRawAxis, s.left());
    CheckWhole(why, "steer.right", limits::kRawAxis, s.right());
    if (Span(s.left(), s.right()) < kMinSpan) {
      why.push_back("steer: left " + std::to_string(s.left()) + " and right " +
                    std::to_string(s.right()) + " are less than " + std::to_string(kMinSpan) +
                    " raw units apart");
    }
    CheckRange(why, "steer.range_deg", limits::kWheelRangeDeg, s.range_deg());
  }
  if (s.has_dead_zone()) CheckRange(why, "steer.dead_zone", limits::kDeadZone, s.dead_zone());
  const int pedal_axes = -1;  // the pedal device's count is checked when it is opened
  CheckPedal(why, "throttle", m.throttle(), axes, pedal_axes);
  CheckPedal(why, "brake", m.brake(), axes, pedal_axes);
  CheckPedal(why, "clutch", m.clutch(), axes, pedal_axes);
  CheckPedal(why, "handbrake", m.handbrake(), axes, pedal_axes);
  if (m.has_combined() && m.combined().has_axis()) {
    const auto& c = m.combined();
    if (m.throttle().has_axis() || m.brake().has_axis()) {
      why.push_back("combined: throttle and brake are on one axis, so neither may have its own");
    }
    CheckAxis(why, "combined.axis", c.axis(), c.on_pedal_device() ? pedal_axes : axes);
    if (!c.has_rest() || !c.has_throttle_full() || !c.has_brake_full()) {
      why.push_back("combined: needs rest, throttle_full and brake_full");
    } else {
      CheckWhole(why, "combined.rest", limits::kRawAxis, c.rest());
      CheckWhole(why, "combined.throttle_full", limits::kRawAxis, c.throttle_full());
      CheckWhole(why, "combined.brake_full", limits::kRawAxis, c.brake_full());
      const std::int64_t t = std::int64_t{c.throttle_full()} - c.rest();
      const std::int64_t b = std::int64_t{c.brake_full()} - c.rest();
      if (std::abs(t) < kMinSpan || std::abs(b) < kMinSpan || (t > 0) == (b > 0)) {
        why.push_back(
            "combined: throttle_full and brake_full must lie on opposite sides of rest, "
            "each at least " +
            std::to_string(kMinSpan) + " raw units from it");
      }
    }
    if (c.has_dead_zone()) CheckRange(why, "combined.dead_zone", limits::kDeadZone, c.dead_zone());
  }
  // Two controls on one axis of one device would move together (issue 33: throttle and brake on
  // one axis were accepted, so every press both drove and braked); one shared pedal axis is what
  // `combined` describes.
  {
    struct Use {
      const char* name;
      bool pedal_device;
      int axis;
    };
    std::vector<Use> uses;
    if (s.has_axis()) uses.push_back({"steer", false, s.axis()});
    const std::pair<const char*, const pb::PedalAxis*> pedals[] = {{"throttle", &m.throttle()},
                                                                   {"brake", &m.brake()},
                                                                   {"clutch", &m.clutch()},
                                                                   {"handbrake", &m.handbrake()}};
    for (const auto& [name, p] : pedals) {
      if (p->has_axis()) uses.push_back({name, p->on_pedal_device(), p->axis()});
    }
    if (m.has_combined() && m.combined().has_axis()) {
      uses.push_back({"combined", m.combined().on_pedal_device(), m.combined().axis()});
    }
    for (std::size_t i = 0; i < uses.size(); ++i) {
      for (std::size_t j = 0; j < i; ++j) {
        if (uses[i].axis != uses[j].axis || uses[i].pedal_device != uses[j].pedal_device) continue;
        why.push_back(std::string(uses[j].name) + " and " + uses[i].name + " are both on axis " +
                      std::to_string(uses[i].axis) + " of the " +
                      (uses[i].pedal_device ? "pedal device" : "wheel") +
                      ": each control needs an axis of its own (throttle and brake on one "
                      "pedal axis: `combined`)");
      }
    }
  }
  const bool pedal_device = m.pedal_vendor_id() != 0 || m.pedal_product_id() != 0;
  for (const pb::PedalAxis* p : {&m.throttle(), &m.brake(), &m.clutch(), &m.handbrake()}) {
    if (p->has_axis() && p->on_pedal_device() && !pedal_device) {
      why.push_back(
          "a pedal is on the pedal device, but pedal_vendor_id/pedal_product_id are not set");
      break;
    }
  }
  const auto& b = m.buttons();
  const std::pair<const char*, std::optional<int>> buttons_used[] = {
      {"paddle_left", b.has_paddle_left() ? std::optional<int>(b.paddle_left()) : std::nullopt},
      {"paddle_right", b.has_paddle_right() ? std::optional<int>(b.paddle_right()) : std::nullopt},
      {"cruise_toggle",
       b.has_cruise_toggle() ? std::optional<int>(b.cruise_toggle()) : std::nullopt},
      {"cruise_up", b.has_cruise_up() ? std::optional<int>(b.cruise_up()) : std::nullopt},
      {"cruise_down", b.has_cruise_down() ? std::optional<int>(b.cruise_down()) : std::nullopt},
      {"reset", b.has_reset() ? std::optional<int>(b.reset()) : std::nullopt},
      {"camera", b.has_camera() ? std::optional<int>(b.camera()) : std::nullopt},
      {"estop", b.has_estop() ? std::optional<int>(b.estop()) : std::nullopt},
      {"horn", b.has_horn() ? std::optional<int>(b.horn()) : std::nullopt},
  };
  for (const auto& [name, index] : buttons_used) {
    if (!index) continue;
    CheckWhole(why, std::string("buttons.") + name, limits::kButtonIndex, *index);
    if (buttons >= 0 && *index >= buttons) {
      why.push_back(std::string("buttons.") + name + ": button " + std::to_string(*index) +
                    " but the device has " + std::to_string(buttons) + " buttons");
    }
  }
  if (m.ffb().has_peak_torque_nm()) {
    CheckRange(why, "ffb.peak_torque_nm", limits::kTorqueNm, m.ffb().peak_torque_nm());
  }
  return why;
}

pb::WheelMapping ParseMappingText(const std::string& text, const std::string& source) {
  pb::WheelMapping m;
  std::string errors;
  if (!messages::ParseTextFormat(text, m, &errors)) throw MappingError(source + ": " + errors);
  const auto why = ValidateMapping(m);
  if (!why.empty()) {
    std::string all;
    for (const auto& w : why) all += (all.empty() ? "" : "; ") + w;
    throw MappingError(source + ": " + all);
  }
  return m;
}

pb::WheelMapping ReadMappingFile(const std::filesystem::path& path) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) {
    throw MappingError(path.string() + ": no such mapping file");
  }
  if (std::filesystem::is_directory(path, ec)) {
    throw MappingError(path.string() + ": is a directory, not a mapping file");
  }
  const base::FileText file =
      base::ReadFileBounded(path, limits::kMaxTextFileBytes, "mapping file");
  if (!file.error.empty()) throw MappingError(path.string() + ": " + file.error);
  return ParseMappingText(file.text, path.string());
}

std::string DumpMappingText(const pb::WheelMapping& m) {
  std::string body;
  gp::TextFormat::Printer printer;
  printer.PrintToString(m, &body);
  return "# vdyn-input wheel mapping (vdyn.pb.WheelMapping, protobuf text format; "
         "docs/formats.md).\n# Raw values are SDL's: axes in [-32768, 32767], buttons from 0.\n" +
         body;
}

void WriteMappingFile(const std::filesystem::path& path, const pb::WheelMapping& m) {
  std::error_code ec;
  if (path.has_parent_path()) std::filesystem::create_directories(path.parent_path(), ec);
  if (ec) throw MappingError(path.parent_path().string() + ": cannot create: " + ec.message());
  const std::filesystem::path tmp = path.string() + ".tmp";
  {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    out << DumpMappingText(m);
    out.flush();
    if (!out) throw MappingError(tmp.string() + ": cannot be written");
  }
  std::filesystem::rename(tmp, path, ec);
  if (ec) throw MappingError(path.string() + ": cannot be written: " + ec.message());
}

std::filesystem::path DefaultMappingPath(std::uint16_t vendor_id, std::uint16_t product_id) {
  std::filesystem::path dir;
  if (const char* v = std::getenv("VDYN_CONFIG_DIR"); v && *v) {
    dir = v;
  } else if (const char* x = std::getenv("XDG_CONFIG_HOME"); x && *x) {
    dir = std::filesystem::path(x) / "vdyn";
  } else if (const char* h = std::getenv("HOME"); h && *h) {
    dir = std::filesystem::path(h) / ".config" / "vdyn";
  } else {
    dir = ".vdyn";
  }
  char name[32];
  std::snprintf(name, sizeof name, "%04x_%04x.txt", vendor_id, product_id);
  return dir / "wheels" / name;
}

}  // namespace vdyn::wheel_input
