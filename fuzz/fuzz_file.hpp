// What every reader's fuzz target shares: the readers take paths, so each input is written to a file
// of its own (in /dev/shm where there is one, else the temporary folder), with the extension that
// chooses the format, and read back through the public reader; kdspace::Error (a clear message) is
// the expected outcome for bad bytes, anything else (a crash, a sanitizer report, another exception,
// a hang) is a finding.
#pragma once

#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <string>

#include "kdspace/error.hpp"

namespace kdspace_fuzz {

/// A file of this process for inputs, named with `extension` (".fvecs").
inline std::string scratch_file(const std::string& extension) {
  const std::filesystem::path dir = std::filesystem::is_directory("/dev/shm")
                                        ? std::filesystem::path("/dev/shm")
                                        : std::filesystem::temp_directory_path();
  return (dir / ("kdspace-fuzz-" + std::to_string(::getpid()) + extension)).string();
}

/// Writes the input to the file (replacing it) and runs read(path); kdspace::Error is swallowed.
template <class Read>
void with_file(const std::uint8_t* data, std::size_t size, const std::string& extension, Read read) {
  static const std::string path = scratch_file(extension);
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (!f) std::abort();
  if (size > 0 && std::fwrite(data, 1, size, f) != size) std::abort();
  std::fclose(f);
  try {
    read(path);
  } catch (const kdspace::Error&) {
  }
}

}  // namespace kdspace_fuzz
