#include "params.h"

namespace vdyn {

void DeriveParams(Params& p) {
  p.wheelbase = p.b + p.c;
  // Mount points A in the body frame (X forward, Y left, Z up), the paper's Fig. 4:
  //   LF (+b, +bL)   RF (+b, -bP)
  //   LR (-c, +bL)   RR (-c, -bP)     each z_offset below T.
  const double x[kNumWheels] = {p.b, p.b, -p.c, -p.c};
  const double y[kNumWheels] = {p.b_l, -p.b_p, p.b_l, -p.b_p};
  for (int w = 0; w < kNumWheels; ++w) {
    p.p_TA_B[w] = Eigen::Vector3d(x[w], y[w], -p.wheel[w].z_offset);
  }
  // Body box seen from above, O at its probe height above T; probes 0-3 end on the faces,
  // probes 4-7 at the corners:
  //        7 ------ 2 ------ 4        Y (left)
  //        |                 |        ^
  //        1        O        0        +--> X (forward)
  //        |                 |
  //        6 ------ 3 ------ 5
  p.p_TO_B = Eigen::Vector3d(0.0, 0.0, p.body_probe_height);
  const double f = p.body_front, r = p.body_rear, hw = p.body_half_width;
  const Eigen::Vector2d ends[Params::kNumProbes] = {{f, 0},   {-r, 0},   {0, hw},  {0, -hw},
                                                    {f, hw},  {f, -hw},  {-r, -hw}, {-r, hw}};
  for (int k = 0; k < Params::kNumProbes; ++k) {
    p.probe_length[k] = ends[k].norm();
    p.probe_dir_B[k] = Eigen::Vector3d(ends[k].x(), ends[k].y(), 0.0) / p.probe_length[k];
  }
}

}  // namespace vdyn
