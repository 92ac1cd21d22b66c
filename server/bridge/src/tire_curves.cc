#include "vdyn/bridge/tire_curves.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <numbers>

#include "vdyn/base/text.h"
#include "vdyn/io/shortest_double.h"

namespace vdyn {
namespace {

void Row(std::string& out, const char* curve, double Fz, double kappa, double alpha,
         const MfOutput& o) {
  out += curve;
  for (double v : {Fz, kappa, alpha, 0.0, o.Fx, o.Fy, o.Mz, o.Mx, o.My}) {
    char buf[kShortestDoubleBytes + 1];
    char* end = WriteShortestDouble(buf, v == 0.0 ? 0.0 : v);
    out += ',';
    out.append(buf, end);
  }
  out += '\n';
}

MfOutput At(const MagicFormula& mf, double Fz, double kappa, double alpha) {
  MfInput in;
  in.Fz = Fz;
  in.kappa = kappa;
  in.tan_alpha = std::tan(alpha);
  in.Vx = mf.longvl;
  in.Vc = mf.longvl / std::cos(alpha);
  in.pressure = mf.inflpres;
  return EvaluateMagicFormula(mf, in);
}

}  // namespace

std::string TireCurvesCsv(const MagicFormula& mf, std::vector<double> loads_N) {
  if (loads_N.empty()) {
    const double fz0 = mf.fnomin * mf.lfzo;
    loads_N = {0.5 * fz0, fz0, std::min(1.5 * fz0, mf.fzmax)};
  }
  // Above FZMAX the law takes FZMAX: a row labelled with another load would not be that load's.
  for (double Fz : loads_N) {
    if (Fz > mf.fzmax) {
      throw std::invalid_argument("--fz " + base::FormatNumber(Fz) +
                                  " N is above the tyre's FZMAX (" + base::FormatNumber(mf.fzmax) +
                                  " N), where its Magic Formula stops: give loads up to it");
    }
  }
  constexpr int kPoints = 120;
  std::string out = "curve,Fz_N,kappa,alpha_rad,gamma_rad,Fx_N,Fy_N,Mz_Nm,Mx_Nm,My_Nm\n";
  for (double Fz : loads_N) {
    for (int i = 0; i <= kPoints; ++i) {
      const double alpha = -0.3 + 0.6 * i / kPoints;
      Row(out, "lateral", Fz, 0.0, alpha, At(mf, Fz, 0.0, alpha));
    }
    for (int i = 0; i <= kPoints; ++i) {
      const double kappa = -0.5 + 1.0 * i / kPoints;
      Row(out, "longitudinal", Fz, kappa, 0.0, At(mf, Fz, kappa, 0.0));
    }
    for (double deg : {1.0, 2.0, 4.0, 8.0}) {
      const double alpha = deg * std::numbers::pi / 180.0;
      for (int i = 0; i <= kPoints; ++i) {
        const double kappa = -0.5 + 1.0 * i / kPoints;
        Row(out, "combined", Fz, kappa, alpha, At(mf, Fz, kappa, alpha));
      }
    }
  }
  return out;
}

}  // namespace vdyn
