// Periodic boundaries (SciPy's boxsize) on top of the single-tree queries: a query is wrapped into
// the box and searched again from each image q + s * L (s in {-1, 0, 1} per periodic axis) that can
// hold a point within the limit; a point met from several images keeps its nearest one.
//
// The points lie in [0, L) on each periodic axis, so on that axis the torus distance is the smaller
// of |q - x| and L - |q - x|, which the images -L, 0, +L of a wrapped q reach; a combination of
// shifts is searched only if its distance to the data's bounding box can be within the limit.
// Distances are measured from the shifted query (q + L rounded once).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "kdspace/points/detail/result_sets.hpp"

namespace kdspace::python {

/// A periodic box over the data: size[a] > 0 makes axis a periodic with period size[a]; lo and hi
/// are the bounds of the data (all finite).
template <class S>
struct PeriodicBox {
  std::vector<S> size, lo, hi;
  bool periodic(std::size_t a) const { return size[a] > 0; }
};

/// q wrapped into [0, L) on the periodic axes.
template <class S>
void wrap_into(const PeriodicBox<S>& box, const S* q, S* out, std::size_t dim) {
  for (std::size_t a = 0; a < dim; ++a) {
    S v = q[a];
    if (box.periodic(a)) {
      v -= box.size[a] * std::floor(v / box.size[a]);
      if (!(v < box.size[a]) || v < 0) v = 0;  // rounding may land on L itself
    }
    out[a] = v;
  }
}

/// Calls visit(image, shifted) for every image of the wrapped query `q` whose lower bound (internal
/// units, the metric's) to the data's bounding box is at most `limit`, the unshifted one first.
template <class Metric, class S, class Visit>
void for_each_image(const PeriodicBox<S>& box, const Metric& metric, const S* q, std::size_t dim, S limit,
                    Visit&& visit) {
  // terms[3a + s + 1]: axis a's contribution to the bound of an image shifted by s periods there.
  std::vector<S> terms(3 * dim), least(dim);
  for (std::size_t a = 0; a < dim; ++a) {
    for (int s = -1; s <= 1; ++s) {
      const S x = q[a] + static_cast<S>(s) * box.size[a];
      const S gap = x < box.lo[a] ? box.lo[a] - x : (x > box.hi[a] ? x - box.hi[a] : S(0));
      terms[3 * a + static_cast<std::size_t>(s + 1)] = metric.term(gap);
    }
    if (!box.periodic(a)) terms[3 * a] = terms[3 * a + 2] = terms[3 * a + 1];  // never shifted
    least[a] = std::min({terms[3 * a], terms[3 * a + 1], terms[3 * a + 2]});
  }
  std::vector<int> shift(dim, 0);
  std::vector<S> image(q, q + dim);
  // The bound of the images whose shifts on the axes before `next` are chosen: those axes' terms,
  // and the least term of every axis after (a lower bound whatever their shifts).
  auto lower_bound = [&](std::size_t next) {
    S bound = 0;
    for (std::size_t a = 0; a < dim; ++a)
      bound = metric.accumulate(bound,
                                a < next ? terms[3 * a + static_cast<std::size_t>(shift[a] + 1)] : least[a]);
    return bound;
  };
  auto recurse = [&](auto&& self, std::size_t a, bool shifted) -> void {
    if (a == dim) {
      visit(static_cast<const S*>(image.data()), shifted);
      return;
    }
    for (int s : {0, -1, 1}) {
      if (s != 0 && !box.periodic(a)) continue;
      shift[a] = s;
      if (lower_bound(a + 1) > limit) continue;
      image[a] = q[a] + static_cast<S>(s) * box.size[a];
      self(self, a + 1, shifted || s != 0);
    }
    shift[a] = 0;
    image[a] = q[a];
  };
  recurse(recurse, 0, false);
}

/// Keeps, for each index, its smallest distance (a point found from several images), in
/// (distance, index) order.
template <class S>
void nearest_image_only(std::vector<detail::Candidate<S>>& found) {
  std::sort(found.begin(), found.end(), [](const auto& x, const auto& y) {
    return x.index < y.index || (x.index == y.index && x.dist < y.dist);
  });
  found.erase(std::unique(found.begin(), found.end(),
                          [](const auto& x, const auto& y) { return x.index == y.index; }),
              found.end());
  std::sort(found.begin(), found.end(), detail::comes_before);
}

}  // namespace kdspace::python
