// Fuzz target of the .pairs reader (kdspace/io/pairs.hpp, written by `kdspace pairs` and
// `kdspace overlaps`): what is read must be what the reader promises, the pairs in strict (a, b)
// order and as many as the file's size holds.
#include <cstdint>
#include <cstdlib>

#include "fuzz_file.hpp"
#include "kdspace/io/pairs.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  kdspace_fuzz::with_file(data, size, KDSPACE_FUZZ_EXTENSION, [&](const std::string& path) {
    const auto pairs = kdspace::io::read_pairs(path);
    if (8 + 8 * pairs.size() != size) std::abort();
    for (std::size_t i = 1; i < pairs.size(); ++i)
      if (!(pairs[i - 1] < pairs[i])) std::abort();
  });
  return 0;
}
