// The Magic Formula tyre: MF 6.1 / 6.2 (Pacejka, *Tire and Vehicle Dynamics*, 3rd ed., 2012,
// chapter 4.3.2, eqs. 4.E1-4.E78), steady state, without turn slip, in the forms of TNO's own
// solver where they differ from the book (docs/model.md, 8.2b, lists each difference and its
// source). Physics only: the coefficients come from a .tir file through the io layer and the
// bridge; this file evaluates them.
//
// Axes: ISO-W at the contact centre: x along the wheel heading, y to the left, z up. Inputs are
// the longitudinal slip kappa, tan(alpha) (alpha > 0 when the contact moves to the left), the
// inclination gamma (> 0 when the top of the wheel leans to the right), the load and the
// pressure. With the TNO files' signs (PKY1 < 0) the side force opposes the slip.
#pragma once

#include <limits>
#include <span>
#include <string_view>

namespace vdyn {

// The coefficients, in the order of proto/vdyn/vehicle_params.proto's MagicFormulaTire: the .tir
// key in lower case and the value used when a file does not give it (kRequired: the file must).
// One list for the struct, its table and (by a test) the message.
#define VDYN_MAGIC_FORMULA_COEFFICIENTS(X)                   \
  /* the model */                                            \
  X(longvl, kRequired)                                       \
  X(vxlow, kRequired)                                        \
  /* dimensions */                                           \
  X(unloaded_radius, kRequired)                              \
  /* operating conditions */                                 \
  X(inflpres, kRequired)                                     \
  X(nompres, kRequired)                                      \
  /* vertical */                                             \
  X(fnomin, kRequired)                                       \
  X(vertical_stiffness, 0.0)                                 \
  X(pfz1, 0.0)                                               \
  /* carcass stiffnesses (relaxation lengths) */             \
  X(longitudinal_stiffness, kRequired)                       \
  X(lateral_stiffness, kRequired)                            \
  X(pcfx1, 0.0)                                              \
  X(pcfx2, 0.0)                                              \
  X(pcfx3, 0.0)                                              \
  X(pcfy1, 0.0)                                              \
  X(pcfy2, 0.0)                                              \
  X(pcfy3, 0.0)                                              \
  /* ranges of use (the law's inputs are clamped to them) */ \
  X(presmin, 0.0)                                            \
  X(presmax, 1e9)                                            \
  X(fzmax, 1e9)                                              \
  X(kpumin, -10.0)                                           \
  X(kpumax, 10.0)                                            \
  X(alpmin, -1.5)                                            \
  X(alpmax, 1.5)                                             \
  X(cammin, -1.0)                                            \
  X(cammax, 1.0)                                             \
  /* scaling factors (absent: 1, LMUV 0) */                  \
  X(lfzo, 1.0)                                               \
  X(lcx, 1.0)                                                \
  X(lmux, 1.0)                                               \
  X(lex, 1.0)                                                \
  X(lkx, 1.0)                                                \
  X(lhx, 1.0)                                                \
  X(lvx, 1.0)                                                \
  X(lcy, 1.0)                                                \
  X(lmuy, 1.0)                                               \
  X(ley, 1.0)                                                \
  X(lky, 1.0)                                                \
  X(lkyc, 1.0)                                               \
  X(lkzc, 1.0)                                               \
  X(lhy, 1.0)                                                \
  X(lvy, 1.0)                                                \
  X(ltr, 1.0)                                                \
  X(lres, 1.0)                                               \
  X(lxal, 1.0)                                               \
  X(lyka, 1.0)                                               \
  X(lvyka, 1.0)                                              \
  X(ls, 1.0)                                                 \
  X(lmx, 1.0)                                                \
  X(lvmx, 1.0)                                               \
  X(lmy, 1.0)                                                \
  X(lmuv, 0.0)                                               \
  /* longitudinal force */                                   \
  X(pcx1, kRequired)                                         \
  X(pdx1, kRequired)                                         \
  X(pdx2, kRequired)                                         \
  X(pdx3, kRequired)                                         \
  X(pex1, kRequired)                                         \
  X(pex2, kRequired)                                         \
  X(pex3, kRequired)                                         \
  X(pex4, kRequired)                                         \
  X(pkx1, kRequired)                                         \
  X(pkx2, kRequired)                                         \
  X(pkx3, kRequired)                                         \
  X(phx1, kRequired)                                         \
  X(phx2, kRequired)                                         \
  X(pvx1, kRequired)                                         \
  X(pvx2, kRequired)                                         \
  X(ppx1, kRequired)                                         \
  X(ppx2, kRequired)                                         \
  X(ppx3, kRequired)                                         \
  X(ppx4, kRequired)                                         \
  X(rbx1, kRequired)                                         \
  X(rbx2, kRequired)                                         \
  X(rbx3, kRequired)                                         \
  X(rcx1, kRequired)                                         \
  X(rex1, kRequired)                                         \
  X(rex2, kRequired)                                         \
  X(rhx1, kRequired)                                         \
  /* overturning moment (QSX4-QSX14, PPMX1 absent: 0) */     \
  X(qsx1, kRequired)                                         \
  X(qsx2, kRequired)                                         \
  X(qsx3, kRequired)                                         \
  X(qsx4, 0.0)                                               \
  X(qsx5, 0.0)                                               \
  X(qsx6, 0.0)                                               \
  X(qsx7, 0.0)                                               \
  X(qsx8, 0.0)                                               \
  X(qsx9, 0.0)                                               \
  X(qsx10, 0.0)                                              \
  X(qsx11, 0.0)                                              \
  X(qsx12, 0.0)                                              \
  X(qsx13, 0.0)                                              \
  X(qsx14, 0.0)                                              \
  X(ppmx1, 0.0)                                              \
  /* lateral force */                                        \
  X(pcy1, kRequired)                                         \
  X(pdy1, kRequired)                                         \
  X(pdy2, kRequired)                                         \
  X(pdy3, kRequired)                                         \
  X(pey1, kRequired)                                         \
  X(pey2, kRequired)                                         \
  X(pey3, kRequired)                                         \
  X(pey4, kRequired)                                         \
  X(pey5, kRequired)                                         \
  X(pky1, kRequired)                                         \
  X(pky2, kRequired)                                         \
  X(pky3, kRequired)                                         \
  X(pky4, kRequired)                                         \
  X(pky5, kRequired)                                         \
  X(pky6, kRequired)                                         \
  X(pky7, kRequired)                                         \
  X(phy1, kRequired)                                         \
  X(phy2, kRequired)                                         \
  X(pvy1, kRequired)                                         \
  X(pvy2, kRequired)                                         \
  X(pvy3, kRequired)                                         \
  X(pvy4, kRequired)                                         \
  X(ppy1, kRequired)                                         \
  X(ppy2, kRequired)                                         \
  X(ppy3, kRequired)                                         \
  X(ppy4, kRequired)                                         \
  X(ppy5, kRequired)                                         \
  X(rby1, kRequired)                                         \
  X(rby2, kRequired)                                         \
  X(rby3, kRequired)                                         \
  X(rby4, kRequired)                                         \
  X(rcy1, kRequired)                                         \
  X(rey1, kRequired)                                         \
  X(rey2, kRequired)                                         \
  X(rhy1, kRequired)                                         \
  X(rhy2, kRequired)                                         \
  X(rvy1, kRequired)                                         \
  X(rvy2, kRequired)                                         \
  X(rvy3, kRequired)                                         \
  X(rvy4, kRequired)                                         \
  X(rvy5, kRequired)                                         \
  X(rvy6, kRequired)                                         \
  /* rolling resistance moment */                            \
  X(qsy1, kRequired)                                         \
  X(qsy2, kRequired)                                         \
  X(qsy3, kRequired)                                         \
  X(qsy4, kRequired)                                         \
  X(qsy5, kRequired)                                         \
  X(qsy6, kRequired)                                         \
  X(qsy7, kRequired)                                         \
  X(qsy8, kRequired)                                         \
  /* aligning moment */                                      \
  X(qbz1, kRequired)                                         \
  X(qbz2, kRequired)                                         \
  X(qbz3, kRequired)                                         \
  X(qbz4, kRequired)                                         \
  X(qbz5, kRequired)                                         \
  X(qbz9, kRequired)                                         \
  X(qbz10, kRequired)                                        \
  X(qcz1, kRequired)                                         \
  X(qdz1, kRequired)                                         \
  X(qdz2, kRequired)                                         \
  X(qdz3, kRequired)                                         \
  X(qdz4, kRequired)                                         \
  X(qdz6, kRequired)                                         \
  X(qdz7, kRequired)                                         \
  X(qdz8, kRequired)                                         \
  X(qdz9, kRequired)                                         \
  X(qdz10, kRequired)                                        \
  X(qdz11, kRequired)                                        \
  X(qez1, kRequired)                                         \
  X(qez2, kRequired)                                         \
  X(qez3, kRequired)                                         \
  X(qez4, kRequired)                                         \
  X(qez5, kRequired)                                         \
  X(qhz1, kRequired)                                         \
  X(qhz2, kRequired)                                         \
  X(qhz3, kRequired)                                         \
  X(qhz4, kRequired)                                         \
  X(ppz1, kRequired)                                         \
  X(ppz2, kRequired)                                         \
  X(ssz1, kRequired)                                         \
  X(ssz2, kRequired)                                         \
  X(ssz3, kRequired)                                         \
  X(ssz4, kRequired)

struct MagicFormula {
  static constexpr double kRequired = std::numeric_limits<double>::quiet_NaN();
  bool enabled = false;  // false: the wheel uses the brush law
  int side = 1;          // TYRESIDE: +1 LEFT, -1 RIGHT, 0 SYMMETRIC
#define VDYN_MF_MEMBER(name, fallback) double name = 0;
  VDYN_MAGIC_FORMULA_COEFFICIENTS(VDYN_MF_MEMBER)
#undef VDYN_MF_MEMBER
  // Derived (DeriveMagicFormula): tan(ALPMIN), tan(ALPMAX), unclamped until derived; My's
  // pressure factor (INFLPRES / NOMPRES)^QSY8 (0: not derived, computed at each evaluation).
  double tan_alpmin = -std::numeric_limits<double>::infinity();
  double tan_alpmax = std::numeric_limits<double>::infinity();
  double my_pressure_factor = 0;
};

struct MagicFormulaField {
  std::string_view name;  // the .tir key in lower case ("pdy1")
  double MagicFormula::*member;
  double fallback;  // MagicFormula::kRequired (NaN): the file must give it
};
// Every coefficient, in the message's order.
std::span<const MagicFormulaField> MagicFormulaFields();
// Fills the derived members (once, when parameters are validated).
void DeriveMagicFormula(MagicFormula& mf);

// The shortest relaxation length the model gives a Magic Formula tyre (at a light load, |K| / C
// shrinks with the load), m.
inline constexpr double kMfMinRelaxationLength = 0.05;

// What depends on the load, inclination and pressure alone (held while the slips vary; the
// relaxation lengths come from here before the slips are known).
struct MfLoad {
  double Fz = 0, gamma = 0, gs = 0, pressure = 0;  // clamped inputs; gs = sin(gamma) (4.E4)
  double Fz0p = 0, dfz = 0, dpi = 0;               // 4.E1, 4.E2
  double Kxk = 0;                                  // longitudinal slip stiffness (4.E15), N
  double Kya = 0;  // cornering stiffness (4.E25), N/rad (< 0 with TNO's signs)
  double Cx = 0, Cy = 0;                    // carcass stiffnesses, N/m
  double sigma_kappa = 0, sigma_alpha = 0;  // relaxation lengths |Kxk| / Cx, |Kya| / Cy, m
  // Set by the evaluation (they depend on the slip speed): 4.E7, 4.E8, the low-speed fade.
  double lmux_star = 1, lmuy_star = 1, lmux_prime = 1, lmuy_prime = 1, reduction = 1;
};
MfLoad MagicFormulaLoad(const MagicFormula& mf, double Fz, double gamma, double pressure);

// The slips and the contact centre's speeds.
struct MfSlip {
  double kappa = 0;      // longitudinal slip
  double tan_alpha = 0;  // tan(slip angle): lateral over longitudinal speed of the contact centre
  double Vx = 0;         // contact centre speed along the heading, m/s (its sign: the direction)
  double Vc = 0;         // contact centre speed, m/s (|V| in the ground plane)
};

// One evaluation's inputs (for a caller without a held MfLoad).
struct MfInput {
  double Fz = 0;         // normal load, N (>= 0)
  double kappa = 0;      // longitudinal slip
  double tan_alpha = 0;  // tan(slip angle)
  double gamma = 0;      // inclination to the ground, rad
  double Vx = 0;         // m/s
  double Vc = 0;         // m/s
  double pressure = 0;   // inflation pressure, Pa
};

// One evaluation's outputs, ISO-W.
struct MfOutput {
  double Fx = 0, Fy = 0;    // N
  double Mz = 0;            // aligning moment, N*m (> 0 turns the wheel to the left)
  double Mx = 0;            // overturning moment, N*m
  double My = 0;            // rolling resistance moment, N*m (< 0 rolling forward)
  double Kxk = 0, Kya = 0;  // as MfLoad
  double mux = 0, muy = 0;  // peak friction coefficients (4.E13, 4.E23)
  double t = 0;             // pneumatic trail, m
  double Mzr = 0;           // residual torque, N*m
  double Cx = 0, Cy = 0, sigma_kappa = 0, sigma_alpha = 0;  // as MfLoad
  // The slips' linear force over the peak force, |(Kxk kappa / Dx, Kya tan(alpha) / Dy)|: 1 where
  // the patch's deflection carries the peak force on the carcass stiffness alone (the brush law's
  // z at full sliding). The deflections' sliding limit at low speed reads it.
  double slide = 0;
};

// The steady-state forces and moments (docs/model.md, 8.2b): Fx and Fy with combined slip, Mz
// (pneumatic trail, residual torque, the Fx moment arm s), My, and with `overturning` Mx. The
// inputs are clamped to the file's ranges of use (KPUMIN..., ALPMIN..., CAMMIN..., FZMAX,
// PRESMIN...); below VXLOW the shifts, the trail and the residual torque fade out as TNO's solver
// fades them, so nothing acts at a standstill but the slips. No allocation. Without `aligning`
// Mz is left 0 and not computed (a third of the cost: the trail, the residual torque and the
// pure side force again at zero inclination): the vehicle reads a rear wheel's only to publish it.
MfOutput EvaluateMagicFormula(const MagicFormula& mf, MfLoad load, const MfSlip& slip,
                              bool aligning, bool overturning);
MfOutput EvaluateMagicFormula(const MagicFormula& mf, const MfInput& in);

// Where the pure-slip forces peak at load Fz (no camber, the file's INFLPRES, at LONGVL): kappa*
// > 0 and tan(alpha*) > 0 where |Fx| and |Fy| are first largest, found by a search (for ABS and
// traction control, at validation; never in a step).
struct MfPeaks {
  double kappa = 0;
  double tan_alpha = 0;
};
MfPeaks MagicFormulaPeaks(const MagicFormula& mf, double Fz);

}  // namespace vdyn
