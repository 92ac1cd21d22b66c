// Classical fourth-order Runge-Kutta at a fixed step, with its Butcher table stored as data.
//
//   k_i = f(x_n + h * sum_j a_ij k_j),  i = 1..4
//   x_{n+1} = x_n + h * sum_i b_i k_i
//
//        c |  a
//        0 |
//      1/2 | 1/2
//      1/2 |  0   1/2
//        1 |  0    0    1
//        --+-------------------
//          | 1/6  1/3  1/3  1/6
#pragma once

#include <array>

#include "vdyn/physics/state.h"

namespace vdyn {

struct ButcherTableau {
  static constexpr int kStages = 4;
  std::array<std::array<double, kStages>, kStages> a;
  std::array<double, kStages> b;
  std::array<double, kStages> c;
};

inline constexpr ButcherTableau kClassicalRk4 = {
    {{{0.0, 0.0, 0.0, 0.0}, {0.5, 0.0, 0.0, 0.0}, {0.0, 0.5, 0.0, 0.0}, {0.0, 0.0, 1.0, 0.0}}},
    {1.0 / 6.0, 1.0 / 3.0, 1.0 / 3.0, 1.0 / 6.0},
    {0.0, 0.5, 0.5, 1.0}};

// Scratch for one step, sized at compile time: a step allocates nothing.
struct Rk4Workspace {
  std::array<StateVector, ButcherTableau::kStages> k;
  StateVector x_stage;
};

// Advances x by one step h. f(stage, x_stage, xdot) evaluates the derivative; `stage` tells the
// caller which evaluation it is (stage 0 is at x_n itself).
template <class Derivative>
void Rk4Step(const ButcherTableau& t, Derivative&& f, double h, Rk4Workspace& ws, StateVector& x) {
  for (int i = 0; i < ButcherTableau::kStages; ++i) {
    ws.x_stage = x;
    for (int j = 0; j < i; ++j) {
      if (t.a[i][j] != 0.0) ws.x_stage += (h * t.a[i][j]) * ws.k[j];
    }
    f(i, ws.x_stage, ws.k[i]);
  }
  for (int i = 0; i < ButcherTableau::kStages; ++i) x += (h * t.b[i]) * ws.k[i];
}

}  // namespace vdyn
