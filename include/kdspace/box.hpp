// Box<T, D>: a closed axis-aligned box, the vocabulary shared by the point and the ray modules.
#pragma once

#include <array>

namespace kdspace {

template <class T, int D>
struct Box {
  std::array<T, D> lo{};
  std::array<T, D> hi{};

  /// True when lo <= p <= hi on every axis (the box is closed).
  bool contains(const T* p) const {
    for (int a = 0; a < D; ++a)
      if (!(lo[a] <= p[a] && p[a] <= hi[a])) return false;
    return true;
  }

  /// True when the closed boxes share a point: touching faces, edges or corners count.
  bool overlaps(const Box& other) const {
    for (int a = 0; a < D; ++a)
      if (!(lo[a] <= other.hi[a] && other.lo[a] <= hi[a])) return false;
    return true;
  }
};

using Box3f = Box<float, 3>;
/// A 3-D vector of floats: a displacement (the motion of a moving box).
using Vec3f = std::array<float, 3>;

}  // namespace kdspace
