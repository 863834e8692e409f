// libFuzzer target: a point file read in parts (io::plan_part / io::read_part, as the ranks of
// kdspace-mpi read it) equals the file read whole by io::read_points, value for value, or fails with
// the same message. The first input byte picks the format and the number of parts (1 to 7); the
// rest is the file. Build and run: fuzz/run.sh.
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <fstream>
#include <string>

#include "../tests/read_in_parts.hpp"
#include "kdspace/io/vectors.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 1) return 0;
  static const char* const extensions[] = {".csv", ".fvecs", ".npy", ".bvecs", ".ivecs"};
  const std::size_t parts = 1 + (data[0] / 5) % 7;
  static const std::string stem = "/tmp/kdspace-fuzz-read-part-" + std::to_string(::getpid());
  const std::string path = stem + extensions[data[0] % 5];
  {
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out.write(reinterpret_cast<const char*>(data + 1), static_cast<std::streamsize>(size - 1));
  }
  const std::string whole =
      kdspace_test::outcome<float>([&] { return kdspace::io::read_points<float>(path); });
  const std::string in_parts =
      kdspace_test::outcome<float>([&] { return kdspace_test::read_in_parts<float>(path, parts); });
  std::remove(path.c_str());
  if (whole != in_parts) {
    std::fprintf(stderr, "read whole: %s\nin %zu parts: %s\n", whole.substr(0, 300).c_str(), parts,
                 in_parts.substr(0, 300).c_str());
    __builtin_trap();
  }
  return 0;
}
