"""kdspace.KDTree: exact answers against brute force and against SciPy's cKDTree, kdspace's own
behaviour (float32 kept, NaN rows, tie rule, errors, threads, the GIL), and what SciPy's test file
does not cover."""

import pickle
import sys
import threading
import time

import numpy as np
import pytest

import kdspace

scipy_spatial = pytest.importorskip("scipy.spatial")


# ---- data -----------------------------------------------------------------------------------------

def points(shape, n, dim, seed, dtype=np.float64):
    rng = np.random.default_rng(seed)
    if shape == "uniform":
        x = rng.uniform(-1, 1, (n, dim))
    elif shape == "clustered":
        centres = rng.uniform(-10, 10, (6, dim))
        x = centres[rng.integers(0, 6, n)] + rng.normal(0, 0.05, (n, dim)) * rng.choice([0.01, 0.3], (n, 1))
    elif shape == "duplicates":
        x = rng.uniform(-1, 1, (12, dim))[rng.integers(0, 12, n)]
    elif shape == "grid":
        x = rng.integers(0, 5, (n, dim)).astype(np.float64)
    elif shape == "identical":
        x = np.tile(rng.uniform(-1, 1, dim), (n, 1))
    else:
        raise ValueError(shape)
    return x.astype(dtype)


SHAPES = ["uniform", "clustered", "duplicates", "grid", "identical"]


def minkowski(a, b, p):
    diff = np.abs(a[..., None, :].astype(np.float64) - b[None, ...].astype(np.float64))
    if np.isinf(p):
        return diff.max(axis=-1)
    if p == 1:
        return diff.sum(axis=-1)
    if p == 2:
        return np.sqrt((diff * diff).sum(axis=-1))
    return (diff ** p).sum(axis=-1) ** (1.0 / p)


def brute_knn(data, queries, k, p):
    """k nearest by (distance, row), with distances in float64."""
    dist = minkowski(queries, data, p)
    order = np.lexsort((np.broadcast_to(np.arange(len(data)), dist.shape), dist), axis=-1)[:, :k]
    return np.take_along_axis(dist, order, axis=1), order


def assert_same_neighbours(d, i, want_d, want_i, rtol, data=None, queries=None, p=2):
    """Distances within rtol; rows equal except at near-ties: a differing row must be a distinct row
    whose own distance (from data and queries) is within rtol of the wanted one."""
    np.testing.assert_allclose(d, want_d, rtol=rtol, atol=0)
    for q, r in zip(*np.nonzero(i != want_i)):
        assert data is not None, f"query {q} rank {r}: row {i[q, r]} instead of {want_i[q, r]}"
        own = minkowski(queries[q:q + 1], data[i[q, r]:i[q, r] + 1], p)[0, 0]
        assert np.isclose(own, want_d[q, r], rtol=rtol, atol=0), (q, r)
        assert len(set(i[q].tolist())) == len(i[q])


# ---- exact answers ---------------------------------------------------------------------------------

@pytest.mark.parametrize("shape", SHAPES)
@pytest.mark.parametrize("dim", [1, 2, 3, 5, 12])
def test_knn_equals_brute_force_for_every_p(shape, dim):
    data = points(shape, 300, dim, seed=dim)
    if shape == "grid":  # integer queries: every distance exact, so ties are exact
        queries = np.random.default_rng(99).integers(-1, 6, (30, dim)).astype(np.float64)
    else:
        queries = np.concatenate([points("uniform", 20, dim, seed=99), data[:10] + 0.0])
    tree = kdspace.KDTree(data, leafsize=4)
    for p in [1, 2, 3.5, np.inf]:
        for k in [1, 7, 300]:
            d, i = tree.query(queries, k=k, p=p)
            want_d, want_i = brute_knn(data, queries, k, p)
            if k == 1:
                d, i = d[:, None], i[:, None]
            if shape == "grid" and p in (1, 2, np.inf):
                # Exact distances: ties are exact and go to the smaller row.
                np.testing.assert_array_equal(i, want_i)
                np.testing.assert_array_equal(d, want_d)
            else:
                assert_same_neighbours(d, i, want_d, want_i, 1e-12, data, queries, p)


def test_ties_go_to_the_smaller_row():
    data = np.array([[1.0, 0], [0, 1], [-1, 0], [0, -1], [0, 0]])
    tree = kdspace.KDTree(data, leafsize=1)
    d, i = tree.query([0, 0], k=5)
    np.testing.assert_array_equal(i, [4, 0, 1, 2, 3])
    np.testing.assert_array_equal(d, [0, 1, 1, 1, 1])
    assert tree.query([0, 0], k=[3])[1].tolist() == [1]


def test_distance_upper_bound_is_strict_as_in_scipy():
    grid = np.stack(np.meshgrid(np.arange(5.0), np.arange(5.0)), axis=-1).reshape(-1, 2)
    ours = kdspace.KDTree(grid).query(grid, k=6, distance_upper_bound=1.0)
    theirs = scipy_spatial.cKDTree(grid).query(grid, k=6, distance_upper_bound=1.0)
    np.testing.assert_array_equal(ours[0], theirs[0])  # only the point itself: neighbours at 1 are out
    np.testing.assert_array_equal(ours[1], theirs[1])
    assert (ours[1][:, 1:] == len(grid)).all()


def test_k_above_n_pads_with_inf_and_n():
    data = points("uniform", 5, 3, 1)
    d, i = kdspace.KDTree(data).query(np.zeros(3), k=8)
    assert np.isinf(d[5:]).all() and (i[5:] == 5).all()
    assert np.isfinite(d[:5]).all() and sorted(i[:5]) == list(range(5))


def test_large_p_is_computed_in_double_even_for_float32_data():
    data = points("uniform", 400, 3, 4, np.float32) * 900
    tree = kdspace.KDTree(data)
    queries = data[:30]
    d, i = tree.query(queries, k=5, p=60)
    want_d, want_i = brute_knn(data, queries, 5, 60)
    assert d.dtype == np.float32
    assert_same_neighbours(d.astype(np.float64), i, want_d, want_i, 1e-6, data, queries, 60)


@pytest.mark.parametrize("dtypes", [(np.float64, np.float64), (np.float32, np.float32), (np.float32, np.float64)])
@pytest.mark.parametrize("p", [1, 2, 3.5, np.inf])
@pytest.mark.parametrize("shape", SHAPES)
def test_pair_methods_equal_brute_force(shape, p, dtypes):
    # p = 1, 2, inf with one dtype go through the dual-tree joins, the rest through single-tree
    # queries; both must find the pairs within r (up to rounding at r) and nothing else.
    a, b = points(shape, 150, 3, 11, dtypes[0]), points(shape, 120, 3, 12, dtypes[1])
    a[[4, 90]] = np.nan  # never paired
    tree_a, tree_b = kdspace.KDTree(a), kdspace.KDTree(b)
    ab, aa = minkowski(a, b, p), minkowski(a, a, p)
    wa, wb = np.random.default_rng(3).random((2, 150))[0], np.random.default_rng(4).random(120)

    def check(found, dist, r):
        assert not (found & ~(dist <= r * (1 + 1e-6))).any(), "a pair beyond r"
        assert not (~found & (dist <= r * (1 - 1e-6))).any(), "a pair within r missing"

    for r in [0.0, 0.3, 1.0, 2.0]:
        lists = tree_a.query_ball_tree(tree_b, r, p=p)
        found = np.zeros(ab.shape, dtype=bool)
        for i, row in enumerate(lists):
            assert row == sorted(row)
            found[i, row] = True
        check(found, ab, r)
        assert tree_a.count_neighbors(tree_b, r, p=p) == found.sum()
        np.testing.assert_allclose(tree_a.count_neighbors(tree_b, r, p=p, weights=(wa, wb)),
                                   (wa[:, None] * wb[None, :])[found].sum(), rtol=1e-9, atol=1e-12)
        matrix = tree_a.sparse_distance_matrix(tree_b, r, p=p, output_type="dict")
        assert set(matrix) == set(zip(*np.nonzero(found)))
        np.testing.assert_allclose([matrix[key] for key in sorted(matrix)],
                                   [ab[key] for key in sorted(matrix)], rtol=1e-5, atol=1e-6)
        pairs = tree_a.query_pairs(r, p=p, output_type="ndarray")
        found = np.zeros(aa.shape, dtype=bool)
        found[pairs[:, 0], pairs[:, 1]] = True
        assert (pairs[:, 0] < pairs[:, 1]).all() and len(np.unique(pairs, axis=0)) == len(pairs)
        check(found, np.where(np.tri(len(a), dtype=bool), np.inf, aa), r)
    radii = [2.0, 0.0, 1.0, 1.0, 0.3]
    totals = tree_a.count_neighbors(tree_b, radii, p=p)
    np.testing.assert_array_equal(totals, [tree_a.count_neighbors(tree_b, r, p=p) for r in radii])
    per_bin = tree_a.count_neighbors(tree_b, sorted(radii), p=p, cumulative=False)
    np.testing.assert_array_equal(np.cumsum(per_bin), np.sort(totals))


# ---- against SciPy's cKDTree ---------------------------------------------------------------------------

@pytest.mark.parametrize("boxsize", [None, 1.0])
@pytest.mark.parametrize("p", [1, 2, 3, np.inf])
def test_every_method_agrees_with_scipy(p, boxsize):
    rng = np.random.default_rng(7)
    a, b = rng.random((300, 3)), rng.random((200, 3))
    ours_a, ours_b = kdspace.KDTree(a, boxsize=boxsize), kdspace.KDTree(b, boxsize=boxsize)
    theirs_a, theirs_b = scipy_spatial.cKDTree(a, boxsize=boxsize), scipy_spatial.cKDTree(b, boxsize=boxsize)
    q = rng.random((50, 3)) * 1.2 - 0.1 if boxsize is None else rng.random((50, 3)) * 3 - 1
    for k in [1, [1, 4], 6]:
        for ub in [np.inf, 0.15]:
            d, i = ours_a.query(q, k=k, p=p, distance_upper_bound=ub)
            d2, i2 = theirs_a.query(q, k=k, p=p, distance_upper_bound=ub)
            np.testing.assert_allclose(d, d2, rtol=1e-12)
            np.testing.assert_array_equal(i, i2)
    r = 0.12
    assert [sorted(x) for x in ours_a.query_ball_point(q, r, p=p)] == \
           [sorted(x) for x in theirs_a.query_ball_point(q, r, p=p)]
    np.testing.assert_array_equal(ours_a.query_ball_point(q, r, p=p, return_length=True),
                                  theirs_a.query_ball_point(q, r, p=p, return_length=True))
    assert ours_a.query_ball_tree(ours_b, r, p=p) == [sorted(x) for x in theirs_a.query_ball_tree(theirs_b, r, p=p)]
    assert ours_a.query_pairs(r, p=p) == theirs_a.query_pairs(r, p=p)
    radii = [0.01, 0.05, 0.1, 0.2]
    np.testing.assert_array_equal(ours_a.count_neighbors(ours_b, radii, p=p),
                                  theirs_a.count_neighbors(theirs_b, radii, p=p))
    wa, wb = rng.random(300), rng.random(200)
    np.testing.assert_allclose(ours_a.count_neighbors(ours_b, radii, p=p, weights=(wa, wb), cumulative=False),
                               theirs_a.count_neighbors(theirs_b, radii, p=p, weights=(wa, wb), cumulative=False),
                               rtol=1e-12)
    ours_m = ours_a.sparse_distance_matrix(ours_b, r, p=p, output_type="dict")
    theirs_m = theirs_a.sparse_distance_matrix(theirs_b, r, p=p, output_type="dict")
    assert ours_m.keys() == theirs_m.keys()
    np.testing.assert_allclose([ours_m[key] for key in theirs_m], list(theirs_m.values()), rtol=1e-12)


def test_eps_in_radius_queries_means_exactly_within_r_times_1_plus_eps():
    data = points("uniform", 500, 2, 3)
    tree = kdspace.KDTree(data)
    q = np.zeros(2)
    assert tree.query_ball_point(q, 0.2, eps=0.5, return_sorted=True) == \
           tree.query_ball_point(q, 0.3, return_sorted=True)
    assert tree.query_pairs(0.02, eps=1.0) == tree.query_pairs(0.04)


# ---- kdspace's own behaviour --------------------------------------------------------------------------

def test_float32_data_stays_float32():
    data = points("clustered", 1000, 4, 2, np.float32)
    tree = kdspace.KDTree(data)
    assert tree.data is data  # not copied, not converted
    d, i = tree.query(data[:10], k=3)
    assert d.dtype == np.float32 and i.dtype == np.intp
    want_d, want_i = brute_knn(data, data[:10], 3, 2)
    assert_same_neighbours(d.astype(np.float64), i, want_d, want_i, 1e-6, data, data[:10])
    assert kdspace.KDTree(data.astype(np.int32)).data.dtype == np.float64  # others become float64, as SciPy


def test_rows_holding_nan_or_inf_are_kept_but_never_neighbours():
    data = points("uniform", 50, 3, 5)
    data[[3, 17]] = np.nan
    data[25, 1] = np.inf
    tree = kdspace.KDTree(data)
    assert tree.n == 50 and tree.data is data
    d, i = tree.query(np.zeros(3), k=50)
    assert not {3, 17, 25} & set(i[:47].tolist())
    assert (i[47:] == 50).all() and np.isinf(d[47:]).all()
    finite = np.delete(np.arange(50), [3, 17, 25])
    d2, i2 = kdspace.KDTree(data[finite]).query(np.zeros(3), k=47)
    np.testing.assert_array_equal(finite[i2], i[:47])
    assert all(not {3, 17, 25} & set(row) for row in tree.query_ball_point(data[finite], 0.5))
    assert tree.count_neighbors(tree, 10.0) == 47 * 47
    np.testing.assert_array_equal(tree.maxes, data[finite].max(axis=0))


def test_all_rows_nan_gives_an_empty_tree():
    tree = kdspace.KDTree(np.full((4, 2), np.nan))
    d, i = tree.query([[0, 0]], k=2)
    assert np.isinf(d).all() and (i == 4).all()
    assert tree.query_pairs(1.0) == set()


def test_pickle_keeps_the_answers():
    data = points("clustered", 300, 3, 6, np.float32)
    data[7] = np.nan
    tree = kdspace.KDTree(data, leafsize=5, boxsize=None)
    copy = pickle.loads(pickle.dumps(tree))
    assert copy.leafsize == 5 and copy.data.dtype == np.float32
    for a, b in zip(tree.query(data[8:28] * 0.9, k=4), copy.query(data[8:28] * 0.9, k=4)):
        np.testing.assert_array_equal(a, b)


def test_node_view_and_node_weights():
    data = points("uniform", 200, 3, 8)
    tree = kdspace.KDTree(data, leafsize=8)
    root = tree.tree
    assert root.children == 200 and sorted(root.indices.tolist()) == list(range(200))
    stack, nodes = [root], 0
    while stack:
        node = stack.pop()
        nodes += 1
        if node.split_dim == -1:
            assert node.lesser is None and node.children <= 8
            np.testing.assert_array_equal(node.data_points, data[node.indices])
        else:
            assert node.lesser.data_points[:, node.split_dim].max() <= node.split
            assert node.greater.data_points[:, node.split_dim].min() == node.split
            stack += [node.lesser, node.greater]
    assert nodes == tree.size
    weights = np.arange(200.0)
    assert tree._build_weights(weights)[0] == weights.sum()


def test_threads_give_the_answers_of_one_thread():
    data = points("clustered", 20000, 3, 9)
    queries = points("uniform", 5000, 3, 10) * 10
    tree = kdspace.KDTree(data)
    for a, b in zip(tree.query(queries, k=4, workers=1), tree.query(queries, k=4, workers=-1)):
        np.testing.assert_array_equal(a, b)
    for a, b in zip(tree.query(queries, k=4, workers=3, distance_upper_bound=0.5),
                    tree.query(queries, k=4, distance_upper_bound=0.5)):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(tree.query_ball_point(queries, 0.3, workers=-1, return_length=True),
                                  tree.query_ball_point(queries, 0.3, return_length=True))


def test_the_gil_is_released_while_a_query_runs():
    # With thread switching left to the threads themselves (a huge switch interval), the main thread
    # can only run while the worker is inside the query if the query released the GIL.
    tree = kdspace.KDTree(points("uniform", 50000, 3, 11))
    queries = points("uniform", 100000, 3, 12)
    started, finished = threading.Event(), threading.Event()
    ticks = 0

    def search():
        started.set()
        tree.query(queries, k=4)
        finished.set()

    interval = sys.getswitchinterval()
    sys.setswitchinterval(1000)
    try:
        worker = threading.Thread(target=search)
        worker.start()
        started.wait()
        while not finished.is_set():
            ticks += 1
            time.sleep(0)  # lets the worker take the GIL back when its query returns
        worker.join()
    finally:
        sys.setswitchinterval(interval)
    assert ticks > 0


# ---- bad input --------------------------------------------------------------------------------------

def test_bad_input_is_refused_with_a_clear_exception():
    tree = kdspace.KDTree(points("uniform", 30, 3, 13))
    with pytest.raises(TypeError, match="complex"):
        kdspace.KDTree(np.ones((3, 2), dtype=complex))
    with pytest.raises(TypeError, match="complex"):
        tree.query(np.ones(3, dtype=complex))
    with pytest.raises(TypeError, match="real numbers"):
        kdspace.KDTree([["a", "b"]])
    with pytest.raises(ValueError, match=r"shape \(n, m\)"):
        kdspace.KDTree(np.ones(5))
    with pytest.raises(ValueError, match=r"vectors of length 3 but has shape \(2,\)"):
        tree.query([1, 2])
    with pytest.raises(ValueError, match="k must be at least 1"):
        tree.query(np.zeros(3), k=0)
    with pytest.raises(ValueError, match="k must be an integer"):
        tree.query(np.zeros(3), k=1.5)
    with pytest.raises(ValueError, match="p-norms"):
        tree.query(np.zeros(3), p=0.5)
    with pytest.raises(ValueError, match="eps"):
        tree.query(np.zeros(3), eps=-1)
    with pytest.raises(ValueError, match="query row 2: coordinate 3 is not finite"):
        tree.query([[0, 0, 0], [0, 0, np.nan]])
    with pytest.raises(ValueError, match="workers"):
        tree.query(np.zeros(3), workers=0)
    with pytest.raises(ValueError, match="leafsize"):
        kdspace.KDTree(np.ones((3, 2)), leafsize=0)
    with pytest.raises(ValueError, match="boxsize"):
        kdspace.KDTree(np.ones((3, 2)) * 0.5, boxsize=-1)
    with pytest.raises(ValueError, match="greater than the size of the periodic box"):
        kdspace.KDTree(np.ones((3, 2)) * 2, boxsize=1)
    with pytest.raises(ValueError, match="different dimensionality"):
        tree.query_ball_tree(kdspace.KDTree(np.ones((3, 2))), 1.0)
    with pytest.raises(ValueError, match="Invalid output type"):
        tree.query_pairs(1.0, output_type="list")
    with pytest.raises(ValueError, match="non-decreasing"):
        tree.count_neighbors(tree, [0.2, 0.1], cumulative=False)
