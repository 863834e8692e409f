// The contact window of a moving box and a scene box, shared by the BoxTree's first-contact traversal
// (lib/collide/contact.cpp) and brute_force_first_contact, so that both compute each time in
// exactly the same way.
#pragma once

#include <array>

#include "kdspace/box.hpp"

namespace kdspace::detail {

/// A moving box prepared once for many tests: its faces and the reciprocal of its motion, in double.
struct PreparedMotion {
  std::array<double, 3> lo, hi;   ///< the moving box at t = 0
  std::array<double, 3> inverse;  ///< 1 / motion; unused on axes where the motion is 0
  std::array<bool, 3> still;      ///< motion component is +0 or -0
  std::array<bool, 3> negative;   ///< motion component < 0

  PreparedMotion(const Box3f& box, const Vec3f& motion) {
    for (int a = 0; a < 3; ++a) {
      lo[a] = box.lo[a];
      hi[a] = box.hi[a];
      still[a] = motion[a] == 0;
      negative[a] = motion[a] < 0;
      // A float motion, even subnormal, has a finite reciprocal in double.
      inverse[a] = still[a] ? 0.0 : 1.0 / static_cast<double>(motion[a]);
    }
  }
};

/// Narrows [t_enter, t_exit] to the times at which the moving box touches the closed box b; false
/// when none is left. On an axis the box moves along, it touches b from when its leading face reaches
/// b's near face, (b.lo - hi) / motion for a positive motion, until its trailing face leaves b's far
/// face, (b.hi - lo) / motion: the slab of b grown by the moving box (Minkowski), entered by the ray
/// t * motion. A difference of two floats is exact in sign in double, so t = 0 is inside the window
/// exactly when the boxes overlap now.
inline bool contact_window(const Box3f& b, const PreparedMotion& m, double& t_enter, double& t_exit) {
  for (int a = 0; a < 3; ++a) {
    if (m.still[a]) {
      if (m.lo[a] > b.hi[a] || m.hi[a] < b.lo[a]) return false;
      continue;
    }
    const double t_reach = (static_cast<double>(b.lo[a]) - m.hi[a]) * m.inverse[a];
    const double t_leave = (static_cast<double>(b.hi[a]) - m.lo[a]) * m.inverse[a];
    const double t0 = m.negative[a] ? t_leave : t_reach, t1 = m.negative[a] ? t_reach : t_leave;
    if (t0 > t_enter) t_enter = t0;
    if (t1 < t_exit) t_exit = t1;
  }
  return t_enter <= t_exit;
}

}  // namespace kdspace::detail
