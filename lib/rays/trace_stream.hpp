// Ray streams: many incoherent rays through the BoxTree together (trace_stream.cpp).
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "kdspace/boxes/box_tree.hpp"
#include "kdspace/rays/ray.hpp"

namespace kdspace::detail {

/// Working memory of trace_stream, kept between calls by a batch's worker so that its streams do
/// not allocate.
struct StreamScratch {
  std::vector<std::uint32_t> keys;         ///< per ray of a batch's chunk: its direction's signs
  std::vector<std::uint32_t> ids;          ///< the chunk's rays for the streams, octant after octant
  std::vector<float> origin, direction, inverse;  ///< by axis, then by ray: [axis * capacity + ray]
  std::vector<double> best_t;              ///< per ray
  std::vector<float> best_bound;           ///< per ray: best_t rounded up; -inf once an any-hit ray is done
  std::vector<std::int32_t> best_box;      ///< per ray
  std::vector<std::uint32_t> ray_of;       ///< per ray: its position in the batch
  std::vector<std::uint32_t> slot;         ///< per entry: the ray
  std::vector<float> enter, exit;          ///< per entry: the ray's interval in the entry's cell
  struct Task {
    std::uint32_t node;
    std::uint32_t begin, end;  ///< its entries
  };
  std::vector<Task> tasks;
  std::vector<std::uint32_t> leaf_rays;    ///< the rays entering a leaf (with 8 of slack)
};

/// The fewest rays a stream keeps together at a node; below it each ray walks the node's subtree
/// alone (walk.hpp).
inline constexpr std::size_t stream_min_rays = 4;

/// Traces rays[ids[0 .. n)] through `tree` over `range`, writing hits[ids[i]] and adding to `stats`
/// exactly what single traces would (hits and counts). The rays must all run the same way (the same
/// direction signs: detail::packet_key equal and below 8), and the tree must hold boxes within the
/// float range: the conditions of the float traversal.
template <bool AnyHit>
void trace_stream(const BoxTree& tree, const Ray* rays, const std::uint32_t* ids, std::size_t n, RayRange range,
                  Hit* hits, RayStats& stats, StreamScratch& scratch);

}  // namespace kdspace::detail
