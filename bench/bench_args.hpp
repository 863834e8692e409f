// Command-line helpers shared by the benchmarks: comma (or other) separated lists and whole counts.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdlib>
#include <optional>
#include <string>
#include <vector>

namespace kdspace::bench {

/// The non-empty items of `list` between separators ("1e4,,1e5" gives "1e4" and "1e5").
inline std::vector<std::string> split_list(const std::string& list, char separator = ',') {
  std::vector<std::string> items;
  std::size_t pos = 0;
  while (pos <= list.size()) {
    const std::size_t end = std::min(list.find(separator, pos), list.size());
    if (end > pos) items.push_back(list.substr(pos, end - pos));
    pos = end + 1;
  }
  return items;
}

/// The whole number in [1, largest] that `text` spells (1e5 is accepted); none when it is not one.
inline std::optional<std::size_t> positive_count(const std::string& text, double largest) {
  char* end = nullptr;
  const double value = std::strtod(text.c_str(), &end);
  if (end == text.c_str() || *end != '\0' || !(value >= 1) || value > largest || value != std::floor(value))
    return std::nullopt;
  return static_cast<std::size_t>(value);
}

}  // namespace kdspace::bench
