// Ray streams: many incoherent rays through the BoxTree together (trace_stream.cpp).
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <new>
#include <utility>
#include <vector>

#include "kdspace/boxes/box_tree.hpp"
#include "kdspace/rays/ray.hpp"

namespace kdspace::detail {

/// Allocates like std::allocator but leaves new elements of a trivial type uninitialized: a
/// stream writes every element of its arrays before it reads it, and a std::vector grown by
/// resize() would first fill them with zeros (a batch's scratch is new with every batch).
template <class T>
struct UninitializedAllocator : std::allocator<T> {
  template <class U>
  struct rebind {
    using other = UninitializedAllocator<U>;
  };
  UninitializedAllocator() = default;
  template <class U>
  UninitializedAllocator(const UninitializedAllocator<U>&) noexcept {}
  template <class U>
  void construct(U* p) noexcept {
    ::new (static_cast<void*>(p)) U;  // default-initialized: no value for a trivial type
  }
  template <class U, class... Args>
  void construct(U* p, Args&&... args) {
    ::new (static_cast<void*>(p)) U(std::forward<Args>(args)...);
  }
};

template <class T>
using ScratchArray = std::vector<T, UninitializedAllocator<T>>;

/// Working memory of trace_stream, kept between calls by a batch's worker so that its streams do
/// not allocate.
struct StreamScratch {
  ScratchArray<std::uint32_t> keys;                ///< per ray of a batch's chunk: its direction's signs
  ScratchArray<std::uint32_t> ids;                 ///< the chunk's rays for the streams, octant after octant
  ScratchArray<float> origin, direction, inverse;  ///< by axis, then by ray: [axis * capacity + ray]
  ScratchArray<double> best_t;                     ///< per ray
  ScratchArray<float> best_bound;       ///< per ray: best_t rounded up; -inf once an any-hit ray is done
  ScratchArray<std::int32_t> best_box;  ///< per ray
  ScratchArray<std::uint32_t> ray_of;   ///< per ray: its position in the batch
  ScratchArray<std::uint32_t> slot;     ///< per entry: the ray
  ScratchArray<float> enter, exit;      ///< per entry: the ray's interval in the entry's cell
  struct Task {
    std::uint32_t node;
    std::uint32_t begin, end;  ///< its entries
  };
  ScratchArray<Task> tasks;
  ScratchArray<std::uint32_t> leaf_rays;  ///< the rays entering a leaf (with 8 of slack)
};

/// The fewest rays a stream keeps together at a node; below it each ray walks the node's subtree
/// alone (walk.hpp).
inline constexpr std::size_t stream_min_rays = 4;

/// Traces rays[ids[0 .. n)] through `tree` over `range`, writing hits[ids[i]] and adding to `stats`
/// exactly what single traces would (hits and counts). Each hits[ids[i]] must hold Hit{} on entry:
/// a ray that misses the scene's bounds is left so. The rays must all run the same way (the same
/// direction signs: detail::packet_key equal and below 8), and the tree must hold boxes within the
/// float range: the conditions of the float traversal.
template <bool AnyHit>
void trace_stream(const BoxTree& tree, const Ray* rays, const std::uint32_t* ids, std::size_t n, RayRange range,
                  Hit* hits, RayStats& stats, StreamScratch& scratch);

}  // namespace kdspace::detail
