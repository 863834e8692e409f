// CheckCompanion: work a loader runs beside the structural check of a tree it loads, on the check's
// own two threads: the checksums of the file the tree's arrays come from.
#pragma once

#include <cstddef>

namespace kdspace::detail {

/// The check reads some of the tree's arrays in two ranges, one a thread (walks 0 and 1), front to
/// back, and tells the companion before it reads them, so that the companion can checksum them just
/// before (each byte then comes from memory once). The arrays are numbered by the check (a point
/// tree's rows and nodes, a box tree's references and boxes: the constants beside each check).
class CheckCompanion {
 public:
  virtual ~CheckCompanion() = default;
  /// Before the walks start: walk 1 reads items [first, end) of `array`, walk 0 those before.
  virtual void split(std::size_t array, std::size_t first) = 0;
  /// Walk 0 or 1 (one thread each) is about to read its items of `array` up to `end`; returns the
  /// item up to which they are now ready (at least `end` within the walk's range), so that the walk
  /// calls again only past it.
  virtual std::size_t ready(std::size_t array, int walk, std::size_t end) = 0;
  /// A thread done with its share of the check takes a share of the companion's own work.
  virtual void help() = 0;
};

}  // namespace kdspace::detail
