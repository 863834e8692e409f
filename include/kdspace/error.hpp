// kdspace::Error — the one exception type the library throws.
#pragma once

#include <stdexcept>
#include <string>

namespace kdspace {

/// Thrown for bad input (NaN coordinates, mismatched dimensions, k out of range, malformed files).
/// The message says what was wrong and, where it applies, where: "FILE: row R: what".
class Error : public std::runtime_error {
 public:
  explicit Error(const std::string& what) : std::runtime_error(what) {}
};

}  // namespace kdspace
