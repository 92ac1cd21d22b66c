// The Magic Formula tyre (issue 34): the .tir reader and its refusals, the law against its
// published equations and closed forms, the tyre in parameter files, messages and on the command
// line, and the full model driven on it.
#include <sys/wait.h>

#include <array>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <numbers>
#include <set>
#include <sstream>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "test_support.h"
#include "vdyn/bridge/convert.h"
#include "vdyn/io/maneuver.h"
#include "vdyn/io/tire_file.h"
#include "vdyn/physics/full_model.h"
#include "vdyn/physics/magic_formula.h"
#include "vdyn/replay/resim.h"
#include "vdyn/runtime/session.h"

namespace vdyn {
namespace {

using testing::Drive;
using ::testing::HasSubstr;
using testing::SharedWorld;
using testing::TempDir;
using testing::WriteFile;

std::filesystem::path SyntheticTirePath() {
  return std::filesystem::path(VDYN_SOURCE_DIR) / "tires" / "vdyn_synthetic_205_55R16_mf61.tir";
}

const pb::MagicFormulaTire& SyntheticTire() {
  static const pb::MagicFormulaTire tire = ReadTireFile(SyntheticTirePath());
  return tire;
}

// The synthetic tyre with `edit` applied to its message, checked and derived.
MagicFormula Tire(const std::function<void(pb::MagicFormulaTire&)>& edit = {}) {
  pb::MagicFormulaTire t = SyntheticTire();
  if (edit) edit(t);
  return MagicFormulaFromProto(t);
}

// Every shift of the curves zeroed (horizontal and vertical shifts, the combined-slip shifts, the
// camber-induced force and residual torque): each curve then passes through the origin.
void ZeroShifts(pb::MagicFormulaTire& t) {
  using Setter = void (pb::MagicFormulaTire::*)(double);
  for (Setter set : {&pb::MagicFormulaTire::set_phx1,  &pb::MagicFormulaTire::set_phx2,
                     &pb::MagicFormulaTire::set_pvx1,  &pb::MagicFormulaTire::set_pvx2,
                     &pb::MagicFormulaTire::set_phy1,  &pb::MagicFormulaTire::set_phy2,
                     &pb::MagicFormulaTire::set_pvy1,  &pb::MagicFormulaTire::set_pvy2,
                     &pb::MagicFormulaTire::set_pvy3,  &pb::MagicFormulaTire::set_pvy4,
                     &pb::MagicFormulaTire::set_pky6,  &pb::MagicFormulaTire::set_pky7,
                     &pb::MagicFormulaTire::set_rhx1,  &pb::MagicFormulaTire::set_rhy1,
                     &pb::MagicFormulaTire::set_rhy2,  &pb::MagicFormulaTire::set_rvy1,
                     &pb::MagicFormulaTire::set_rvy2,  &pb::MagicFormulaTire::set_rvy3,
                     &pb::MagicFormulaTire::set_qhz1,  &pb::MagicFormulaTire::set_qhz2,
                     &pb::MagicFormulaTire::set_qhz3,  &pb::MagicFormulaTire::set_qhz4,
                     &pb::MagicFormulaTire::set_qdz6,  &pb::MagicFormulaTire::set_qdz7,
                     &pb::MagicFormulaTire::set_qdz8,  &pb::MagicFormulaTire::set_qdz9,
                     &pb::MagicFormulaTire::set_qdz10, &pb::MagicFormulaTire::set_qdz11,
                     &pb::MagicFormulaTire::set_qsx1,  &pb::MagicFormulaTire::set_qsx2,
                     &pb::MagicFormulaTire::set_ssz1,  &pb::MagicFormulaTire::set_ssz2,
                     &pb::MagicFormulaTire::set_rby3}) {
    (t.*set)(0.0);
  }
}
// ... and the terms that make a curve depend on the slip's sign (curvature, trail curvature).
void ZeroAsymmetry(pb::MagicFormulaTire& t) {
  ZeroShifts(t);
  t.set_pex4(0.0);
  t.set_pey3(0.0);
  t.set_pey4(0.0);
  t.set_qez4(0.0);
  t.set_qez5(0.0);
}

// The law at a point, rolling at LONGVL.
MfOutput At(const MagicFormula& m, double Fz, double kappa, double alpha, double gamma = 0.0,
            double pressure = 0.0) {
  MfInput in;
  in.Fz = Fz;
  in.kappa = kappa;
  in.tan_alpha = std::tan(alpha);
  in.gamma = gamma;
  in.Vx = m.longvl;
  in.Vc = m.longvl / std::cos(alpha);
  in.pressure = pressure > 0.0 ? pressure : m.nompres;
  return EvaluateMagicFormula(m, in);
}

constexpr std::array<double, 3> kLoads = {1500.0, 4500.0, 8000.0};
constexpr std::array<double, 3> kPressures = {180e3, 230e3, 290e3};

// The closed forms of the slip stiffnesses (Pacejka 2012, 4.E15 and 4.E25 at zero camber).
double ClosedKxk(const MagicFormula& m, double Fz, double p) {
  const double Fz0 = m.fnomin * m.lfzo, dfz = (Fz - Fz0) / Fz0, dpi = (p - m.nompres) / m.nompres;
  return Fz * (m.pkx1 + m.pkx2 * dfz) * std::exp(m.pkx3 * dfz) *
         (1.0 + m.ppx1 * dpi + m.ppx2 * dpi * dpi) * m.lkx;
}
double ClosedKya(const MagicFormula& m, double Fz, double p) {
  const double Fz0 = m.fnomin * m.lfzo, dpi = (p - m.nompres) / m.nompres;
  return m.pky1 * Fz0 * (1.0 + m.ppy1 * dpi) *
         std::sin(m.pky4 * std::atan(Fz / (Fz0 * m.pky2 * (1.0 + m.ppy2 * dpi)))) * m.lky;
}
// The peak friction coefficients (4.E13, 4.E23 at zero camber).
double ClosedMux(const MagicFormula& m, double Fz, double p) {
  const double Fz0 = m.fnomin * m.lfzo, dfz = (Fz - Fz0) / Fz0, dpi = (p - m.nompres) / m.nompres;
  return (m.pdx1 + m.pdx2 * dfz) * (1.0 + m.ppx3 * dpi + m.ppx4 * dpi * dpi) * m.lmux;
}
double ClosedMuy(const MagicFormula& m, double Fz, double p) {
  const double Fz0 = m.fnomin * m.lfzo, dfz = (Fz - Fz0) / Fz0, dpi = (p - m.nompres) / m.nompres;
  return (m.pdy1 + m.pdy2 * dfz) * (1.0 + m.ppy3 * dpi + m.ppy4 * dpi * dpi) * m.lmuy;
}

// The largest |F| along a slip from 0 to `hi`: a grid, then golden-section refinement.
double PeakOf(const std::function<double(double)>& f, double hi) {
  double best_x = 0.0, best = -1.0;
  for (int i = 1; i <= 2000; ++i) {
    const double x = hi * i / 2000.0;
    if (std::abs(f(x)) > best) {
      best = std::abs(f(x));
      best_x = x;
    }
  }
  double a = best_x - hi / 2000.0, b = best_x + hi / 2000.0;
  const double g = 0.5 * (std::sqrt(5.0) - 1.0);
  for (int i = 0; i < 80; ++i) {
    const double c = b - g * (b - a), d = a + g * (b - a);
    (std::abs(f(c)) > std::abs(f(d)) ? b : a) = std::abs(f(c)) > std::abs(f(d)) ? d : c;
  }
  return std::abs(f(0.5 * (a + b)));
}

// === the reader
// ===================================================================================

TEST(TireFile, ReadsTheSyntheticFile) {
  const pb::MagicFormulaTire& t = SyntheticTire();
  EXPECT_EQ(t.name(), "vdyn_synthetic_205_55R16_mf61.tir");
  EXPECT_EQ(t.fittyp(), 61u);
  EXPECT_EQ(t.tyreside(), "LEFT");
  EXPECT_EQ(t.fnomin(), 4500.0);
  EXPECT_EQ(t.unloaded_radius(), 0.316);
  EXPECT_EQ(t.pky1(), -18.0);
  EXPECT_EQ(t.ssz4(), -0.2);
  EXPECT_EQ(t.lmuv(), 0.0);
  EXPECT_FALSE(t.has_qsx4());  // not in the file: absent, its fallback (0) applies
  // Every coefficient the equations need is there.
  for (const MagicFormulaField& f : MagicFormulaFields()) {
    if (!std::isnan(f.fallback)) continue;
    const auto* d = pb::MagicFormulaTire::descriptor()->FindFieldByName(std::string(f.name));
    ASSERT_NE(d, nullptr) << f.name;
    EXPECT_TRUE(t.GetReflection()->HasField(t, d)) << f.name;
  }
}

// One list of coefficients: the physics' table and the message name the same ones, in order.
TEST(TireFile, ThePhysicsTableAndTheMessageListTheSameCoefficients) {
  const auto* d = pb::MagicFormulaTire::descriptor();
  std::vector<std::string> message;
  for (int i = 0; i < d->field_count(); ++i) {
    if (d->field(i)->type() == google::protobuf::FieldDescriptor::TYPE_DOUBLE) {
      message.push_back(d->field(i)->name());
    }
  }
  std::vector<std::string> table;
  for (const MagicFormulaField& f : MagicFormulaFields()) table.emplace_back(f.name);
  EXPECT_EQ(table, message);
}

constexpr const char* kMinimal = R"([MODEL]
FITTYP = 61
)";

TEST(TireFile, FortranNumbersCommentsKeysInAnyCaseAndTables) {
  const pb::MagicFormulaTire t = ParseTireFile(std::string(R"([MDI_HEADER]
FILE_TYPE = 'tir'      $ a string, and a comment
! a comment line
[UNITS]
MASS = 'kg'
[model]
fittyp = 62
TyreSide = 'right'
[LATERAL_COEFFICIENTS]
pdy1 = .105E+01
Pcx1=1.6D0
PKY1 = -1.8d+1 $ Fortran's D exponent
PEY1 = -5.
[INERTIA]
MASS = 9.5
[SHAPE]
{radial width}
 1.0    0.0
 1.0    0.4
[STRUCTURAL]
LATERAL_STIFFNESS = 140000
)"),
                                               "dir/t.tir");
  EXPECT_EQ(t.name(), "t.tir");
  EXPECT_EQ(t.fittyp(), 62u);
  EXPECT_EQ(t.tyreside(), "RIGHT");
  EXPECT_EQ(t.pdy1(), 1.05);
  EXPECT_EQ(t.pcx1(), 1.6);
  EXPECT_EQ(t.pky1(), -18.0);
  EXPECT_EQ(t.pey1(), -5.0);
  EXPECT_EQ(t.lateral_stiffness(), 140000.0);
}

TEST(TireFile, UnitsAreConvertedToSi) {
  const pb::MagicFormulaTire t = ParseTireFile(std::string(R"([UNITS]
LENGTH = 'mm'
FORCE = 'kN'
ANGLE = 'degree'
TIME = 'second'
[MODEL]
FITTYP = 61
LONGVL = 16700
[DIMENSION]
UNLOADED_RADIUS = 316
[VERTICAL]
FNOMIN = 4.5
VERTICAL_STIFFNESS = 0.23
[OPERATING_CONDITIONS]
INFLPRES = 0.00023
[SLIP_ANGLE_RANGE]
ALPMAX = 45
[LATERAL_COEFFICIENTS]
PKY1 = -18
)"),
                                               "units.tir");
  EXPECT_DOUBLE_EQ(t.longvl(), 16.7);                  // mm/s
  EXPECT_DOUBLE_EQ(t.unloaded_radius(), 0.316);        // mm
  EXPECT_DOUBLE_EQ(t.fnomin(), 4500.0);                // kN
  EXPECT_DOUBLE_EQ(t.vertical_stiffness(), 230000.0);  // kN/mm
  EXPECT_DOUBLE_EQ(t.inflpres(), 230000.0);            // kN/mm^2
  EXPECT_DOUBLE_EQ(t.alpmax(), std::numbers::pi / 4.0);
  EXPECT_EQ(t.pky1(), -18.0);  // dimensionless: as written
  const pb::MagicFormulaTire bar =
      ParseTireFile(std::string("[UNITS]\nPRESSURE = 'bar'\n") + kMinimal +
                        "[OPERATING_CONDITIONS]\nNOMPRES = 2.3\n",
                    "bar.tir");
  EXPECT_DOUBLE_EQ(bar.nompres(), 230000.0);
}

struct BadTir {
  const char* text;
  const char* says;
};

// Every bad file is refused with the file, the line, the key and the reason.
TEST(TireFile, EveryBadFileIsRefusedWithFileLineKeyAndReason) {
  const BadTir bad[] = {
      {"[UNITS]\nLENGTH = 'furlong'\n[MODEL]\nFITTYP = 61\n",
       "bad.tir:2: LENGTH: 'furlong' is not a unit vdyn converts (meter"},
      {"[UNITS]\nFORCE = 1\n", "bad.tir:2: FORCE: a unit is a quoted name"},
      {"[MODEL]\nFITTYP = 6\n",
       "bad.tir:2: FITTYP: 6 is MF 5.2 / PAC2002; vdyn reads MF 6.1 and 6.2"},
      {"[MODEL]\nFITTYP = 21\n", "FITTYP: 21 is MF 5.2 / PAC2002"},
      {"[MODEL]\nFITTYP = 52\n", "bad.tir:2: FITTYP: 52 is not a Magic Formula version vdyn reads"},
      {"[MODEL]\nFITTYP = 61.5\n", "bad.tir:2: FITTYP: must be a whole number"},
      {"[MODEL]\nPROPERTY_FILE_FORMAT = 'PAC2002'\nFITTYP = 61\n",
       "bad.tir:2: PROPERTY_FILE_FORMAT: 'PAC2002': a PAC2002 / MF 5.2 file"},
      {"[MODEL]\nLONGVL = 16.7\n", "bad.tir: no FITTYP in [MODEL]"},
      {"[MODEL]\nFITTYP = 61\nPDY1 = 1.0.5\n", "bad.tir:3: PDY1: '1.0.5' is not a finite number"},
      {"[MODEL]\nFITTYP = 61\nPDY1 = 1e999\n", "bad.tir:3: PDY1: '1e999' is not a finite number"},
      {"[MODEL]\nFITTYP = 61\nPDY1 = nan\n", "bad.tir:3: PDY1: 'nan' is not a finite number"},
      {"[MODEL]\nFITTYP = 61\nPDY1 = 'one'\n", "bad.tir:3: PDY1: must be a number, not a string"},
      {"[MODEL]\nFITTYP = 61\nTYRESIDE = 'LEFT\n",
       "bad.tir:3: TYRESIDE: a string without its closing quote"},
      {"[MODEL]\nFITTYP = 61\nTYRESIDE = 'UP'\n",
       "bad.tir:3: TYRESIDE: 'UP' is not LEFT, RIGHT or SYMMETRIC"},
      {"[MODEL]\nFITTYP = 61\nPDY1 = 1\n[LATERAL]\npdy1 = 2\n",
       "bad.tir:5: PDY1: given twice (first at line 3)"},
      // Settings given twice (the last won: every length in millimetres; PAC2002 read as MF 6.1).
      {"[UNITS]\nLENGTH = 'meter'\nLENGTH = 'millimeter'\n[MODEL]\nFITTYP = 61\n",
       "bad.tir:3: LENGTH: given twice (first at line 2)"},
      {"[MODEL]\nFITTYP = 6\nFITTYP = 61\n", "bad.tir:3: FITTYP: given twice (first at line 2)"},
      {"[MODEL]\nFITTYP = 61\nTYRESIDE = 'LEFT'\nTYRESIDE = 'RIGHT'\n",
       "bad.tir:4: TYRESIDE: given twice (first at line 3)"},
      {"[MODEL\nFITTYP = 61\n", "bad.tir:1: a section line '[MODEL' has no closing ]"},
      {"[]\n", "bad.tir:1: an empty section name"},
      {"FITTYP = 61\n", "bad.tir:1: FITTYP: given before any [SECTION]"},
      {"[MODEL]\nFITTYP = 61\nthis is not a line\n",
       "bad.tir:3: 'this is not a line' is neither [SECTION], KEY = value nor a table"},
      {"[MODEL]\nFITTYP = 61\n= 5\n", "bad.tir:3: a line '= 5' with no key before ="},
      {"[MODEL]\nFITTYP = 61\nP-DY1 = 5\n", "bad.tir:3: 'P-DY1' is not a key"},
      {"[MODEL]\nFITTYP = 61\nPDY1 =\n", "bad.tir:3: PDY1: no value after ="},
      {"[SHAPE]\n{radial width\n", "bad.tir:2: a table header '{radial width' has no closing }"},
      {"[SHAPE]\n{radial width}\n1.0 x\n", "bad.tir:3: table row: 'x' is not a number"},
      {"{radial width}\n", "bad.tir:1: a table before any [SECTION]"},
      {"[UNITS]\nLENGTH = 'km'\n[MODEL]\nFITTYP = 61\n[DIMENSION]\nUNLOADED_RADIUS = 1e306\n",
       "LENGTH: 'km' is not a unit"},
      {"[UNITS]\nFORCE = 'kN'\n[MODEL]\nFITTYP = 61\n[VERTICAL]\nFNOMIN = 1e306\n",
       "bad.tir:6: FNOMIN: not a finite number in SI units"},
  };
  for (const BadTir& b : bad) {
    try {
      ParseTireFile(b.text, "bad.tir");
      ADD_FAILURE() << "accepted: " << b.text;
    } catch (const TireFileError& e) {
      EXPECT_THAT(e.what(), HasSubstr(b.says)) << b.text;
    }
  }
  EXPECT_THROW(ParseTireFile(std::string(kMaxTireFileBytes + 1, ' '), "big.tir"), TireFileError);
  TempDir dir;
  try {
    ReadTireFile(dir / "none.tir");
    ADD_FAILURE();
  } catch (const TireFileError& e) {
    EXPECT_THAT(e.what(), HasSubstr("none.tir: no such tyre file"));
  }
  try {
    ReadTireFile(dir.path());
    ADD_FAILURE();
  } catch (const TireFileError& e) {
    EXPECT_THAT(e.what(), HasSubstr("is a directory, not a tyre file"));
  }
  // A file that never ends (a device: its size is 0 to stat) is refused at the bound while it is
  // read; it was read whole and filled the memory (24 GB, killed by the kernel).
  try {
    ReadTireFile("/dev/zero");
    ADD_FAILURE();
  } catch (const TireFileError& e) {
    EXPECT_THAT(e.what(), HasSubstr("/dev/zero: more than 4194304 bytes, more than a tyre file may "
                                    "have"));
  }
}

// A file that parses but lacks a coefficient the equations need is refused with the coefficient
// named, the tyre file's name with it; so is one whose values cannot make a tyre.
TEST(TireFile, AMissingOrUnusableCoefficientIsNamed) {
  pb::MagicFormulaTire t = SyntheticTire();
  t.clear_pdy1();
  pb::VehicleParams car = DefaultVehicleParams();
  *car.mutable_rr()->mutable_magic_formula() = t;
  const auto issues = ValidateVehicleParams(car);
  ASSERT_EQ(issues.size(), 1u) << FormatIssues(issues);
  EXPECT_EQ(issues[0].field, "rr.magic_formula.pdy1");
  EXPECT_THAT(issues[0].reason,
              HasSubstr("missing from the tyre file 'vdyn_synthetic_205_55R16_mf61.tir' (PDY1)"));
  struct Bad {
    std::function<void(pb::MagicFormulaTire&)> edit;
    const char* field;
    const char* says;
  };
  const Bad bad[] = {
      {[](auto& m) { m.set_pcx1(0.9); }, "magic_formula.pcx1", "must exceed 1"},
      {[](auto& m) { m.set_pky1(18.0); }, "magic_formula.pky1", "must be negative"},
      {[](auto& m) { m.set_pkx1(-24.0); }, "magic_formula.pkx1", "must be positive"},
      {[](auto& m) { m.set_fnomin(0.0); }, "magic_formula.fnomin", "must be in (0, 1e6] N"},
      {[](auto& m) { m.set_fnomin(1e300); }, "magic_formula.fnomin", "must be in (0, 1e6] N"},
      // Taken, and side forces of 4e301 N written to a batch's CSV with exit 0.
      {[](auto& m) { m.set_pdy1(1e300); }, "magic_formula.pdy1",
       "the friction PDY1 * LMUY is 1e300: more than 10 times the load"},
      {[](auto& m) { m.set_lmux(20.0); }, "magic_formula.pdx1",
       "the friction PDX1 * LMUX is 24: more than 10 times the load"},
      {[](auto& m) { m.set_pky1(-1e6); }, "magic_formula.pky1",
       "times the load: more than 1000 times is no tyre's"},
      {[](auto& m) { m.set_pkx1(1e5); }, "magic_formula.pkx1",
       "times the load: more than 1000 times is no tyre's"},
      // Every load taken as FZMAX (the curves labelled 4500 N were 100 N's).
      {[](auto& m) { m.set_fzmax(100.0); }, "magic_formula.fzmax",
       "FZMAX (100 N) is below the nominal load FNOMIN * LFZO (4500 N)"},
      // Metre values under LENGTH = 'millimeter': a 0.3 mm wheel crawled at 0.37 km/h.
      {[](auto& m) { m.set_unloaded_radius(0.000316); }, "magic_formula.unloaded_radius",
       "is not a tyre's radius (0.05 to 3 m): does [UNITS] LENGTH match"},
      {[](auto& m) { m.set_alpmax(2.0); }, "magic_formula.alpmin", "ALPMAX < pi/2"},
      {[](auto& m) { m.set_fittyp(52); }, "magic_formula.fittyp", "not a model vdyn evaluates"},
      {[](auto& m) { m.set_tyreside("UP"); }, "magic_formula.tyreside", "LEFT, RIGHT or SYMMETRIC"},
  };
  for (const Bad& b : bad) {
    pb::MagicFormulaTire m = SyntheticTire();
    b.edit(m);
    try {
      MagicFormulaFromProto(m);
      ADD_FAILURE() << b.field;
    } catch (const ParamsError& e) {
      EXPECT_THAT(e.what(), HasSubstr(b.field)) << e.what();
      EXPECT_THAT(e.what(), HasSubstr(b.says)) << e.what();
    }
  }
}

// === the law against its equations
// =================================================================

TEST(MagicFormula, NoForceAtZeroSlipWithTheShiftsZeroed) {
  const MagicFormula m = Tire(ZeroShifts);
  for (double Fz : kLoads) {
    for (double p : kPressures) {
      const MfOutput o = At(m, Fz, 0.0, 0.0, 0.0, p);
      EXPECT_LT(std::abs(o.Fx), 1e-9 * Fz) << Fz << " " << p;
      EXPECT_LT(std::abs(o.Fy), 1e-9 * Fz) << Fz << " " << p;
      EXPECT_LT(std::abs(o.Mz), 1e-9 * Fz) << Fz << " " << p;
    }
  }
  // The file's own shifts do push at zero slip (the test above is not empty).
  EXPECT_GT(std::abs(At(Tire(), 4500.0, 0.0, 0.0).Fx), 10.0);
}

TEST(MagicFormula, EveryCurveIsOddWithoutShiftsAndAsymmetry) {
  const MagicFormula m = Tire(ZeroAsymmetry);
  for (double Fz : kLoads) {
    for (double s : {0.01, 0.05, 0.1, 0.3}) {
      EXPECT_NEAR(At(m, Fz, s, 0.0).Fx, -At(m, Fz, -s, 0.0).Fx, 1e-9 * Fz);
      EXPECT_NEAR(At(m, Fz, 0.0, s).Fy, -At(m, Fz, 0.0, -s).Fy, 1e-9 * Fz);
      EXPECT_NEAR(At(m, Fz, 0.0, s).Mz, -At(m, Fz, 0.0, -s).Mz, 1e-9 * Fz);
      EXPECT_NEAR(At(m, Fz, s, 0.05).Fy, -At(m, Fz, s, -0.05).Fy, 1e-9 * Fz);  // combined
    }
  }
}

TEST(MagicFormula, TheSlopeAtTheOriginIsTheClosedFormSlipStiffness) {
  const MagicFormula m = Tire(ZeroShifts);
  constexpr double d = 1e-6;
  for (double Fz : kLoads) {
    for (double p : kPressures) {
      const double Kx = (At(m, Fz, d, 0.0, 0.0, p).Fx - At(m, Fz, -d, 0.0, 0.0, p).Fx) / (2 * d);
      const double Ky = (At(m, Fz, 0.0, d, 0.0, p).Fy - At(m, Fz, 0.0, -d, 0.0, p).Fy) / (2 * d);
      EXPECT_NEAR(Kx / ClosedKxk(m, Fz, p), 1.0, 1e-6) << Fz << " " << p;
      EXPECT_NEAR(Ky / ClosedKya(m, Fz, p), 1.0, 1e-6) << Fz << " " << p;
    }
  }
  // At the nominal load: the README's -73 kN/rad.
  EXPECT_NEAR(ClosedKya(m, 4500.0, 230e3), -72809.0, 1.0);
}

TEST(MagicFormula, ThePeakIsMuTimesTheLoad) {
  const MagicFormula m = Tire(ZeroShifts);
  for (double Fz : kLoads) {
    for (double p : kPressures) {
      const double fx = PeakOf([&](double k) { return At(m, Fz, k, 0.0, 0.0, p).Fx; }, 1.0);
      const double fy = PeakOf([&](double a) { return At(m, Fz, 0.0, a, 0.0, p).Fy; }, 0.8);
      EXPECT_NEAR(fx / (ClosedMux(m, Fz, p) * Fz), 1.0, 1e-9) << Fz << " " << p;
      EXPECT_NEAR(fy / (ClosedMuy(m, Fz, p) * Fz), 1.0, 1e-9) << Fz << " " << p;
    }
  }
}

TEST(MagicFormula, TheScalingFactorsScaleWhatTheyName) {
  const double Fz = 5000.0, d = 1e-6;
  const MagicFormula base = Tire(ZeroShifts);
  auto scaled = [](auto set, double v) {
    return Tire([&](pb::MagicFormulaTire& t) {
      ZeroShifts(t);
      (t.*set)(v);
    });
  };
  auto peak_x = [&](const MagicFormula& m) {
    return PeakOf([&](double k) { return At(m, Fz, k, 0.0).Fx; }, 1.0);
  };
  auto peak_y = [&](const MagicFormula& m) {
    return PeakOf([&](double a) { return At(m, Fz, 0.0, a).Fy; }, 0.8);
  };
  auto kx = [&](const MagicFormula& m) {
    return (At(m, Fz, d, 0.0).Fx - At(m, Fz, -d, 0.0).Fx) / (2 * d);
  };
  auto ky = [&](const MagicFormula& m) {
    return (At(m, Fz, 0.0, d).Fy - At(m, Fz, 0.0, -d).Fy) / (2 * d);
  };
  EXPECT_NEAR(peak_x(scaled(&pb::MagicFormulaTire::set_lmux, 0.8)) / peak_x(base), 0.8, 1e-9);
  EXPECT_NEAR(peak_y(scaled(&pb::MagicFormulaTire::set_lmuy, 0.7)) / peak_y(base), 0.7, 1e-9);
  EXPECT_NEAR(kx(scaled(&pb::MagicFormulaTire::set_lkx, 1.3)) / kx(base), 1.3, 1e-6);
  EXPECT_NEAR(ky(scaled(&pb::MagicFormulaTire::set_lky, 0.9)) / ky(base), 0.9, 1e-6);
  const MagicFormula file = Tire();
  auto with = [](auto set, double v) {
    return Tire([&](pb::MagicFormulaTire& t) { (t.*set)(v); });
  };
  EXPECT_NEAR(
      At(with(&pb::MagicFormulaTire::set_ltr, 1.5), Fz, 0.0, 0.03).t / At(file, Fz, 0.0, 0.03).t,
      1.5, 1e-12);
  EXPECT_NEAR(At(with(&pb::MagicFormulaTire::set_lres, 2.0), Fz, 0.0, 0.03).Mzr /
                  At(file, Fz, 0.0, 0.03).Mzr,
              2.0, 1e-12);
  EXPECT_NEAR(
      At(with(&pb::MagicFormulaTire::set_lmy, 1.4), Fz, 0.05, 0.0).My / At(file, Fz, 0.05, 0.0).My,
      1.4, 1e-12);
  EXPECT_NEAR(
      At(with(&pb::MagicFormulaTire::set_lmx, 0.6), Fz, 0.0, 0.05).Mx / At(file, Fz, 0.0, 0.05).Mx,
      0.6, 1e-12);
  // LFZO scales the nominal load: at LFZO * FNOMIN the friction is the file's at FNOMIN.
  const MagicFormula lfzo = with(&pb::MagicFormulaTire::set_lfzo, 1.2);
  EXPECT_NEAR(At(lfzo, 1.2 * 4500.0, 0.0, 0.0).mux, At(file, 4500.0, 0.0, 0.0).mux, 1e-12);
  // LVYKA scales the kappa-induced side force SVyk: Fy(LVYKA) - Fy(0) is LVYKA times
  // Fy(1) - Fy(0).
  auto fy_k = [&](double lvyka) {
    return At(with(&pb::MagicFormulaTire::set_lvyka, lvyka), Fz, 0.1, 0.02).Fy;
  };
  EXPECT_NEAR(fy_k(3.0) - fy_k(0.0), 3.0 * (fy_k(1.0) - fy_k(0.0)), 1e-9 * Fz);
  EXPECT_GT(std::abs(fy_k(1.0) - fy_k(0.0)), 10.0);
}

// Combined slip (4.E50-4.E67) weighs each pure-slip force by G <= 1: a slip in the other direction
// only takes force away (the kappa-induced side force S_Vyk zeroed with the shifts). The resultant
// is not bounded by the friction ellipse by the equations themselves: with the synthetic file's
// combined-slip coefficients (Fx/Dx)^2 + (Fy/Dy)^2 reaches 1.055^2 at a third of FNOMIN near both
// peaks (docs/model.md, 8.2b); what the equations guarantee is tested here.
TEST(MagicFormula, CombinedSlipNeverExceedsThePureSlipForces) {
  const MagicFormula m = Tire(ZeroShifts);
  for (double Fz : kLoads) {
    int reduced = 0;
    for (int i = -40; i <= 40; ++i) {
      const double kappa = i / 40.0;
      const double fx0 = std::abs(At(m, Fz, kappa, 0.0).Fx);
      for (int j = -40; j <= 40; ++j) {
        const double alpha = 0.5 * j / 40.0;
        const MfOutput o = At(m, Fz, kappa, alpha);
        const double fy0 = std::abs(At(m, Fz, 0.0, alpha).Fy);
        EXPECT_LE(std::abs(o.Fx), fx0 * (1.0 + 1e-12) + 1e-9) << Fz << " " << kappa << " " << alpha;
        EXPECT_LE(std::abs(o.Fy), fy0 * (1.0 + 1e-12) + 1e-9) << Fz << " " << kappa << " " << alpha;
        reduced += std::abs(o.Fx) < 0.9 * fx0 && std::abs(o.Fy) < 0.9 * fy0;
      }
    }
    EXPECT_GT(reduced, 1000) << Fz;  // and both are reduced where both slips are large
  }
}

// ISO-W: a positive inclination leans the top of the wheel to the right (-y); the camber thrust
// pushes where the top leans, with the slope Kyg0 = Fz (PKY6 + PKY7 dfz) LKYC at zero slip (4.E30).
TEST(MagicFormula, CamberThrustPointsWhereTheTopLeans) {
  const MagicFormula m = Tire([](pb::MagicFormulaTire& t) {
    const double pky6 = t.pky6(), pky7 = t.pky7(), pvy3 = t.pvy3(), pvy4 = t.pvy4();
    ZeroShifts(t);
    t.set_pky6(pky6);
    t.set_pky7(pky7);
    t.set_pvy3(pvy3);
    t.set_pvy4(pvy4);
  });
  for (double Fz : kLoads) {
    EXPECT_LT(At(m, Fz, 0.0, 0.0, 0.05).Fy, 0.0);
    EXPECT_GT(At(m, Fz, 0.0, 0.0, -0.05).Fy, 0.0);
    constexpr double d = 1e-6;
    const double slope = (At(m, Fz, 0.0, 0.0, d).Fy - At(m, Fz, 0.0, 0.0, -d).Fy) / (2 * d);
    const double dfz = (Fz - m.fnomin) / m.fnomin;
    EXPECT_NEAR(slope / (Fz * (m.pky6 + m.pky7 * dfz) * m.lkyc), 1.0, 1e-6) << Fz;
  }
}

// Three points of the synthetic file worked out term by term from the equations in
// docs/model.md (8.2b, "Hand-checked points"), at FNOMIN, NOMPRES, no camber, LONGVL.
TEST(MagicFormula, HandCheckedPointsOfTheSyntheticFile) {
  const MagicFormula m = Tire();
  const MfOutput lateral = At(m, 4500.0, 0.0, 0.05);
  // To 1e-9 relative: the hand's numbers leave out Pacejka's epsilon (1e-6 in B's denominator).
  auto near = [](double got, double want) { EXPECT_NEAR(got, want, 1e-9 * std::abs(want)); };
  near(lateral.Fy, -3152.7703258394577);
  near(lateral.t, 0.025358872907201655);
  near(lateral.Mzr, 2.2654229482329495);
  near(lateral.Fx, 64.51650387097733);
  near(lateral.Mz, 82.33819721933575);
  near(At(m, 4500.0, 0.05, 0.0).Fx, 4158.710866648746);
  near(lateral.Kya, -72808.98876404495);
}

// The law against tests/tire/mf61_reference.csv: an evaluation of the same published equations
// written apart from it in Python (tests/tire/mf61_reference.py, from the book and the forms of
// TNO's solver that MFeval documents), at 450 points of loads, pressures, inclinations and combined
// slips that the closed forms above do not reach (the camber terms of Mz, combined-slip Mz).
TEST(MagicFormula, AgreesWithAnEvaluationWrittenApart) {
  std::ifstream in(std::filesystem::path(VDYN_SOURCE_DIR) / "tests" / "tire" /
                   "mf61_reference.csv");
  ASSERT_TRUE(in) << "tests/tire/mf61_reference.csv";
  std::string line;
  std::getline(in, line);
  ASSERT_EQ(line, "Fz_N,pressure_Pa,gamma_rad,kappa,alpha_rad,Fx_N,Fy_N,Mz_Nm");
  const MagicFormula m = Tire();
  int points = 0;
  while (std::getline(in, line)) {
    std::vector<double> v;
    std::istringstream row(line);
    std::string cell;
    while (std::getline(row, cell, ',')) v.push_back(std::stod(cell));
    ASSERT_EQ(v.size(), 8u) << line;
    const MfOutput o = At(m, v[0], v[3], v[4], v[2], v[1]);
    // The table's 12 significant digits, and Pacejka's epsilon placed alike.
    EXPECT_NEAR(o.Fx, v[5], 1e-9 * v[0]) << line;
    EXPECT_NEAR(o.Fy, v[6], 1e-9 * v[0]) << line;
    EXPECT_NEAR(o.Mz, v[7], 1e-9 * v[0] * m.unloaded_radius) << line;
    ++points;
  }
  EXPECT_EQ(points, 450);
}

// TNO's relaxation lengths: the slip stiffness over the carcass stiffness, which the file gives
// with its load and pressure terms (PCFX*, PCFY*).
TEST(MagicFormula, RelaxationLengthsAreTheSlipStiffnessesOverTheCarcassStiffnesses) {
  const MagicFormula m = Tire();
  for (double Fz : kLoads) {
    for (double p : kPressures) {
      const MfOutput o = At(m, Fz, 0.0, 0.0, 0.0, p);
      const double dfz = (Fz - m.fnomin) / m.fnomin, dpi = (p - m.nompres) / m.nompres;
      const double Cx = m.longitudinal_stiffness * (1 + m.pcfx1 * dfz + m.pcfx2 * dfz * dfz) *
                        (1 + m.pcfx3 * dpi);
      const double Cy =
          m.lateral_stiffness * (1 + m.pcfy1 * dfz + m.pcfy2 * dfz * dfz) * (1 + m.pcfy3 * dpi);
      EXPECT_NEAR(o.sigma_kappa, ClosedKxk(m, Fz, p) / Cx, 1e-12);
      EXPECT_NEAR(o.sigma_alpha, -ClosedKya(m, Fz, p) / Cy, 1e-12);
    }
  }
}

// === the tyre in parameters, messages and on the command line ===================================

// The default car with `tire` on every wheel, then `edit`.
pb::VehicleParams CarOn(const pb::MagicFormulaTire& tire,
                        const std::function<void(pb::VehicleParams&)>& edit = {}) {
  pb::VehicleParams p = DefaultVehicleParams();
  for (pb::WheelParams* w : {p.mutable_lf(), p.mutable_rf(), p.mutable_lr(), p.mutable_rr()}) {
    *w->mutable_magic_formula() = tire;
  }
  if (edit) edit(p);
  return p;
}
ValidParams TireParams(const std::function<void(pb::VehicleParams&)>& edit = {}) {
  return ParamsFromProto(CarOn(SyntheticTire(), edit));
}

TEST(TireParams, AParameterFileNamesTyresPerAxleAndPerWheelRelativeToItself) {
  TempDir dir;
  std::filesystem::create_directories(dir / "car" / "tyres");
  std::filesystem::copy_file(SyntheticTirePath(), dir / "car" / "tyres" / "front.tir");
  std::string rear = testing::ReadFile(SyntheticTirePath());
  rear.replace(rear.find("PDY1                     = 1.05"), 31, "PDY1                     = 0.95");
  WriteFile(dir / "car" / "tyres" / "rear.tir", rear);
  WriteFile(dir / "car" / "car.txt",
            "tire_file: \"tyres/front.tir\"\ntire_file_rear: \"tyres/rear.tir\"\n"
            "rr { tire_file: \"tyres/front.tir\" camber: -0.02 }\n");
  const pb::VehicleParams p = LoadVehicleParamsFile(dir / "car" / "car.txt");
  EXPECT_EQ(p.lf().magic_formula().pdy1(), 1.05);
  EXPECT_EQ(p.rf().magic_formula().pdy1(), 1.05);
  EXPECT_EQ(p.lr().magic_formula().pdy1(), 0.95);  // the axle's file over the one for all
  EXPECT_EQ(p.rr().magic_formula().pdy1(), 1.05);  // the wheel's own over its axle's
  EXPECT_EQ(p.lr().magic_formula().name(), "rear.tir");
  EXPECT_FALSE(p.has_tire_file() || p.has_tire_file_rear() || p.rr().has_tire_file());
  EXPECT_EQ(p.rr().camber(), -0.02);
  // The tyre's radius and vertical stiffness (with its pressure term) replace the car's.
  const ValidParams v = ParamsFromProto(p);
  EXPECT_EQ(v->wheel[kLF].radius, 0.316);
  EXPECT_EQ(v->full.tire_vertical_stiffness[kLF], 230000.0);
  EXPECT_NE(v->wheel[kLF].radius, DefaultVehicleParams().lf().radius());
  // A tyre file that cannot be read is named with the parameter file.
  WriteFile(dir / "car" / "bad.txt", "lf { tire_file: \"tyres/none.tir\" }\n");
  try {
    LoadVehicleParamsFile(dir / "car" / "bad.txt");
    ADD_FAILURE();
  } catch (const ParamsError& e) {
    EXPECT_THAT(e.what(), HasSubstr("bad.txt: tire_file: "));
    EXPECT_THAT(e.what(), HasSubstr("none.tir: no such tyre file"));
  }
}

// The tyre is a radial spring: a stiffness the static load would compress by more than a fifth of
// the radius (or one not positive) is refused by name. Before, 1000 N/m was accepted and the car
// started 4 m deep and fell for ever (exit 0), as did a file whose PFZ1 made its stiffness
// negative at its pressure, also as a live change.
TEST(TireParams, ATyreTooSoftToCarryTheCarIsRefused) {
  pb::VehicleParams soft = DefaultVehicleParams();
  soft.set_tire_vertical_stiffness(1000.0);
  std::string issues = FormatIssues(ValidateVehicleParams(soft));
  // LF: m g c / (b + c) / 2 = 1500 * 9.81 * 1.5 / 2.7 / 2 = 4087.5 N on 1000 N/m: 4.0875 m; a
  // fifth of the 0.32 m radius is 0.064 m, which takes 4087.5 / 0.064 = 63867 N/m (printed to 4
  // significant digits).
  EXPECT_THAT(issues, HasSubstr("tire_vertical_stiffness: the static load (4087 N) compresses the "
                                "LF tyre by 4.087 m, more than a fifth of its radius (0.064 m): it "
                                "needs at least 63867 N/m"))
      << issues;
  soft.set_tire_vertical_stiffness(63900.0);  // just above the front's need
  issues = FormatIssues(ValidateVehicleParams(soft));
  EXPECT_TRUE(issues.empty()) << issues;
  // A tyre file's own stiffness, with its pressure term: VERTICAL_STIFFNESS (1 + PFZ1 dpi).
  const pb::VehicleParams car = CarOn(SyntheticTire());
  pb::VehicleParams change;
  change.mutable_lf()->mutable_magic_formula()->set_pfz1(-100.0);
  change.mutable_lf()->mutable_magic_formula()->set_inflpres(
      SyntheticTire().nompres() * 1.2);  // dpi = 0.2: 1 - 20 < 0
  issues = FormatIssues(ValidateVehicleParams(MergeVehicleParams(car, change)));
  EXPECT_THAT(issues, HasSubstr("lf.magic_formula.vertical_stiffness: the LF tyre's vertical "
                                "stiffness (VERTICAL_STIFFNESS (1 + PFZ1 dpi) at INFLPRES) is -"))
      << issues;
  EXPECT_THAT(issues, HasSubstr("it must be positive")) << issues;
}

// A message carries coefficients, never a file name; a named tyre replaces a wheel's, a nameless
// one changes the coefficients it has, an empty one removes the tyre.
TEST(TireParams, MessagesCarryCoefficientsAndMergeAsDocumented) {
  pb::VehicleParams msg = DefaultVehicleParams();
  msg.mutable_lf()->set_tire_file("front.tir");
  msg.set_tire_file_rear("rear.tir");
  const auto issues = ValidateVehicleParams(msg);
  ASSERT_EQ(issues.size(), 2u) << FormatIssues(issues);
  EXPECT_THAT(FormatIssues(issues),
              HasSubstr("lf.tire_file: a tyre file is read where a parameter "
                        "file is loaded; a message carries its coefficients"));
  const pb::VehicleParams car = CarOn(SyntheticTire());
  pb::VehicleParams change;
  change.mutable_lf()->mutable_magic_formula()->set_pdy1(0.8);  // a live change of one coefficient
  const pb::VehicleParams a = MergeVehicleParams(car, change);
  EXPECT_EQ(a.lf().magic_formula().pdy1(), 0.8);
  EXPECT_EQ(a.lf().magic_formula().pky1(), -18.0);
  EXPECT_TRUE(ValidateVehicleParams(a).empty());
  pb::VehicleParams other;
  pb::MagicFormulaTire t = SyntheticTire();
  t.set_name("other.tir");
  t.clear_lmuv();
  *other.mutable_lf()->mutable_magic_formula() = t;  // another file: replaces the whole tyre
  pb::VehicleParams with_lmuv = car;
  with_lmuv.mutable_lf()->mutable_magic_formula()->set_lmuv(0.5);
  const pb::VehicleParams b = MergeVehicleParams(with_lmuv, other);
  EXPECT_EQ(b.lf().magic_formula().name(), "other.tir");
  EXPECT_FALSE(b.lf().magic_formula().has_lmuv());
  pb::VehicleParams remove;
  remove.mutable_rr()->mutable_magic_formula();
  EXPECT_FALSE(MergeVehicleParams(car, remove).rr().has_magic_formula());
  EXPECT_TRUE(MergeVehicleParams(car, remove).lf().has_magic_formula());
  // The dump reads back to the same parameters, coefficients and all.
  const std::string dump = DumpVehicleParamsText(car);
  EXPECT_THAT(dump, HasSubstr("name: \"vdyn_synthetic_205_55R16_mf61.tir\""));
  EXPECT_EQ(ParseVehicleParams(dump, false, "dump").SerializeAsString(), car.SerializeAsString());
  // Static camber: in range, or refused by name.
  pb::VehicleParams cam = car;
  cam.mutable_lr()->set_camber(0.5);
  EXPECT_THAT(FormatIssues(ValidateVehicleParams(cam)),
              HasSubstr("lr.camber: static camber must be "
                        "in [-0.3, 0.3] rad, got 0.5"));
}

struct ServerRun {
  int exit_code = -1;
  std::string output;
};
ServerRun RunServer(const std::string& args, bool with_stderr = true) {
  const std::string cmd = std::string("timeout -s KILL 120 ") + VDYN_SERVER_BINARY + " " + args +
                          (with_stderr ? " 2>&1" : " 2>/dev/null");
  ServerRun r;
  FILE* pipe = popen(cmd.c_str(), "r");
  if (pipe == nullptr) return r;
  std::array<char, 4096> buf;
  while (std::fgets(buf.data(), buf.size(), pipe) != nullptr) r.output += buf.data();
  const int status = pclose(pipe);
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return r;
}

TEST(TireCli, TheCurvesOfATyreFileAsCsv) {
  const ServerRun r = RunServer("--tire-curves " + SyntheticTirePath().string(), false);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  std::istringstream in(r.output);
  std::string line;
  std::getline(in, line);
  EXPECT_EQ(line, "curve,Fz_N,kappa,alpha_rad,gamma_rad,Fx_N,Fy_N,Mz_Nm,Mx_Nm,My_Nm");
  std::map<std::string, int> rows;
  std::set<double> loads;
  const MagicFormula m = Tire();
  double worst = 0.0;
  while (std::getline(in, line)) {
    std::istringstream row(line);
    std::string curve, cell;
    std::getline(row, curve, ',');
    std::vector<double> v;
    while (std::getline(row, cell, ',')) v.push_back(std::stod(cell));
    ASSERT_EQ(v.size(), 9u) << line;
    ++rows[curve];
    loads.insert(v[0]);
    // Each row is the law at its point.
    const MfOutput o = At(m, v[0], v[1], v[2]);
    worst = std::max({worst, std::abs(o.Fx - v[4]), std::abs(o.Fy - v[5]), std::abs(o.Mz - v[6])});
  }
  EXPECT_EQ(worst, 0.0);
  EXPECT_EQ(loads, (std::set<double>{2250.0, 4500.0, 6750.0}));
  EXPECT_EQ(rows["lateral"], 3 * 121);
  EXPECT_EQ(rows["longitudinal"], 3 * 121);
  EXPECT_EQ(rows["combined"], 3 * 4 * 121);
  const ServerRun one =
      RunServer("--tire-curves " + SyntheticTirePath().string() + " --fz 3000", false);
  EXPECT_EQ(std::count(one.output.begin(), one.output.end(), '\n'), 1 + 6 * 121);
  TempDir dir;
  WriteFile(dir / "pac.tir", "[MODEL]\nFITTYP = 6\n");
  const ServerRun bad = RunServer("--tire-curves " + (dir / "pac.tir").string());
  EXPECT_EQ(bad.exit_code, 2);
  EXPECT_THAT(bad.output, HasSubstr("pac.tir:2: FITTYP: 6 is MF 5.2 / PAC2002"));
  // A load above FZMAX (10000 N) is not evaluated there: the rows were FZMAX's, labelled 20000.
  const ServerRun above =
      RunServer("--tire-curves " + SyntheticTirePath().string() + " --fz 3000,20000");
  EXPECT_EQ(above.exit_code, 2);
  EXPECT_THAT(above.output, HasSubstr("--fz 20000 N is above the tyre's FZMAX (10000 N)"));
  // The paper model has no tyre law: a tyre file with it is refused (it read only the radius).
  const ServerRun paper = RunServer("--batch --world flat --maneuver demo --duration 1 --model "
                                    "paper --tire " + SyntheticTirePath().string());
  EXPECT_EQ(paper.exit_code, 2);
  EXPECT_THAT(paper.output, HasSubstr("lf.magic_formula: the paper model has no tyre law"));
}

TEST(TireCli, TireOptionsPutTheFileOnTheirWheelsAndTheDumpShowsIt) {
  const std::string tir = SyntheticTirePath().string();
  const ServerRun all = RunServer("--dump-vehicle --tire " + tir, false);
  ASSERT_EQ(all.exit_code, 0) << all.output;
  const pb::VehicleParams p = ParseVehicleParams(all.output, false, "dump");
  for (const pb::WheelParams* w : {&p.lf(), &p.rf(), &p.lr(), &p.rr()}) {
    EXPECT_EQ(w->magic_formula().name(), "vdyn_synthetic_205_55R16_mf61.tir");
  }
  const ServerRun front = RunServer("--dump-vehicle --tire-front " + tir, false);
  const pb::VehicleParams f = ParseVehicleParams(front.output, false, "dump");
  EXPECT_TRUE(f.lf().has_magic_formula() && f.rf().has_magic_formula());
  EXPECT_FALSE(f.lr().has_magic_formula() || f.rr().has_magic_formula());
  const ServerRun missing = RunServer("--dump-vehicle --tire-rear /nonexistent.tir");
  EXPECT_EQ(missing.exit_code, 2);
  EXPECT_THAT(missing.output, HasSubstr("/nonexistent.tir: no such tyre file"));
}

// === the full model on the tyre
// ===================================================================

Eigen::Vector3d BodyVelocity(const State& s) {
  return Orientation(s.x).normalized().toRotationMatrix().transpose() * Velocity(s.x);
}

// Seconds of simulated time, a tenth under the sanitizers for the long ones.
std::int64_t Steps(const Simulator& sim, double seconds) {
  return static_cast<std::int64_t>(seconds / sim.h());
}

double ParkedTravel(double yaw) {
  const std::shared_ptr<const World> world =
      WorldFromMesh(testing::InclinedPlane(0.10, 300.0), {0.0, 0.0, yaw});
  Simulator sim(world, TireParams());
  DriverInput in;
  in.brake = 0.5;
  sim.SetInput(in);
  Drive(sim, 3000, {});  // settle: the tyres and brakes take up the load
  const Eigen::Vector3d p0 = Position(sim.state().x);
  Drive(sim, Steps(sim, testing::kSanitized ? 6.0 : 60.0), {});
  EXPECT_EQ(sim.invariant_failures(), 0u);
  return (Position(sim.state().x) - p0).norm();
}

TEST(MagicFormulaVehicle, ParkedOnA10PercentGradeWithTheBrakeHeldDoesNotCreep) {
  const double along = ParkedTravel(0.0);
  const double across = ParkedTravel(std::numbers::pi / 2);
  std::printf(
      "Magic Formula tyres parked on 10 %%: %.3g m along, %.3g m across the slope in %g s\n", along,
      across, testing::kSanitized ? 6.0 : 60.0);
  EXPECT_LT(along, 1e-3);
  EXPECT_LT(across, 1e-3);
}

// Braked to a stop from 10 m/s, then held: once at rest nothing oscillates (no tyre force, moment
// or steering torque moves by more than a hair over two seconds) and the car stays where it is.
TEST(MagicFormulaVehicle, NothingChattersAtAStandstill) {
  Simulator sim(SharedWorld("flat"), TireParams());
  sim.Spawn({0, 0, 0}, 10.0);
  DriverInput in;
  in.brake = 1.0;
  sim.SetInput(in);
  Drive(sim, Steps(sim, 6.0), {});
  ASSERT_LT(Velocity(sim.state().x).norm(), 1e-3);
  std::array<std::array<double, 2>, 12> range;
  for (auto& r : range) r = {1e300, -1e300};
  double steer_lo = 1e300, steer_hi = -1e300;
  const Eigen::Vector3d p0 = Position(sim.state().x);
  Drive(sim, Steps(sim, 2.0), {}, [&](const StepRecord& r) {
    for (int w = 0; w < kNumWheels; ++w) {
      const WheelOutputs& o = r.derived.wheel[w];
      const double v[3] = {o.Fx, o.Fy, o.Mz};
      for (int k = 0; k < 3; ++k) {
        range[3 * w + k][0] = std::min(range[3 * w + k][0], v[k]);
        range[3 * w + k][1] = std::max(range[3 * w + k][1], v[k]);
      }
    }
    steer_lo = std::min(steer_lo, r.derived.steering_torque);
    steer_hi = std::max(steer_hi, r.derived.steering_torque);
    return false;
  });
  double worst = 0.0;
  for (const auto& r : range) worst = std::max(worst, r[1] - r[0]);
  std::printf(
      "at a standstill for 2 s: largest swing of a tyre force or moment %.3g, of the "
      "steering torque %.3g N m, moved %.3g m\n",
      worst, steer_hi - steer_lo, (Position(sim.state().x) - p0).norm());
  EXPECT_LT(worst, 0.5);
  EXPECT_LT(steer_hi - steer_lo, 0.01);
  EXPECT_LT((Position(sim.state().x) - p0).norm(), 1e-4);
  EXPECT_EQ(sim.invariant_failures(), 0u);
}

// Wheels locked to a stop from 15 m/s (ABS off), the brake held. A locked wheel slides at
// kappa = -1, its deflection near sigma_kappa (0.3 m); at low speed the deflection is held at the
// sliding limit and pulled back to it (8.2b), so when the car stops nothing is left wound up to
// push it back by sigma_kappa: it moves back no more than the brush tyre's car does in the same
// stop (its body pitching back and its tyres unwinding), a few centimetres.
double LockedStopRollBack(const ValidParams& p) {
  Simulator sim(SharedWorld("flat"), p);
  sim.Spawn({0, 0, 0}, 15.0);
  DriverInput in;
  in.brake = 1.0;
  sim.SetInput(in);
  double x_stop = 0.0;
  Drive(sim, 20000, {}, [&](const StepRecord&) {
    x_stop = Position(sim.state().x).x();
    return BodyVelocity(sim.state()).x() < 0.01;
  });
  double x_min = x_stop;
  Drive(sim, Steps(sim, 3.0), {}, [&](const StepRecord&) {
    x_min = std::min(x_min, Position(sim.state().x).x());
    return false;
  });
  EXPECT_LT(Velocity(sim.state().x).norm(), 1e-3);
  return x_stop - x_min;
}

TEST(MagicFormulaVehicle, ALockedStopLeavesNothingWoundUp) {
  auto locked = [](pb::VehicleParams& m) {
    m.set_abs(false);
    m.set_brake_force_max(40000.0);
  };
  const double mf = LockedStopRollBack(TireParams(locked));
  const double brush = LockedStopRollBack(testing::ParamsWith(locked));
  std::printf(
      "locked stop from 15 m/s, then held: moved back %.4f m (the brush tyre's car %.4f m)\n", mf,
      brush);
  EXPECT_LT(mf, 1.2 * brush);
  EXPECT_LT(mf, 0.1);
}

// The file is a LEFT tyre: on the right wheels it is mirrored (TNO's convention), so its
// conicity and ply steer (the shifts) cancel across the car and it runs straight.
TEST(MagicFormulaVehicle, ARightWheelsTyreIsMirroredAndTheCarRunsStraight) {
  Simulator sim(SharedWorld("flat"), TireParams());
  sim.Spawn({0, 0, 0}, 20.0);
  DriverInput in;
  in.cruise_on = true;
  in.cruise_speed = 20.0;
  sim.SetInput(in);
  Drive(sim, Steps(sim, 5.0), {});
  const StepRecord& r = sim.last_step();
  const double fy_l = r.derived.wheel[kLR].Fy, fy_r = r.derived.wheel[kRR].Fy;
  std::printf("straight at 20 m/s: Fy LR %.2f N, RR %.2f N, yaw rate %.2g rad/s, lateral %.3g m\n",
              fy_l, fy_r, AngularVelocityB(sim.state().x).z(), Position(sim.state().x).y());
  EXPECT_GT(std::abs(fy_l), 5.0);  // the shifts act ...
  EXPECT_NEAR(fy_l, -fy_r, 0.5);   // ... and cancel
  EXPECT_LT(std::abs(AngularVelocityB(sim.state().x).z()), 1e-4);
  EXPECT_LT(std::abs(Position(sim.state().x).y()), 0.01);
}

// The inclination the law reads: the static camber (negative: the top leans inboard) and the
// body's roll, ISO-W signs (positive leans the top to the right).
TEST(MagicFormulaVehicle, TheLawReadsTheWheelsInclinationToTheGround) {
  Simulator rest(
      SharedWorld("flat"), TireParams([](pb::VehicleParams& p) {
        for (auto* w : {p.mutable_lf(), p.mutable_rf(), p.mutable_lr(), p.mutable_rr()}) {
          w->set_camber(-0.02);
        }
      }));
  Drive(rest, 1000, {});
  const auto& w = rest.last_step().derived.wheel;
  EXPECT_NEAR(w[kLF].camber, 0.02, 1e-3);
  EXPECT_NEAR(w[kLR].camber, 0.02, 1e-3);
  EXPECT_NEAR(w[kRF].camber, -0.02, 1e-3);
  EXPECT_NEAR(w[kRR].camber, -0.02, 1e-3);
  EXPECT_EQ(w[kLF].pressure, 230000.0);
  // A steady left turn rolls the body right side down (roll > 0): every wheel leans the same.
  Simulator turn(SharedWorld("flat"), TireParams());
  turn.Spawn({0, 0, 0}, 15.0);
  DriverInput in;
  in.steer = 0.04;
  in.cruise_on = true;
  in.cruise_speed = 15.0;
  turn.SetInput(in);
  Drive(turn, Steps(turn, 4.0), {});
  const double roll = RollPitchYaw(Orientation(turn.state().x)).x();
  const auto& t = turn.last_step().derived.wheel;
  std::printf("left turn at 15 m/s: roll %.4f rad, inclination LR %.4f RR %.4f rad\n", roll,
              t[kLR].camber, t[kRR].camber);
  EXPECT_GT(roll, 0.005);
  EXPECT_NEAR(t[kLR].camber, roll, 1e-3);
  EXPECT_NEAR(t[kRR].camber, roll, 1e-3);
}

// The understeer gradient the tyres' cornering stiffnesses give, K = (m / L)(c / Cf - b / Cr)
// with Cf, Cr = 2 |Kya| at each axle's static load (4.E25), next to the one measured in steady
// turns at constant steer: K = (V delta / r - L) / V^2. The car coasts with the clutch down, no
// drag and no rolling resistance (LMY = 0), so no tyre drives or brakes (a driving front tyre
// gives up side force to combined slip: +12 % on K at 30 m/s); the camber thrust and the shifts
// are zeroed so that Kya is all the tyre says (body roll leans the wheels).
TEST(MagicFormulaVehicle, SteadyStateUndersteerGradientFromTheTyresCorneringStiffness) {
  pb::MagicFormulaTire t = SyntheticTire();
  ZeroShifts(t);
  t.set_lmy(0.0);
  const ValidParams p = ParamsFromProto(CarOn(t, [](pb::VehicleParams& m) { m.set_cx(0.0); }));
  const MagicFormula m = MagicFormulaFromProto(t);
  const double L = p->wheelbase, g = p->gravity, mass = p->mass;
  const double Cf = 2.0 * std::abs(ClosedKya(m, StaticWheelLoad(p, kLF), m.inflpres));
  const double Cr = 2.0 * std::abs(ClosedKya(m, StaticWheelLoad(p, kLR), m.inflpres));
  const double K_closed = (mass / L) * (p->c / Cf - p->b / Cr);
  const double delta = 0.002;  // lateral accelerations under 0.6 m/s^2: the linear range
  double K_sum = 0.0;
  int n = 0;
  for (double V : {10.0, 20.0, 30.0}) {
    Simulator sim(SharedWorld("flat"), p);
    sim.Spawn({0, 0, 0}, V);
    DriverInput in;
    in.steer = delta;
    in.clutch = 1.0;
    sim.SetInput(in);
    Drive(sim, Steps(sim, 8.0), {});
    const double r = AngularVelocityB(sim.state().x).z();
    const double v = BodyVelocity(sim.state()).x();
    const double K = (v * delta / r - L) / (v * v);
    std::printf("  V %.1f m/s: yaw rate %.5f rad/s, ay %.2f m/s^2, K %.5f rad/(m/s^2)\n", v, r,
                v * r, K);
    K_sum += K;
    ++n;
  }
  const double K_measured = K_sum / n;
  std::printf(
      "understeer gradient: measured %.5f, from the tyres' Kya %.5f rad/(m/s^2) (%+.1f %%; "
      "%.3f and %.3f deg/g)\n",
      K_measured, K_closed, 100.0 * (K_measured / K_closed - 1.0),
      K_measured * g * 180.0 / std::numbers::pi, K_closed * g * 180.0 / std::numbers::pi);
  EXPECT_GT(K_closed, 0.0);  // the rear tyres are the less loaded: an understeering car
  EXPECT_NEAR(K_measured / K_closed, 1.0, 0.03);
}

// A step steer at 10 m/s on a heavy body (mass and inertia times 67, gravity over 67: the loads
// of the default car, a body that hardly turns): the front side force follows the slip step as a
// first-order lag with the time constant sigma_alpha / V, sigma_alpha the file's relaxation length
// at the wheel's load. Measured by three equally spaced points of the rise, F(t) = F_inf (1 -
// exp(-(t - t_d) / tau)): tau = dt / ln((F2 - F1) / (F3 - F2)), whatever F_inf and the column's
// delay t_d, before the body's own slow turn bends the curve.
TEST(MagicFormulaVehicle, SideForceLagsAStepSteerByTheFilesRelaxationLength) {
  const double V = 10.0, scale = 1e5 / 1500.0;
  const ValidParams p = TireParams([&](pb::VehicleParams& m) {
    m.set_mass(m.mass() * scale);
    m.set_ixx(m.ixx() * scale);
    m.set_iyy(m.iyy() * scale);
    m.set_izz(m.izz() * scale);
    m.set_gravity(m.gravity() / scale);
    m.set_steering_follow_frequency(2000.0);
  });
  Simulator sim(SharedWorld("flat"), p);
  sim.Spawn({0, 0, 0}, V);
  Drive(sim, 500, {});
  const double Fz = sim.last_step().derived.wheel[kLF].Fp;
  const MfOutput at = At(p->wheel[kLF].mf, Fz, 0.0, 0.0);
  const double F_before = sim.last_step().derived.wheel[kLF].Fy;
  DriverInput in;
  in.steer = 0.005;
  sim.SetInput(in);
  const double tau_expect = at.sigma_alpha / V;
  const double dt = 0.8 * tau_expect;
  std::array<double, 3> F{};
  double v = 0.0;
  const double t0 = sim.time();
  Drive(sim, static_cast<std::int64_t>((0.01 + 2.0 * dt) / sim.h()) + 2, {},
        [&](const StepRecord& r) {
          for (int k = 0; k < 3; ++k) {
            if (std::abs(r.t - t0 - (0.01 + k * dt)) < 0.5 * sim.h()) {
              F[k] = r.derived.wheel[kLF].Fy - F_before;
              if (k == 1) v = BodyVelocity(r.state).x();
            }
          }
          return false;
        });
  const double tau = dt / std::log((F[1] - F[0]) / (F[2] - F[1]));
  std::printf(
      "step steer at %.2f m/s, Fz %.0f N: side force time constant %.2f ms, sigma_alpha "
      "%.3f m / V = %.2f ms (%+.2f %%)\n",
      v, Fz, 1e3 * tau, at.sigma_alpha, 1e3 * at.sigma_alpha / v,
      100.0 * (tau / (at.sigma_alpha / v) - 1.0));
  EXPECT_GT(F[2], 100.0);  // a real side force, to the left for a left steer
  EXPECT_NEAR(tau / (at.sigma_alpha / v), 1.0, 0.03);
}

// ABS braking from 20 m/s without drag: about v^2 / (2 mu g) with mu the tyres' peak friction at
// their static loads (4.E13), a little longer (ABS holds the slip just below the peak).
TEST(MagicFormulaVehicle, AbsBrakingDistanceIsNearTheTyresPeakFriction) {
  const ValidParams p = TireParams([](pb::VehicleParams& m) {
    m.set_brake_force_max(40000.0);
    m.set_cx(0.0);
  });
  Simulator sim(SharedWorld("flat"), p);
  const double v0 = 20.0;
  sim.Spawn({0, 0, 0}, v0);
  DriverInput in;
  in.brake = 1.0;
  sim.SetInput(in);
  const Eigen::Vector3d p0 = Position(sim.state().x);
  Drive(sim, 20000, {}, [&](const StepRecord&) { return Velocity(sim.state().x).norm() < 0.01; });
  const double d = (Position(sim.state().x) - p0).norm();
  double mu = 0.0;
  for (int w = 0; w < kNumWheels; ++w) {
    mu += ClosedMux(p->wheel[w].mf, StaticWheelLoad(p, w), p->wheel[w].mf.inflpres) *
          StaticWheelLoad(p, w) / (p->mass * p->gravity);
  }
  const double expect = v0 * v0 / (2.0 * mu * p->gravity);
  std::printf(
      "ABS stop from %.0f m/s: %.2f m, v^2 / (2 mu g) with the tyres' mu %.3f: %.2f m "
      "(%+.1f %%)\n",
      v0, d, mu, expect, 100.0 * (d / expect - 1.0));
  EXPECT_GT(d, expect);
  EXPECT_LT(d, 1.15 * expect);
}

// Full throttle in top gear: the drive force meets drag plus the tyres' rolling resistance, the
// sum of |My| / R (A48, at the static loads and the speed).
TEST(MagicFormulaVehicle, TopSpeedIsWhereTheDriveForceMeetsDragAndTheTyresRollingResistance) {
  const ValidParams p = TireParams();
  Simulator sim(SharedWorld("flat"), p);
  sim.Spawn({0, 0, 0}, 180.0 / 3.6);
  DriverInput in;
  in.throttle = 1.0;
  sim.SetInput(in);
  Drive(sim, Steps(sim, testing::kSanitized ? 30.0 : 120.0), {});
  const double v = BodyVelocity(sim.state()).x();
  // The tyres' rolling resistance: |My| / R of each wheel at its static load.
  const double expect = testing::ClosedFormTopSpeed(p, [&](double speed) {
    double roll = 0.0;
    for (int w = 0; w < kNumWheels; ++w) {
      MfInput at;
      at.Fz = StaticWheelLoad(p, w);
      at.Vx = at.Vc = speed;
      at.pressure = p->wheel[w].mf.inflpres;
      roll += std::abs(EvaluateMagicFormula(p->wheel[w].mf, at).My) / p->wheel[w].radius;
    }
    return roll;
  });
  std::printf("Magic Formula tyres, top speed %.2f km/h, closed form %.2f km/h (%+.2f %%)\n",
              3.6 * v, 3.6 * expect, 100.0 * (v / expect - 1.0));
  if (!testing::kSanitized) {
    EXPECT_NEAR(v / expect, 1.0, 0.01);
  }
}

// The demo drive on facility on the tyre: finite, no invariant broken, no tyre force beyond the
// file's friction ellipse at its load (with a margin for the shifts).
TEST(MagicFormulaVehicle, TheDemoDriveRunsOnTheTyre) {
  Simulator sim(SharedWorld("facility"), TireParams());
  const Maneuver m = Maneuver::Parse(DemoManeuverCsv(), "demo");
  const double end = testing::kSanitized ? 8.0 : m.end_time();
  Drive(sim, Steps(sim, end), [&m](Simulator& s) { s.SetInput(FromManeuver(m.At(s.time()))); });
  EXPECT_EQ(sim.invariant_failures(), 0u);
  EXPECT_EQ(sim.nonfinite_steps(), 0u);
  EXPECT_GT(Position(sim.state().x).norm(), 50.0);
}

// A session on the tyre, with a live change of a coefficient, re-simulates from its events bit
// for bit (what vdyn-recorder verify does with a recording), the events through their bytes.
TEST(MagicFormulaVehicle, ASessionOnTheTyreResimulatesBitForBit) {
  const auto world = SharedWorld("facility");
  SessionConfig c;
  c.server_id = "test";
  c.default_params = CarOn(SyntheticTire());
  c.checkpoint_every_steps = 500;
  std::vector<pb::SessionEvent> events;
  const std::uint64_t terrain = TerrainHash(world->terrain);
  Session s(world, c, [&](SessionEventRecord&& r) {
    pb::SessionEvent e = ToMessage(r, "test", terrain, 1'000'000);
    pb::SessionEvent copy;
    ASSERT_TRUE(copy.ParseFromString(e.SerializeAsString()));
    events.push_back(copy);
  });
  s.Spawn(1, world->spawn, 0.0, pb::VehicleParams());
  std::map<std::uint64_t, std::uint64_t> hashes;
  auto step = [&](int n) {
    for (int i = 0; i < n; ++i) {
      s.Step(
          [&](std::uint32_t, const pb::VehicleState& st) { hashes[st.step()] = st.state_hash(); });
    }
  };
  std::string why;
  for (int k = 0; k < 20; ++k) {
    pb::DriverInput in;
    in.set_vehicle_id(1);
    in.set_source_id("test");
    in.set_throttle(0.8);
    in.set_steer(0.003 * k);
    ASSERT_TRUE(s.OfferInput(in, &why)) << why;
    step(50);
  }
  pb::ControlRequest change;
  change.set_vehicle_id(1);
  change.set_request_id(1);
  change.set_client_id("t");
  change.mutable_set_params()->mutable_params()->mutable_lf()->mutable_magic_formula()->set_pdy1(
      0.8);
  ASSERT_TRUE(s.Apply(change).accepted());
  step(1500);
  const ResimResult res = Resimulate(world, events, {{1u, hashes.rbegin()->first + 1}});
  ASSERT_TRUE(res.ok) << res.error;
  ASSERT_EQ(res.hashes.at(1).size(), hashes.size());
  for (const auto& [n, h] : hashes) ASSERT_EQ(res.hashes.at(1).at(n), h) << "step " << n;
}

}  // namespace
}  // namespace vdyn

namespace vdyn {
namespace {

// A wheel on a tyre file rolls on its UNLOADED_RADIUS: a live change of its radius is refused
// with the reason (it was accepted, shown by params() and never used); the same radius again
// (a whole message sent back) is not a change and passes. The dump says which radius is used.
TEST(TireParams, ARadiusChangeOnATyreFilesWheelIsRefusedWithTheReason) {
  const auto world = testing::SharedWorld("flat");
  SessionConfig c;
  c.default_params = CarOn(SyntheticTire());
  Session s(world, c, nullptr);
  s.Spawn(1, world->spawn, 0.0, pb::VehicleParams());
  pb::ControlRequest change;
  change.set_vehicle_id(1);
  change.mutable_set_params()->mutable_params()->mutable_lf()->set_radius(0.4);
  const pb::ControlReply refused = s.Apply(change);
  EXPECT_FALSE(refused.accepted());
  EXPECT_THAT(refused.reason(), HasSubstr("lf.radius: this wheel's tyre file sets its radius "
                                          "(UNLOADED_RADIUS 0.316 m)"));
  pb::ControlRequest same;
  same.set_vehicle_id(1);
  *same.mutable_set_params()->mutable_params() = s.params(1);
  EXPECT_TRUE(s.Apply(same).accepted());
  EXPECT_THAT(DumpVehicleParamsText(c.default_params),
              HasSubstr("# lf rolls on its tyre file's UNLOADED_RADIUS (0.316 m), not on its "
                        "radius\n"));
}

}  // namespace
}  // namespace vdyn
