// .pairs files (see kdspace/io/pairs.hpp).
#include "kdspace/io/pairs.hpp"

#include <string>

#include "record_file.hpp"

namespace kdspace::io {

static_assert(sizeof(IndexPair) == 8, "a pair is two packed uint32, as in the file");

namespace {

std::string text(const IndexPair& p) {
  return "(" + std::to_string(p.a) + ", " + std::to_string(p.b) + ")";
}

}  // namespace

std::vector<IndexPair> read_pairs(const std::string& path) {
  std::vector<IndexPair> pairs = detail::read_records<IndexPair>(path, "pairs");
  for (std::size_t i = 1; i < pairs.size(); ++i)
    if (!(pairs[i - 1] < pairs[i]))
      detail::fail(path, "pair " + std::to_string(i + 1) + ": " + text(pairs[i]) + " is not after " +
                             text(pairs[i - 1]) + " (pairs must be sorted by (a, b), each once)");
  return pairs;
}

void write_pairs(const std::string& path, const IndexPair* pairs, std::size_t m) {
  detail::write_records(path, pairs, m);
}

void write_pairs(const std::string& path, const std::vector<IndexPair>& pairs) {
  detail::write_records(path, pairs.data(), pairs.size());
}

}  // namespace kdspace::io
