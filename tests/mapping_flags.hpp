// The flags the kernel shows for a mapping of this process (Linux's /proc/self/smaps), for tests that
// check how an array or a file is mapped.
#pragma once

#include <cstdint>
#include <fstream>
#include <sstream>
#include <string>

namespace kdspace_test {

/// The VmFlags of the mapping that holds `address` in /proc/self/smaps ("" where none is found).
inline std::string mapping_flags(const void* address) {
  const auto at = reinterpret_cast<std::uintptr_t>(address);
  std::ifstream smaps("/proc/self/smaps");
  std::string line;
  bool inside = false;
  while (std::getline(smaps, line)) {
    std::istringstream fields(line);
    std::string range;
    fields >> range;
    const auto dash = range.find('-');
    if (dash != std::string::npos && range.find(':') == std::string::npos && line.find(':') > dash) {
      const auto lo = std::stoull(range.substr(0, dash), nullptr, 16);
      const auto hi = std::stoull(range.substr(dash + 1), nullptr, 16);
      inside = lo <= at && at < hi;
    } else if (inside && line.rfind("VmFlags:", 0) == 0) {
      return line.substr(8) + " ";
    }
  }
  return "";
}

inline bool advised_for_huge_pages(const void* address) {
  return mapping_flags(address).find(" hg ") != std::string::npos;
}

}  // namespace kdspace_test
