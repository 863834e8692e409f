// libFuzzer target for io::read_pairs: any bytes as a .pairs file must give the pairs, sorted, or a
// kdspace::Error; never a crash, a hang or an allocation beyond the file's size. Build and run:
// fuzz/run.sh.
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "kdspace/error.hpp"
#include "kdspace/io/pairs.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const std::string path = "/tmp/kdspace-fuzz-pairs-" + std::to_string(::getpid()) + ".pairs";
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (!f) return 0;
  if (size > 0) std::fwrite(data, 1, size, f);
  std::fclose(f);
  try {
    const auto pairs = kdspace::io::read_pairs(path);
    if (8 + 8 * pairs.size() != size) std::abort();  // the count must match the file
    for (std::size_t i = 1; i < pairs.size(); ++i)
      if (!(pairs[i - 1] < pairs[i])) std::abort();  // the reader promised strict order
  } catch (const kdspace::Error&) {
  }
  return 0;
}
