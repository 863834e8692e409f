// IndexPair: two indices, the record of a .pairs file (pairs of points within a distance, pairs of
// overlapping boxes).
#pragma once

#include <cstdint>

namespace kdspace {

/// For one set, two of its indices with a < b; for two sets, a indexes the first and b the second.
struct IndexPair {
  std::uint32_t a;
  std::uint32_t b;

  friend bool operator==(const IndexPair& x, const IndexPair& y) { return x.a == y.a && x.b == y.b; }
  friend bool operator!=(const IndexPair& x, const IndexPair& y) { return !(x == y); }
  /// The order of a .pairs file: by a, then by b.
  friend bool operator<(const IndexPair& x, const IndexPair& y) { return x.a < y.a || (x.a == y.a && x.b < y.b); }
};

}  // namespace kdspace
