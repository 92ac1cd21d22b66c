#include "vdyn/physics/magic_formula.h"

#include <algorithm>
#include <cmath>

namespace vdyn {
namespace {

constexpr double kRequired = MagicFormula::kRequired;
constexpr MagicFormulaField kMagicFormulaFields[] = {
#define VDYN_MF_FIELD(name, fallback) {#name, &MagicFormula::name, fallback},
    VDYN_MAGIC_FORMULA_COEFFICIENTS(VDYN_MF_FIELD)
#undef VDYN_MF_FIELD
};

constexpr double kPi = 3.14159265358979323846;
// Pacejka's epsilon (eq. 4.E6a): keeps the denominators B = K / (C D + eps) and the like away from
// zero without changing a value anywhere else.
constexpr double kEps = 1e-6;

// The sign with sign(0) = +1, as TNO's solver takes it in the denominators and the curvature.
double SgnPositiveAtZero(double v) {
  return v >= 0.0 ? 1.0 : -1.0;
}
// cos(atan(x)) without either.
double CosAtan(double x) {
  return 1.0 / std::sqrt(1.0 + x * x);
}
// The Magic Formula's inner argument, B x - E (B x - atan(B x)) (eq. 4.E9 and the like).
double Inner(double B, double E, double x) {
  const double bx = B * x;
  return bx - E * (bx - std::atan(bx));
}

// The pure lateral force (eqs. 4.E19-4.E30) at inclination sin(gamma) = gs, with what Mz reads.
struct LateralPure {
  double Fy0 = 0, muy = 0, By = 0, Cy = 0, SHy = 0, SVy = 0;
};
LateralPure PureLateral(const MagicFormula& m, const MfLoad& L, double Kya, double gs,
                        double alpha_star) {
  LateralPure r;
  const double SVyg = L.Fz * (m.pvy3 + m.pvy4 * L.dfz) * gs * m.lkyc * L.lmuy_prime;
  const double Kyg0 = L.Fz * (m.pky6 + m.pky7 * L.dfz) * (1.0 + m.ppy5 * L.dpi) * m.lkyc;
  r.SHy = ((m.phy1 + m.phy2 * L.dfz) * m.lhy +
           (Kyg0 * gs - SVyg) / (Kya + kEps * SgnPositiveAtZero(Kya))) *
          L.reduction;
  r.SVy = (L.Fz * (m.pvy1 + m.pvy2 * L.dfz) * m.lvy * L.lmuy_prime + SVyg) * L.reduction;
  const double alpha_y = alpha_star + r.SHy;
  r.Cy = m.pcy1 * m.lcy;
  r.muy = (m.pdy1 + m.pdy2 * L.dfz) * (1.0 + m.ppy3 * L.dpi + m.ppy4 * L.dpi * L.dpi) *
          (1.0 - m.pdy3 * gs * gs) * L.lmuy_star;
  const double Dy = r.muy * L.Fz;
  const double Ey = std::min(
      (m.pey1 + m.pey2 * L.dfz) *
          (1.0 + m.pey5 * gs * gs - (m.pey3 + m.pey4 * gs) * SgnPositiveAtZero(alpha_y)) * m.ley,
      1.0);
  r.By = Kya / (r.Cy * Dy + kEps * SgnPositiveAtZero(Dy));
  r.Fy0 = Dy * std::sin(r.Cy * std::atan(Inner(r.By, Ey, alpha_y))) + r.SVy;
  return r;
}

// The cornering stiffness (eq. 4.E25) at inclination sin(gamma) = gs.
double CorneringStiffness(const MagicFormula& m, const MfLoad& L, double gs) {
  return m.pky1 * L.Fz0p * (1.0 + m.ppy1 * L.dpi) * (1.0 - m.pky3 * std::abs(gs)) *
         std::sin(m.pky4 * std::atan((L.Fz / L.Fz0p) /
                                     ((m.pky2 + m.pky5 * gs * gs) * (1.0 + m.ppy2 * L.dpi)))) *
         m.lky;
}

// The weighting function of combined slip, cos(C atan(B x - E (B x - atan(B x)))) (4.E51, 4.E59).
double Weight(double B, double C, double E, double x) {
  return std::cos(C * std::atan(Inner(B, E, x)));
}

}  // namespace

std::span<const MagicFormulaField> MagicFormulaFields() {
  return kMagicFormulaFields;
}

void DeriveMagicFormula(MagicFormula& mf) {
  mf.tan_alpmin = std::tan(mf.alpmin);
  mf.tan_alpmax = std::tan(mf.alpmax);
  mf.my_pressure_factor =
      std::pow(std::clamp(mf.inflpres, mf.presmin, mf.presmax) / mf.nompres, mf.qsy8);
}

MfLoad MagicFormulaLoad(const MagicFormula& m, double Fz, double gamma, double pressure) {
  MfLoad L;
  L.Fz = std::clamp(Fz, 0.0, m.fzmax);
  L.gamma = std::clamp(gamma, m.cammin, m.cammax);
  L.gs = std::sin(L.gamma);
  L.pressure = std::clamp(pressure, m.presmin, m.presmax);
  L.Fz0p = m.fnomin * m.lfzo;                    // 4.E1
  L.dfz = (L.Fz - L.Fz0p) / L.Fz0p;              // 4.E2a
  L.dpi = (L.pressure - m.nompres) / m.nompres;  // 4.E2b
  L.Kxk = L.Fz * (m.pkx1 + m.pkx2 * L.dfz) * std::exp(m.pkx3 * L.dfz) *
          (1.0 + m.ppx1 * L.dpi + m.ppx2 * L.dpi * L.dpi) * m.lkx;  // 4.E15
  L.Kya = CorneringStiffness(m, L, L.gs);
  // Carcass stiffnesses and the relaxation lengths of MF 6.1 (TNO: sigma = |K| / C).
  L.Cx = m.longitudinal_stiffness * (1.0 + m.pcfx1 * L.dfz + m.pcfx2 * L.dfz * L.dfz) *
         (1.0 + m.pcfx3 * L.dpi);
  L.Cy = m.lateral_stiffness * (1.0 + m.pcfy1 * L.dfz + m.pcfy2 * L.dfz * L.dfz) *
         (1.0 + m.pcfy3 * L.dpi);
  L.sigma_kappa = std::abs(L.Kxk) / L.Cx;
  L.sigma_alpha = std::abs(L.Kya) / L.Cy;
  return L;
}

MfOutput EvaluateMagicFormula(const MagicFormula& m, MfLoad L, const MfSlip& s, bool aligning,
                              bool overturning) {
  MfOutput o;
  o.Kxk = L.Kxk;
  o.Kya = L.Kya;
  o.Cx = L.Cx;
  o.Cy = L.Cy;
  o.sigma_kappa = L.sigma_kappa;
  o.sigma_alpha = L.sigma_alpha;
  if (L.Fz <= 0.0) return o;
  const double kappa = std::clamp(s.kappa, m.kpumin, m.kpumax);
  const double alpha_star = std::clamp(s.tan_alpha, m.tan_alpmin, m.tan_alpmax);  // 4.E3
  const double gs = L.gs;  // sin(gamma), 4.E4
  const double gamma = L.gamma;
  // Friction scaling with slip speed (4.E7; LMUV), no digressive friction (A_mu = 1: 4.E8 as TNO).
  const double Vs = std::abs(s.Vx) * std::sqrt(kappa * kappa + alpha_star * alpha_star);
  const double lmu_decay = 1.0 + m.lmuv * Vs / m.longvl;
  L.lmux_star = m.lmux / lmu_decay;
  L.lmuy_star = m.lmuy / lmu_decay;
  L.lmux_prime = L.lmux_star;
  L.lmuy_prime = L.lmuy_star;
  // Below VXLOW the shifts, the trail and the residual torque fade out (TNO's smooth reduction):
  // nothing pushes at a standstill but the slips.
  const double vx_low = std::abs(s.Vx) / m.vxlow;
  L.reduction = vx_low >= 1.0 ? 1.0 : 0.5 * (1.0 - std::cos(kPi * vx_low));
  // cos(alpha'), alpha' the angle of the contact centre's velocity (4.E6).
  const double cos_alpha_prime = std::clamp(s.Vx / (s.Vc + kEps), -1.0, 1.0);

  // Pure longitudinal slip (4.E9-4.E18).
  const double Cx = m.pcx1 * m.lcx;
  o.mux = (m.pdx1 + m.pdx2 * L.dfz) * (1.0 + m.ppx3 * L.dpi + m.ppx4 * L.dpi * L.dpi) *
          (1.0 - m.pdx3 * gamma * gamma) * L.lmux_star;
  const double Dx = o.mux * L.Fz;
  const double Bx = L.Kxk / (Cx * Dx + kEps * SgnPositiveAtZero(Dx));
  const double SHx = (m.phx1 + m.phx2 * L.dfz) * m.lhx * L.reduction;
  const double SVx = L.Fz * (m.pvx1 + m.pvx2 * L.dfz) * m.lvx * L.lmux_prime * L.reduction;
  const double kappa_x = kappa + SHx;
  const double Ex = std::min((m.pex1 + m.pex2 * L.dfz + m.pex3 * L.dfz * L.dfz) *
                                 (1.0 - m.pex4 * SgnPositiveAtZero(kappa_x)) * m.lex,
                             1.0);
  const double Fx0 = Dx * std::sin(Cx * std::atan(Inner(Bx, Ex, kappa_x))) + SVx;

  // Pure lateral slip (4.E19-4.E30).
  const LateralPure y = PureLateral(m, L, L.Kya, gs, alpha_star);
  o.muy = y.muy;

  // Combined slip (4.E50-4.E67).
  const double Exa = std::min(m.rex1 + m.rex2 * L.dfz, 1.0);
  const double Bxa = (m.rbx1 + m.rbx3 * gs * gs) * CosAtan(m.rbx2 * kappa) * m.lxal;
  const double Gxa =
      Weight(Bxa, m.rcx1, Exa, alpha_star + m.rhx1) / Weight(Bxa, m.rcx1, Exa, m.rhx1);
  o.Fx = Gxa * Fx0;
  const double DVyk =
      y.muy * L.Fz * (m.rvy1 + m.rvy2 * L.dfz + m.rvy3 * gs) * CosAtan(m.rvy4 * alpha_star);
  const double SVyk = DVyk * std::sin(m.rvy5 * std::atan(m.rvy6 * kappa)) * m.lvyka * L.reduction;
  const double SHyk = m.rhy1 + m.rhy2 * L.dfz;
  const double Eyk = std::min(m.rey1 + m.rey2 * L.dfz, 1.0);
  const double Byk = (m.rby1 + m.rby4 * gs * gs) * CosAtan(m.rby2 * (alpha_star - m.rby3)) * m.lyka;
  const double Gyk = Weight(Byk, m.rcy1, Eyk, kappa + SHyk) / Weight(Byk, m.rcy1, Eyk, SHyk);
  o.Fy = Gyk * y.Fy0 + SVyk;

  // Aligning moment (4.E31-4.E49, 4.E71-4.E78) in the forms of TNO's solver: Bt and Dt with gamma
  // (QBZ4, QDZ3), the trail times LFZO, s with Fz0 (not Fz0'), the equivalent slips of A54/A55;
  // the trail acts on the pure side force at zero inclination (4.E74).
  if (aligning) {
    const double Kya0 = gs == 0.0 ? L.Kya : CorneringStiffness(m, L, 0.0);
    const double Fy0_g0 = gs == 0.0 ? y.Fy0 : PureLateral(m, L, Kya0, 0.0, alpha_star).Fy0;
    const double Kya_p = L.Kya + kEps * SgnPositiveAtZero(L.Kya);                 // 4.E39
    const double alpha_r = alpha_star + y.SHy + y.SVy / Kya_p;                    // 4.E37, 4.E38
    const double SHt = m.qhz1 + m.qhz2 * L.dfz + (m.qhz3 + m.qhz4 * L.dfz) * gs;  // 4.E35
    const double alpha_t = alpha_star + SHt;                                      // 4.E34
    const double Bt = (m.qbz1 + m.qbz2 * L.dfz + m.qbz3 * L.dfz * L.dfz) *
                      (1.0 + m.qbz4 * gamma + m.qbz5 * std::abs(gamma)) * m.lky / L.lmuy_star;
    const double Ct = m.qcz1;
    const double Dt = (m.qdz1 + m.qdz2 * L.dfz) * (1.0 - m.ppz1 * L.dpi) *
                      (1.0 + m.qdz3 * gamma + m.qdz4 * gamma * gamma) * L.Fz *
                      (m.unloaded_radius / L.Fz0p) * m.ltr;
    const double Et =
        std::min((m.qez1 + m.qez2 * L.dfz + m.qez3 * L.dfz * L.dfz) *
                     (1.0 + (m.qez4 + m.qez5 * gs) * (2.0 / kPi) * std::atan(Bt * Ct * alpha_t)),
                 1.0);
    const double Br = m.qbz9 * m.lky / L.lmuy_star + m.qbz10 * y.By * y.Cy;
    const double Dr =
        L.Fz * m.unloaded_radius *
        ((m.qdz6 + m.qdz7 * L.dfz) * m.lres + ((m.qdz8 + m.qdz9 * L.dfz) * (1.0 + m.ppz2 * L.dpi) +
                                               (m.qdz10 + m.qdz11 * L.dfz) * std::abs(gs)) *
                                                  gs * m.lkzc) *
        L.lmuy_star * SgnPositiveAtZero(s.Vx) * std::cos(alpha_star);
    const double k_ratio = L.Kxk / Kya_p * kappa;
    const double tr = std::tan(alpha_r), tt = std::tan(alpha_t);
    const double alpha_r_eq =
        std::atan(std::sqrt(tr * tr + k_ratio * k_ratio)) * SgnPositiveAtZero(alpha_r);
    const double alpha_t_eq =
        std::atan(std::sqrt(tt * tt + k_ratio * k_ratio)) * SgnPositiveAtZero(alpha_t);
    const double s_arm = m.unloaded_radius *
                         (m.ssz1 + m.ssz2 * (o.Fy / m.fnomin) + (m.ssz3 + m.ssz4 * L.dfz) * gamma) *
                         m.ls;
    o.Mzr = Dr * std::cos(std::atan(Br * alpha_r_eq)) * L.reduction;  // Cr = 1
    o.t = Dt * Weight(Bt, Ct, Et, alpha_t_eq) * cos_alpha_prime * m.lfzo * L.reduction;
    o.Mz = -o.t * Gyk * Fy0_g0 + o.Mzr + s_arm * o.Fx;
  }

  // The slips' linear force over the peak, |(Kxk kappa / Dx, Kya tan(alpha) / Dy)|: 1 where the
  // patch's deflection (kappa sigma_kappa = Kxk kappa / Cx) would carry the peak force on the
  // carcass stiffness alone. The deflections' sliding limit at low speed.
  const double Dy = y.muy * L.Fz;
  o.slide = std::hypot(L.Kxk * kappa / std::max(Dx, kEps), L.Kya * alpha_star / std::max(Dy, kEps));

  // Rolling resistance (A48) and, with `overturning`, the overturning moment (TNO's equation
  // manual; Besselink et al.).
  const double fz_n = L.Fz / m.fnomin;
  const double vx_n = s.Vx / m.longvl;
  o.My = -m.unloaded_radius * m.fnomin * m.lmy *
         (m.qsy1 + m.qsy2 * (o.Fx / m.fnomin) + m.qsy3 * std::abs(vx_n) +
          m.qsy4 * vx_n * vx_n * vx_n * vx_n + (m.qsy5 + m.qsy6 * fz_n) * gamma * gamma) *
         std::pow(fz_n, m.qsy7) *
         (m.my_pressure_factor > 0.0 && L.pressure == std::clamp(m.inflpres, m.presmin, m.presmax)
              ? m.my_pressure_factor
              : std::pow(L.pressure / m.nompres, m.qsy8));
  if (!overturning) return o;
  const double fy_n = o.Fy / m.fnomin;
  o.Mx =
      m.unloaded_radius * L.Fz * m.lmx *
          (m.qsx1 * m.lvmx - m.qsx2 * gamma * (1.0 + m.ppmx1 * L.dpi) + m.qsx3 * fy_n +
           m.qsx4 * std::cos(m.qsx5 * std::atan((m.qsx6 * fz_n) * (m.qsx6 * fz_n))) *
               std::sin(m.qsx7 * gamma + m.qsx8 * std::atan(m.qsx9 * fy_n)) +
           m.qsx10 * std::atan(m.qsx11 * fz_n) * gamma) +
      m.unloaded_radius * m.lmx *
          (o.Fy * (m.qsx13 + m.qsx14 * std::abs(gamma)) - L.Fz * m.qsx12 * gamma * std::abs(gamma));
  return o;
}

MfOutput EvaluateMagicFormula(const MagicFormula& mf, const MfInput& in) {
  const MfLoad L = MagicFormulaLoad(mf, in.Fz, in.gamma, in.pressure);
  return EvaluateMagicFormula(mf, L, {in.kappa, in.tan_alpha, in.Vx, in.Vc}, true, true);
}

MfPeaks MagicFormulaPeaks(const MagicFormula& mf, double Fz) {
  // Fx0 along kappa and Fy0 along alpha at speed LONGVL, no camber, the file's pressure: the
  // first maximum of |F| on a fine grid, refined by golden-section search.
  MfPeaks p;
  for (int axis = 0; axis < 2; ++axis) {
    auto force = [&](double x) {
      MfInput in;
      in.Fz = Fz;
      in.pressure = mf.inflpres;
      in.Vx = mf.longvl;
      in.kappa = axis == 0 ? x : 0.0;
      in.tan_alpha = axis == 1 ? x : 0.0;
      in.Vc = mf.longvl * std::sqrt(1.0 + in.tan_alpha * in.tan_alpha);
      const MfOutput o = EvaluateMagicFormula(mf, in);
      return std::abs(axis == 0 ? o.Fx : o.Fy);
    };
    const double hi = axis == 0 ? std::min(mf.kpumax, 2.0) : std::min(std::tan(mf.alpmax), 2.0);
    constexpr int kGrid = 400;
    double best_x = hi, best_f = -1.0;
    for (int i = 1; i <= kGrid; ++i) {
      const double x = hi * i / kGrid;
      const double f = force(x);
      if (f > best_f) {
        best_f = f;
        best_x = x;
      } else if (f < best_f) {
        break;  // past the first maximum
      }
    }
    double a = std::max(best_x - hi / kGrid, 0.0), b = std::min(best_x + hi / kGrid, hi);
    const double g = 0.5 * (std::sqrt(5.0) - 1.0);
    for (int i = 0; i < 60; ++i) {
      const double c = b - g * (b - a), d = a + g * (b - a);
      if (force(c) > force(d)) {
        b = d;
      } else {
        a = c;
      }
    }
    (axis == 0 ? p.kappa : p.tan_alpha) = 0.5 * (a + b);
  }
  return p;
}

}  // namespace vdyn
