// Fuzz target of one vector file reader (kdspace/io/vectors.hpp): the format is chosen at build time
// by KDSPACE_FUZZ_EXTENSION (".fvecs", ".ivecs", ".bvecs", ".csv", ".npy"); fuzz/CMakeLists.txt makes
// one target per format. Every point reader (float, double, bytes) reads the input, and for the vecs
// formats the ragged-row readers too; what is read must be what the reader promises.
#include <cmath>
#include <cstdint>
#include <cstdlib>

#include "fuzz_file.hpp"
#include "kdspace/io/vectors.hpp"

namespace {

template <class T>
void read_points(const std::string& path) {
  try {
    const kdspace::io::Matrix<T> m = kdspace::io::read_points<T>(path);
    // The promise: at least one row, every row as long as the first, every value finite.
    if (m.rows == 0 || m.cols == 0 || m.data.size() != m.rows * m.cols) std::abort();
    for (T v : m.data)
      if constexpr (!std::is_integral_v<T>) {
        if (!std::isfinite(v)) std::abort();
      }
  } catch (const kdspace::Error&) {
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string extension = KDSPACE_FUZZ_EXTENSION;
  kdspace_fuzz::with_file(data, size, extension, [&](const std::string& path) {
    read_points<float>(path);
    read_points<double>(path);
    read_points<std::uint8_t>(path);
    (void)kdspace::io::stores_double(path);
    if (extension == ".ivecs") (void)kdspace::io::read_ivecs_rows(path);
    if (extension == ".fvecs") (void)kdspace::io::read_fvecs_rows(path);
  });
  return 0;
}
