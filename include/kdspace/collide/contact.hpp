// First contact of a moving box with the boxes of a BoxTree: when a box moving along a straight line
// first touches a box of the scene, and which box.
//
// The Minkowski view: the moving box M, displaced by t * motion, touches the scene box S exactly
// when the point t * motion lies in S grown by M, the box [S.lo - M.hi, S.hi - M.lo] (the Minkowski
// sum of S and -M). So first contact is a ray, from the origin along the motion, shot at the grown
// boxes; and a split plane at p becomes the slab [p - M.hi, p - M.lo], which the traversal uses in
// place of the plane. Nothing is grown or rebuilt: the tree is the scene's.
//
// Exactness. The grown box is never formed (its half extents would be rounded). Each contact time
// is computed in double from the float coordinates, (S.lo[a] - M.hi[a]) * (1 / motion[a]) and
// (S.hi[a] - M.lo[a]) * (1 / motion[a]) with the reciprocal precomputed (detail::contact_window); a
// difference of two floats keeps its sign in double, so contact at t = 0 happens exactly when the
// boxes overlap (closed: touching counts), as overlapping() decides. Ties at equal t (in double) go
// to the smaller box index, as for rays. The traversal widens its slabs by a relative margin far
// above double rounding, so it never skips a leaf whose box would win: the answer equals
// brute_force_first_contact bit for bit. The reported t is the double rounded to float.
#pragma once

#include <cstddef>
#include <limits>
#include <vector>

#include "kdspace/box.hpp"
#include "kdspace/boxes/box_tree.hpp"
#include "kdspace/collide/overlap.hpp"
#include "kdspace/rays/ray.hpp"

namespace kdspace {

/// The answer of first_contact: the box touched first (its index, -1 for none) and the time t (in
/// multiples of the motion; +inf for none). The record of a ray's Hit.
using Contact = Hit;

/// A box and the displacement it moves by over t in [0, 1]: at time t it is box + t * motion.
struct MovingBox {
  Box3f box;
  Vec3f motion{};
};

/// The first t in [0, t_max] at which `moving` + t * motion touches a box of the tree, and that box
/// (equal t: the smaller index); Contact{} (box -1) when none does. A box that already overlaps
/// `moving` is touched at t = 0. The motion may be zero (then: is anything touched now?).
/// Throws Error for a moving box that is not finite or has min > max, a motion that is not finite,
/// and a t_max that is negative or NaN (+inf is allowed).
Contact first_contact(const BoxTree& tree, const Box3f& moving, const Vec3f& motion,
                      float t_max = std::numeric_limits<float>::infinity(), CollideStats* stats = nullptr);

/// first_contact for moving[0 .. n), each over [0, t_max], on `threads` threads (0 = all hardware
/// threads); the same answers as one at a time. Throws Error naming the first bad one, 1-based
/// ("moving box 3: motion y is nan").
std::vector<Contact> first_contact_batch(const BoxTree& tree, const MovingBox* moving, std::size_t n,
                                         float t_max = std::numeric_limits<float>::infinity(),
                                         unsigned threads = 1, CollideStats* stats = nullptr);
inline std::vector<Contact> first_contact_batch(const BoxTree& tree, const std::vector<MovingBox>& moving,
                                                float t_max = std::numeric_limits<float>::infinity(),
                                                unsigned threads = 1, CollideStats* stats = nullptr) {
  return first_contact_batch(tree, moving.data(), moving.size(), t_max, threads, stats);
}

}  // namespace kdspace
