"""kdspace.BoxTree: closest and any hit against a brute-force slab test, overlapping pairs against
all pairs, errors naming the box or ray."""

import numpy as np
import pytest

import kdspace


def scene(n, seed):
    rng = np.random.default_rng(seed)
    lo = rng.uniform(0, 10, (n, 3))
    return np.concatenate([lo, lo + rng.uniform(0.05, 1.5, (n, 3))], axis=1).astype(np.float32)


def slab_hits(boxes, origin, direction, t_min, t_max):
    """t of every box the ray meets within [t_min, t_max] (inf: missed), in double."""
    o, d = origin.astype(np.float64), direction.astype(np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = (boxes[:, :3] - o) / d
        t2 = (boxes[:, 3:] - o) / d
    near = np.where(np.isnan(t1), -np.inf, np.minimum(t1, t2))
    far = np.where(np.isnan(t2), np.inf, np.maximum(t1, t2))
    inside = (d == 0) & ((o < boxes[:, :3]) | (o > boxes[:, 3:]))
    enter = np.maximum(near.max(axis=1), t_min)
    leave = np.minimum(far.min(axis=1), t_max)
    hit = (enter <= leave) & ~inside.any(axis=1)
    return np.where(hit, enter, np.inf)


@pytest.mark.parametrize("build", ["sah_nlogn", "sah", "median"])
def test_closest_hit_equals_brute_force(build):
    boxes = scene(400, 1)
    rng = np.random.default_rng(2)
    origins = rng.uniform(-2, 12, (300, 3)).astype(np.float32)
    directions = rng.normal(0, 1, (300, 3)).astype(np.float32)
    tree = kdspace.BoxTree(boxes, build=build)
    hit, t = tree.closest_hit(origins, directions, workers=-1)
    for r in range(300):
        ts = slab_hits(boxes.astype(np.float64), origins[r], directions[r], 0.0, np.inf)
        if np.isinf(ts.min()):
            assert hit[r] == -1 and np.isinf(t[r])
        else:
            assert ts[hit[r]] <= ts.min() * (1 + 1e-5) + 1e-5  # the closest, up to float rounding
            np.testing.assert_allclose(t[r], ts.min(), rtol=1e-5, atol=1e-5)


def test_any_hit_finds_a_box_within_the_interval_or_none():
    boxes = scene(300, 3)
    tree = kdspace.BoxTree(boxes)
    origins = np.tile(np.float32([-1, 5, 5]), (50, 1))
    directions = np.random.default_rng(4).normal(0, 1, (50, 3)).astype(np.float32)
    directions[:, 0] = np.abs(directions[:, 0]) + 0.5
    closest, t_closest = tree.closest_hit(origins, directions, t_max=6.0)
    any_box, t_any = tree.any_hit(origins, directions, t_max=6.0)
    np.testing.assert_array_equal(any_box == -1, closest == -1)
    for r in np.flatnonzero(any_box >= 0):
        ts = slab_hits(boxes.astype(np.float64), origins[r], directions[r], 0.0, 6.0)
        assert np.isfinite(ts[any_box[r]]) and t_any[r] >= t_closest[r]


def test_one_ray_gives_scalars_and_t_is_in_multiples_of_the_direction():
    tree = kdspace.BoxTree([[0, 0, 0, 1, 1, 1]])
    assert tree.closest_hit([-2, 0.5, 0.5], [2, 0, 0]) == (0, 1.0)
    assert tree.closest_hit([-2, 0.5, 0.5], [-1, 0, 0]) == (-1, float("inf"))
    assert tree.closest_hit([0.5, 0.5, 0.5], [0, 0, 1], t_min=0.25) == (0, 0.25)  # starting inside


def test_overlapping_pairs_equal_all_pairs():
    a, b = scene(250, 5), scene(150, 6)

    def meets(x, y):
        return bool((x[:3] <= y[3:]).all() and (y[:3] <= x[3:]).all())

    within = {(i, j) for i in range(250) for j in range(i + 1, 250) if meets(a[i], a[j])}
    between = {(i, j) for i in range(250) for j in range(150) if meets(a[i], b[j])}
    tree = kdspace.BoxTree(a)
    assert set(map(tuple, tree.overlaps().tolist())) == within
    pairs = tree.overlaps(kdspace.BoxTree(b))
    assert set(map(tuple, pairs.tolist())) == between
    assert pairs.tolist() == sorted(pairs.tolist())
    assert tree.overlaps(b).tolist() == pairs.tolist()  # boxes as an array get a tree of their own
    binned = kdspace.BoxTree(a, build="binned")
    assert binned.overlaps(workers=3).tolist() == [list(p) for p in sorted(within)]
    assert kdspace.overlapping_pairs(a, b, workers=2).tolist() == pairs.tolist()
    assert kdspace.overlapping_pairs(np.zeros((0, 6), np.float32)).shape == (0, 2)
    touching = np.float32([[0, 0, 0, 1, 1, 1], [1, 0, 0, 2, 1, 1]])  # closed boxes: a shared face counts
    assert kdspace.overlapping_pairs(touching).tolist() == [[0, 1]]


def test_bad_boxes_and_rays_are_named():
    with pytest.raises(ValueError, match="box 2: min x 3 > max x 1"):
        kdspace.BoxTree([[0, 0, 0, 1, 1, 1], [3, 0, 0, 1, 1, 1]])
    tree = kdspace.BoxTree([[0, 0, 0, 1, 1, 1]])
    with pytest.raises(ValueError, match="ray 2: direction is zero"):
        tree.closest_hit([[0, 0, 0], [0, 0, 0]], [[1, 0, 0], [0, 0, 0]])
    with pytest.raises(ValueError, match=r"shape \(n, 6\)"):
        kdspace.BoxTree(np.zeros((3, 5)))
