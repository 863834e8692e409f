"""kdspace.Forest: approximate k-NN whose distances are exact, exact with checks='exact', bytes kept
as bytes, tuning to a recall."""

import pickle

import numpy as np
import pytest

import kdspace


def descriptors(n, dim, seed, dtype=np.float32):
    """Clustered data of low intrinsic dimension, like image or audio descriptors."""
    rng = np.random.default_rng(seed)
    centres = rng.normal(0, 10, (20, dim))
    basis = rng.normal(0, 1, (20, 6, dim))
    which = rng.integers(0, 20, n)
    x = centres[which] + np.einsum("nk,nkd->nd", rng.normal(0, 1, (n, 6)), basis[which])
    return x.astype(dtype)


def test_exact_checks_give_the_kdtree_answers():
    data = descriptors(3000, 24, 1, np.float64)
    queries = descriptors(100, 24, 2, np.float64)
    forest = kdspace.Forest(data, trees=3)
    d, i = forest.query(queries, k=5, checks="exact")
    d2, i2 = kdspace.KDTree(data).query(queries, k=5)
    np.testing.assert_array_equal(d, d2)
    np.testing.assert_array_equal(i, i2)
    de, ie = forest.query_exact(queries, k=5)
    np.testing.assert_array_equal(de, d2)


def test_recall_grows_with_the_budget_and_distances_are_exact():
    data = descriptors(5000, 32, 3)
    queries = descriptors(200, 32, 4)
    forest = kdspace.Forest(data, trees=4)
    exact_d, _ = forest.query_exact(queries, k=10)
    recalls = []
    for checks in [16, 64, 256, 1024]:
        d, i = forest.query(queries, k=10, checks=checks)
        assert d.dtype == np.float32 and i.shape == (200, 10)
        true = np.sqrt(((queries[:, None, :].astype(np.float64) - data[i].astype(np.float64)) ** 2).sum(-1))
        np.testing.assert_allclose(d, true, rtol=1e-5)
        recalls.append(kdspace.recall_at_k(d, exact_d))
    assert recalls == sorted(recalls) and recalls[-1] > recalls[0]


def test_byte_data_is_kept_as_bytes_with_the_same_answers():
    data = np.clip(descriptors(2000, 16, 5) * 4 + 128, 0, 255).astype(np.uint8)
    queries = data[:50].astype(np.float32) + 0.5
    as_bytes = kdspace.Forest(data)
    as_floats = kdspace.Forest(data.astype(np.float32), compact=False)
    assert as_bytes.compact and not as_floats.compact
    assert as_bytes.memory_bytes < as_floats.memory_bytes
    for a, b in zip(as_bytes.query(queries, k=4, checks=64), as_floats.query(queries, k=4, checks=64)):
        np.testing.assert_array_equal(a, b)


def test_tune_reaches_the_recall_and_becomes_the_default():
    data = descriptors(6000, 32, 6)
    queries = descriptors(600, 32, 7)
    forest = kdspace.Forest(data, trees=4)
    tuning = forest.tune(0.9, k=5, queries=queries[:400])
    assert tuning["validation_recall"] >= 0.9
    assert (forest.trees, forest.checks) == (tuning["trees"], tuning["checks"])
    d, _ = forest.query(queries[400:], k=5)
    exact_d, _ = forest.query_exact(queries[400:], k=5)
    assert kdspace.recall_at_k(d, exact_d) > 0.8  # unseen queries: close to the target
    copy = pickle.loads(pickle.dumps(forest))
    assert (copy.trees, copy.checks) == (forest.trees, forest.checks)
    np.testing.assert_array_equal(copy.query(queries[:20], k=5)[1], forest.query(queries[:20], k=5)[1])


def test_shapes_and_missing_neighbours_follow_kdtree_query():
    data = descriptors(30, 8, 8)
    forest = kdspace.Forest(data, trees=2)
    d, i = forest.query(data[0], k=1)
    assert isinstance(d, float) and i == 0
    d, i = forest.query(data[:4].reshape(2, 2, 8), k=40, checks="exact")
    assert d.shape == (2, 2, 40) and (i[..., 30:] == 30).all() and np.isinf(d[..., 30:]).all()


def test_bad_input_is_refused():
    with pytest.raises(ValueError, match="row 2: coordinate 1 is not finite"):
        kdspace.Forest(np.array([[0.0, 1], [np.nan, 1], [2, 2]]))
    forest = kdspace.Forest(descriptors(100, 8, 9), trees=2)
    with pytest.raises(ValueError, match="k must be at least 1"):
        forest.query(np.zeros(8), k=0)
    with pytest.raises(ValueError, match="checks"):
        forest.query(np.zeros(8), checks=0)
    with pytest.raises(ValueError, match="vectors of length 8"):
        forest.query(np.zeros(7))
