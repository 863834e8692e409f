// The closed slab test shared by the BoxTree traversal (lib/rays/traverse.cpp) and the benchmark's
// Embree user geometry (bench/rays_bench.cpp), so that both test a box in exactly the same way.
#pragma once

#include <algorithm>
#include <array>

#include "kdspace/box.hpp"
#include "kdspace/rays/ray.hpp"

namespace kdspace::detail {

/// A ray prepared once for many slab tests: its origin and reciprocal direction in double.
struct PreparedRay {
  std::array<double, 3> origin;
  std::array<double, 3> inverse;  ///< 1 / direction; unused on axes where the direction is 0
  std::array<bool, 3> parallel;   ///< direction component is +0 or -0
  std::array<bool, 3> negative;   ///< direction component < 0

  explicit PreparedRay(const Ray& r) {
    for (int a = 0; a < 3; ++a) {
      origin[a] = r.origin[a];
      parallel[a] = r.direction[a] == 0;
      negative[a] = r.direction[a] < 0;
      // A float direction, even subnormal, has a finite reciprocal in double.
      inverse[a] = parallel[a] ? 0.0 : 1.0 / static_cast<double>(r.direction[a]);
    }
  }
};

/// Slab test (Kay & Kajiya 1986) of the closed box against the ray over [t_near, t_far]; on return
/// [t_near, t_far] is the part of that interval inside the box. False when it is empty.
inline bool clip_to_box(const Box3f& b, const PreparedRay& r, double& t_near, double& t_far) {
  for (int a = 0; a < 3; ++a) {
    if (r.parallel[a]) {
      if (r.origin[a] < b.lo[a] || r.origin[a] > b.hi[a]) return false;
      continue;
    }
    const double t_lo = (static_cast<double>(b.lo[a]) - r.origin[a]) * r.inverse[a];
    const double t_hi = (static_cast<double>(b.hi[a]) - r.origin[a]) * r.inverse[a];
    // Entered at the smaller parameter, left at the larger (neither is NaN: the origin and the box
    // are finite and the reciprocal is finite); a min and a max, not a select on the direction's
    // sign, which the compiler made a branch mispredicted 2.7 times a random ray that hits.
    const double t0 = std::min(t_lo, t_hi), t1 = std::max(t_lo, t_hi);
    t_near = std::max(t_near, t0);
    t_far = std::min(t_far, t1);
  }
  return t_near <= t_far;
}

}  // namespace kdspace::detail
