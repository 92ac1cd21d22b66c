#include "vdyn/io/tire_file.h"

#include <array>
#include <cctype>
#include <cmath>
#include <fstream>
#include <map>
#include <optional>
#include <span>
#include <sstream>

#include <google/protobuf/descriptor.h>

#include "vdyn/base/file.h"
#include "vdyn/base/text.h"

namespace vdyn {
namespace {

namespace gp = google::protobuf;

// The dimension of a quantity as powers of length, force, angle, time, and whether it is a
// pressure (which [UNITS] may name on its own).
struct Dimension {
  int length = 0, force = 0, angle = 0, time = 0;
  bool pressure = false;
};

// The coefficients of MagicFormulaTire that carry a dimension; every other one is a number
// (TNO's coefficients are dimensionless with angles in radians, whatever [UNITS] says).
const std::map<std::string, Dimension, std::less<>>& Dimensions() {
  static const std::map<std::string, Dimension, std::less<>> table = {
      {"longvl", {1, 0, 0, -1}},
      {"vxlow", {1, 0, 0, -1}},
      {"unloaded_radius", {1, 0, 0, 0}},
      {"inflpres", {0, 0, 0, 0, true}},
      {"nompres", {0, 0, 0, 0, true}},
      {"presmin", {0, 0, 0, 0, true}},
      {"presmax", {0, 0, 0, 0, true}},
      {"fnomin", {0, 1, 0, 0}},
      {"fzmax", {0, 1, 0, 0}},
      {"vertical_stiffness", {-1, 1, 0, 0}},
      {"longitudinal_stiffness", {-1, 1, 0, 0}},
      {"lateral_stiffness", {-1, 1, 0, 0}},
      {"alpmin", {0, 0, 1, 0}},
      {"alpmax", {0, 0, 1, 0}},
      {"cammin", {0, 0, 1, 0}},
      {"cammax", {0, 0, 1, 0}},
  };
  return table;
}

struct Unit {
  std::string_view name;
  double to_si;
};
// [UNITS] keys and the units vdyn converts (names in any case).
constexpr Unit kLengthUnits[] = {{"meter", 1.0},   {"meters", 1.0},      {"metre", 1.0},
                                 {"m", 1.0},       {"millimeter", 1e-3}, {"millimeters", 1e-3},
                                 {"mm", 1e-3},     {"centimeter", 1e-2}, {"cm", 1e-2},
                                 {"inch", 0.0254}, {"in", 0.0254}};
constexpr Unit kForceUnits[] = {{"newton", 1.0},
                                {"n", 1.0},
                                {"kilonewton", 1e3},
                                {"kn", 1e3},
                                {"pound_force", 4.4482216152605},
                                {"lbf", 4.4482216152605}};
constexpr Unit kAngleUnits[] = {{"radians", 1.0},
                                {"radian", 1.0},
                                {"rad", 1.0},
                                {"degrees", 3.14159265358979323846 / 180.0},
                                {"degree", 3.14159265358979323846 / 180.0},
                                {"deg", 3.14159265358979323846 / 180.0}};
constexpr Unit kMassUnits[] = {{"kg", 1.0}, {"kilogram", 1.0}, {"gram", 1e-3}, {"g", 1e-3}};
constexpr Unit kTimeUnits[] = {{"second", 1.0}, {"seconds", 1.0},      {"sec", 1.0},
                               {"s", 1.0},      {"millisecond", 1e-3}, {"ms", 1e-3}};
constexpr Unit kPressureUnits[] = {{"pascal", 1.0}, {"pa", 1.0},  {"kilopascal", 1e3},
                                   {"kpa", 1e3},    {"bar", 1e5}, {"psi", 6894.757293168}};

std::string Upper(std::string_view s) {
  std::string out(s);
  for (char& c : out) c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
  return out;
}
std::string Lower(std::string_view s) {
  std::string out(s);
  for (char& c : out) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return out;
}
std::string_view TrimSpace(std::string_view s) {
  while (!s.empty() && std::isspace(static_cast<unsigned char>(s.front()))) s.remove_prefix(1);
  while (!s.empty() && std::isspace(static_cast<unsigned char>(s.back()))) s.remove_suffix(1);
  return s;
}

// 'text', made safe for a message.
std::string Quoted(std::string_view text) {
  std::string s = "'";
  s += base::Quote(text);
  s += "'";
  return s;
}

// A number as Fortran writes it too: 1.5D-3 is 1.5E-3.
std::optional<double> ParseFortranNumber(std::string_view text) {
  std::string s(text);
  for (char& c : s) {
    if (c == 'd' || c == 'D') c = 'E';
  }
  if (s.find_first_of("xXnN") != std::string::npos) return std::nullopt;  // no hex, inf, nan
  return base::ParseNumber(s);
}

// The parse of one file: every error names the file and the line.
class TirParser {
 public:
  explicit TirParser(const std::string& source) : source_(source) {}

  pb::MagicFormulaTire Parse(std::string_view text) {
    text = base::StripBom(text);
    std::size_t start = 0;
    while (start <= text.size()) {
      std::size_t end = text.find('\n', start);
      if (end == std::string_view::npos) end = text.size();
      ++line_;
      Line(text.substr(start, end - start));
      start = end + 1;
    }
    return Finish();
  }

 private:
  [[noreturn]] void Fail(const std::string& why) const {
    throw TireFileError(source_ + ":" + std::to_string(line_) + ": " + why);
  }
  [[noreturn]] void FailKey(const std::string& key, const std::string& why) const {
    Fail(key + ": " + why);
  }

  // The line without its comment: `$` outside quotes to the end, or a line starting with `!`.
  static std::string_view Uncommented(std::string_view raw) {
    std::string_view s = TrimSpace(raw);
    if (!s.empty() && s.front() == '!') return {};
    char quote = 0;
    for (std::size_t i = 0; i < s.size(); ++i) {
      const char c = s[i];
      if (quote != 0) {
        if (c == quote) quote = 0;
      } else if (c == '\'' || c == '"') {
        quote = c;
      } else if (c == '$') {
        return TrimSpace(s.substr(0, i));
      }
    }
    return s;
  }

  void Line(std::string_view raw) {
    const std::string_view s = Uncommented(raw);
    if (s.empty()) return;
    if (s.front() == '[') {
      in_table_ = false;
      if (s.back() != ']') Fail("a section line " + Quoted(s) + " has no closing ]");
      section_ = Upper(TrimSpace(s.substr(1, s.size() - 2)));
      if (section_.empty()) Fail("an empty section name []");
      return;
    }
    if (s.front() == '{') {
      if (s.back() != '}') Fail("a table header " + Quoted(s) + " has no closing }");
      if (section_.empty()) Fail("a table before any [SECTION]");
      in_table_ = true;
      return;
    }
    const std::size_t eq = s.find('=');
    if (eq == std::string_view::npos) {
      if (!in_table_) Fail(Quoted(s) + " is neither [SECTION], KEY = value nor a table");
      TableRow(s);
      return;
    }
    in_table_ = false;
    const std::string key = Upper(TrimSpace(s.substr(0, eq)));
    if (key.empty()) Fail("a line " + Quoted(s) + " with no key before =");
    for (char c : key) {
      if (!std::isalnum(static_cast<unsigned char>(c)) && c != '_') {
        Fail(Quoted(key) + " is not a key (letters, digits and _)");
      }
    }
    if (section_.empty()) FailKey(key, "given before any [SECTION]");
    Value(key, TrimSpace(s.substr(eq + 1)));
  }

  void TableRow(std::string_view s) {
    std::size_t i = 0;
    while (i < s.size()) {
      while (i < s.size() && std::isspace(static_cast<unsigned char>(s[i]))) ++i;
      std::size_t j = i;
      while (j < s.size() && !std::isspace(static_cast<unsigned char>(s[j]))) ++j;
      if (j > i && !ParseFortranNumber(s.substr(i, j - i))) {
        Fail("table row: " + Quoted(s.substr(i, j - i)) + " is not a number");
      }
      i = j;
    }
  }

  void Value(const std::string& key, std::string_view v) {
    if (v.empty()) FailKey(key, "no value after =");
    std::optional<std::string> text;
    std::optional<double> number;
    if (v.front() == '\'' || v.front() == '"') {
      if (v.size() < 2 || v.back() != v.front()) FailKey(key, "a string without its closing quote");
      text = std::string(v.substr(1, v.size() - 2));
    } else {
      number = ParseFortranNumber(v);
      if (!number) FailKey(key, Quoted(v) + " is not a finite number");
    }
    // A unit, the model's version or the tyre's side given twice in its section is refused as a
    // coefficient given twice is (the last one won: LENGTH 'meter' then 'millimeter' made every
    // length millimetres; FITTYP 6 then 61 read a PAC2002 file as MF 6.1).
    if (section_ == "UNITS" || key == "FITTYP" || key == "PROPERTY_FILE_FORMAT" ||
        key == "TYRESIDE") {
      const std::string where = section_ + "/" + key;
      if (const auto it = given_settings_.find(where); it != given_settings_.end()) {
        FailKey(key, "given twice (first at line " + std::to_string(it->second) + ")");
      }
      given_settings_[where] = line_;
    }
    if (section_ == "UNITS") return UnitLine(key, text, number);
    if (key == "FITTYP") {
      if (!number || *number != std::floor(*number)) FailKey(key, "must be a whole number");
      fittyp_ = *number;
      fittyp_line_ = line_;
      return;
    }
    if (key == "PROPERTY_FILE_FORMAT" && text) {
      if (Upper(*text).find("PAC") != std::string::npos) {
        FailKey(key, Quoted(*text) +
                         ": a PAC2002 / MF 5.2 file; vdyn reads MF 6.1 and 6.2 (FITTYP = 61, 62)");
      }
      return;
    }
    if (key == "TYRESIDE") {
      if (!text) FailKey(key, "must be a quoted string ('LEFT', 'RIGHT' or 'SYMMETRIC')");
      const std::string side = Upper(TrimSpace(*text));
      if (side != "LEFT" && side != "RIGHT" && side != "SYMMETRIC") {
        FailKey(key, Quoted(*text) + " is not LEFT, RIGHT or SYMMETRIC");
      }
      out_.set_tyreside(side);
      return;
    }
    const gp::FieldDescriptor* f = pb::MagicFormulaTire::descriptor()->FindFieldByName(Lower(key));
    if (f == nullptr || f->type() != gp::FieldDescriptor::TYPE_DOUBLE) return;  // not read
    if (!number) FailKey(key, "must be a number, not a string");
    if (const auto it = given_.find(key); it != given_.end()) {
      FailKey(key, "given twice (first at line " + std::to_string(it->second) + ")");
    }
    given_[key] = line_;
    out_.GetReflection()->SetDouble(&out_, f, *number);
  }

  void UnitLine(const std::string& key, const std::optional<std::string>& text,
                const std::optional<double>& number) {
    struct Kind {
      std::string_view key;
      std::span<const Unit> units;
      double* factor;
    };
    const Kind kinds[] = {
        {"LENGTH", kLengthUnits, &length_}, {"FORCE", kForceUnits, &force_},
        {"ANGLE", kAngleUnits, &angle_},    {"MASS", kMassUnits, &mass_},
        {"TIME", kTimeUnits, &time_},       {"PRESSURE", kPressureUnits, &pressure_}};
    for (const Kind& k : kinds) {
      if (key != k.key) continue;
      if (!text || number) FailKey(key, "a unit is a quoted name, e.g. 'meter'");
      const std::string name = Lower(TrimSpace(*text));
      for (const Unit& u : k.units) {
        if (u.name == name) {
          *k.factor = u.to_si;
          return;
        }
      }
      std::string known;
      for (const Unit& u : k.units) {
        if (!known.empty()) known += ", ";
        known += u.name;
      }
      FailKey(key, Quoted(*text) + " is not a unit vdyn converts (" + known + ")");
    }
  }

  pb::MagicFormulaTire Finish() {
    line_ = fittyp_line_;
    if (!fittyp_) {
      throw TireFileError(
          source_ + ": no FITTYP in [MODEL]: vdyn reads MF 6.1 and 6.2 files (FITTYP = 61, 62)");
    }
    const double v = *fittyp_;
    if (v == 6 || v == 21) {
      FailKey("FITTYP", base::FormatNumber(v) +
                            " is MF 5.2 / PAC2002; vdyn reads MF 6.1 and 6.2 (FITTYP = 61, 62)");
    }
    if (v != 61 && v != 62) {
      FailKey("FITTYP", base::FormatNumber(v) +
                            " is not a Magic Formula version vdyn reads (61: MF 6.1, 62: MF 6.2)");
    }
    out_.set_fittyp(static_cast<std::uint32_t>(v));
    const double pressure = pressure_ != 0.0 ? pressure_ : force_ / (length_ * length_);
    const gp::Reflection* r = out_.GetReflection();
    for (const auto& [name, d] : Dimensions()) {
      const gp::FieldDescriptor* f = pb::MagicFormulaTire::descriptor()->FindFieldByName(name);
      if (!r->HasField(out_, f)) continue;
      double factor = d.pressure ? pressure : 1.0;
      factor *= std::pow(length_, d.length) * std::pow(force_, d.force) *
                std::pow(angle_, d.angle) * std::pow(time_, d.time);
      const double si = r->GetDouble(out_, f) * factor;
      if (!std::isfinite(si)) {
        const std::string key = Upper(name);
        throw TireFileError(source_ + ":" + std::to_string(given_[key]) + ": " + key +
                            ": not a finite number in SI units");
      }
      r->SetDouble(&out_, f, si);
    }
    return out_;
  }

  const std::string& source_;
  int line_ = 0;
  std::string section_;
  bool in_table_ = false;
  std::optional<double> fittyp_;
  int fittyp_line_ = 0;
  std::map<std::string, int> given_;  // coefficient key -> its line
  std::map<std::string, int> given_settings_;  // "SECTION/KEY" of a unit or setting -> its line
  double length_ = 1.0, force_ = 1.0, angle_ = 1.0, mass_ = 1.0, time_ = 1.0, pressure_ = 0.0;
  pb::MagicFormulaTire out_;
};

}  // namespace

pb::MagicFormulaTire ParseTireFile(std::string_view text, const std::string& source_name) {
  if (text.size() > kMaxTireFileBytes) {
    throw TireFileError(source_name + ": " + std::to_string(text.size()) +
                        " bytes, more than a tyre file may have (" +
                        std::to_string(kMaxTireFileBytes) + ")");
  }
  TirParser parser(source_name);
  pb::MagicFormulaTire tire = parser.Parse(text);
  tire.set_name(std::filesystem::path(source_name).filename().string());
  return tire;
}

pb::MagicFormulaTire ReadTireFile(const std::filesystem::path& path) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) {
    throw TireFileError(path.string() + ": is a directory, not a tyre file");
  }
  if (!std::filesystem::exists(path, ec))
    throw TireFileError(path.string() + ": no such tyre file");
  // Bounded while it reads: a device or a pipe has no size to check beforehand (/dev/zero filled
  // the memory).
  const base::FileText file = base::ReadFileBounded(path, kMaxTireFileBytes, "tyre file");
  if (!file.error.empty()) throw TireFileError(path.string() + ": " + file.error);
  return ParseTireFile(file.text, path.string());
}

void ResolveTireFiles(pb::VehicleParams& update, const std::filesystem::path& folder) {
  std::map<std::string, pb::MagicFormulaTire> read;  // each file read once
  auto tire = [&](const std::string& file) -> const pb::MagicFormulaTire& {
    auto it = read.find(file);
    if (it == read.end()) it = read.emplace(file, ReadTireFile(folder / file)).first;
    return it->second;
  };
  pb::WheelParams* wheels[] = {update.mutable_lf(), update.mutable_rf(), update.mutable_lr(),
                               update.mutable_rr()};
  const bool any =
      update.has_tire_file() || update.has_tire_file_front() || update.has_tire_file_rear();
  for (int w = 0; w < 4; ++w) {
    pb::WheelParams& wp = *wheels[w];
    const bool front = w < 2;
    std::optional<std::string> file;
    if (wp.has_tire_file()) {
      file = wp.tire_file();
    } else if (front && update.has_tire_file_front()) {
      file = update.tire_file_front();
    } else if (!front && update.has_tire_file_rear()) {
      file = update.tire_file_rear();
    } else if (update.has_tire_file()) {
      file = update.tire_file();
    }
    if (file) *wp.mutable_magic_formula() = tire(*file);
    wp.clear_tire_file();
  }
  if (any) {
    update.clear_tire_file();
    update.clear_tire_file_front();
    update.clear_tire_file_rear();
  }
}

}  // namespace vdyn
