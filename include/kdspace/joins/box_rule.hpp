// The box rule: the points inside an axis-aligned box, on a torus where the box may wrap around a
// periodic axis (the query of PeriodicTree::box). The query tree is a single node whose box is
// ignored; the rule looks at the reference cells only, so the traversal becomes a plain descent.
//
// On axis i the box is [lo, hi]; where the axis is periodic and lo > hi it wraps: [lo, L) and
// [0, hi]. A coordinate is inside by comparisons alone (no arithmetic, so nothing to round).
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "kdspace/joins/bounded_tree.hpp"
#include "kdspace/joins/traversal.hpp"

namespace kdspace::detail {

template <class T, int Dim>
class BoxRule {
 public:
  using Tree = BoundedTree<T, Dim>;
  struct Context {};
  static constexpr bool nearest_first = false;

  /// lo, hi: the box; found: the original indices of the points inside, in visiting order.
  BoxRule(const Tree& query, const Tree& reference, const T* lo, const T* hi, std::vector<std::uint32_t>& found)
      : query_(query), reference_(reference), lo_(lo), hi_(hi), found_(found) {}

  const Tree& query_tree() const { return query_; }
  const Tree& reference_tree() const { return reference_; }

  JoinScore<T, Context> score(std::uint32_t, std::uint32_t r, const Context&) const {
    const T* rlo = reference_.lo(r);
    const T* rhi = reference_.hi(r);
    bool meets = true;
    for (std::size_t a = 0; a < reference_.dim() && meets; ++a)
      meets = lo_[a] <= hi_[a] ? rhi[a] >= lo_[a] && rlo[a] <= hi_[a] : rhi[a] >= lo_[a] || rlo[a] <= hi_[a];
    return {meets, T(0), {}};
  }

  bool rescore(std::uint32_t, std::uint32_t, T) const { return true; }
  void query_done(std::uint32_t) {}

  template <class Isa>
  void base_case(std::uint32_t, std::uint32_t r, const Context&, Isa) {
    const auto& leaf = reference_.node(r);
    for (std::uint32_t j = leaf.begin; j < leaf.end; ++j)
      if (inside(reference_.point(j))) found_.push_back(reference_.index(j));
  }

 private:
  bool inside(const T* p) const {
    for (std::size_t a = 0; a < reference_.dim(); ++a)
      if (lo_[a] <= hi_[a] ? !(lo_[a] <= p[a] && p[a] <= hi_[a]) : !(p[a] >= lo_[a] || p[a] <= hi_[a])) return false;
    return true;
  }

  const Tree& query_;
  const Tree& reference_;
  const T* lo_;
  const T* hi_;
  std::vector<std::uint32_t>& found_;
};

}  // namespace kdspace::detail
