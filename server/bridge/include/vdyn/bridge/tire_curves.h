// A Magic Formula tyre's characteristic curves as CSV (vdyn-server --tire-curves): what engineers
// plot to check a tyre file before they use it (docs/formats.md, "Tyre curves").
#pragma once

#include <string>
#include <vector>

#include "vdyn/physics/magic_formula.h"

namespace vdyn {

// At each load (N; empty: 0.5, 1 and 1.5 times the file's FNOMIN), at the file's LONGVL, INFLPRES
// and no inclination: the pure lateral sweep (alpha over +-0.3 rad: Fy, Mz, Mx), the pure
// longitudinal sweep (kappa over +-0.5: Fx, My) and combined slip (kappa over +-0.5 at alpha 1,
// 2, 4 and 8 degrees: Fx and Fy). One row a point: curve,Fz_N,kappa,alpha_rad,gamma_rad,Fx_N,
// Fy_N,Mz_Nm,Mx_Nm,My_Nm, numbers in their shortest exact form.
std::string TireCurvesCsv(const MagicFormula& mf, std::vector<double> loads_N);

}  // namespace vdyn
