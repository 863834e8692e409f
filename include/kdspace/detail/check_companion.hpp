// CheckCompanion: work a loader runs beside the structural check of a tree it loads, on the check's
// own threads: the checksums of the file the tree's arrays come from.
#pragma once

#include <cstddef>
#include <vector>

namespace kdspace::detail {

/// The check reads some of the tree's arrays in pieces, each piece front to back by one thread at a
/// time, and tells the companion before it reads them, so that the companion can checksum them just
/// before (each byte then comes from memory once). The arrays are numbered by the check (a point
/// tree's rows and nodes, a box tree's references and boxes: the constants beside each check).
class CheckCompanion {
 public:
  virtual ~CheckCompanion() = default;
  /// Before the pieces are read: piece p of `array` is items [starts[p], starts[p + 1]), the last one
  /// up to the array's end (starts ascending, the first 0). Until then an array is one piece.
  virtual void pieces(std::size_t array, const std::vector<std::size_t>& starts) = 0;
  /// Piece `piece` of `array` is about to be read up to item `end`; returns the item up to which it is
  /// now ready (at least `end` within the piece), so that the reader calls again only past it.
  virtual std::size_t ready(std::size_t array, std::size_t piece, std::size_t end) = 0;
  /// A thread done with its share of the check takes a share of the companion's own work.
  virtual void help() = 0;
};

}  // namespace kdspace::detail
