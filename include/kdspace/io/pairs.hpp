// Reading and writing .pairs files: the answers of `kdspace overlaps` (overlapping boxes) and of
// `kdspace pairs` (points within a distance).
//
//   .pairs  uint64 M (little-endian), then M records of uint32 a, uint32 b, sorted by (a, b), each
//           pair once. For one set a < b; for two sets a indexes the first and b the second.
//
// The reader checks the header against the file size before allocating anything, then the order:
// every problem throws kdspace::Error whose message starts with the path and, for a bad record, its
// 1-based position ("found.pairs: pair 12: (5, 3) is not after (5, 7)", "found.pairs: truncated:
// header says 100 pairs (808 bytes), file has 500 bytes"). A file of zero bytes is an error; a
// header with count 0 is a valid, empty file.
#pragma once

#include <cstddef>
#include <string>
#include <vector>

#include "kdspace/index_pair.hpp"

namespace kdspace::io {

/// The pairs of a .pairs file, checked to be strictly ascending by (a, b).
std::vector<IndexPair> read_pairs(const std::string& path);

/// Writes the pairs as they are (unchecked, so that tests can make bad files), atomically: into a
/// temporary file in the same folder, renamed to `path` once complete; a failed write leaves no
/// file and an older file of that name as it was.
void write_pairs(const std::string& path, const IndexPair* pairs, std::size_t m);
void write_pairs(const std::string& path, const std::vector<IndexPair>& pairs);

}  // namespace kdspace::io
