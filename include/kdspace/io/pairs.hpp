// Writing .pairs files: the pairs of points within a distance (`kdspace pairs`).
//
//   .pairs  uint64 M (little-endian), then M records of uint32 a, uint32 b, sorted by (a, b)
//
// The file is written to a temporary file in the same folder and renamed over the path at the end,
// so a reader never sees a half-written file, and a failure leaves any earlier file in place.
#pragma once

#include <string>
#include <vector>

#include "kdspace/index_pair.hpp"

namespace kdspace::io {

/// Writes the pairs as they are (the caller sorts them). Throws Error "PATH: what went wrong".
void write_pairs(const std::string& path, const std::vector<IndexPair>& pairs);

}  // namespace kdspace::io
