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


def test_graph_search_exact_budget_and_recall():
    both = descriptors(4200, 24, 10)  # queries from the data's own clusters
    data, queries = both[:4000], both[4000:]
    forest = kdspace.Forest(data)
    assert forest.has_graph and forest.graph_degree == 32
    assert not kdspace.Forest(data, graph=False).has_graph
    exact_d, exact_i = forest.query_exact(queries, k=10)
    d, i = forest.query(queries, k=10, ef="exact")
    np.testing.assert_array_equal(d, exact_d)
    np.testing.assert_array_equal(i, exact_i)
    recalls = []
    for ef in [10, 40, 160]:
        d, i = forest.query(queries, k=10, ef=ef)
        true = np.sqrt(((queries[:, None, :].astype(np.float64) - data[i].astype(np.float64)) ** 2).sum(-1))
        np.testing.assert_allclose(d, true, rtol=1e-5)
        recalls.append(kdspace.recall_at_k(d, exact_d))
    assert recalls[-1] >= recalls[0] and recalls[-1] > 0.95  # (ef 10 may already find them all)
    # the same graph whatever the build's thread count
    built_on_all = kdspace.Forest(data, workers=-1)
    np.testing.assert_array_equal(built_on_all.query(queries, k=10, ef=40)[1], forest.query(queries, k=10, ef=40)[1])


def test_tune_on_the_graph_becomes_the_default_and_survives_pickling():
    both = descriptors(6500, 32, 12)
    data, queries = both[:6000], both[6000:]
    forest = kdspace.Forest(data, degree=16)
    tuning = forest.tune(0.95, k=5, queries=queries[:400], method="graph")
    assert tuning["ef"] > 0 and forest.ef == tuning["ef"]
    assert tuning["validation_recall"] >= 0.9
    d, i = forest.query(queries[400:], k=5)
    np.testing.assert_array_equal(i, forest.query(queries[400:], k=5, ef=forest.ef)[1])
    copy = pickle.loads(pickle.dumps(forest))
    assert copy.ef == forest.ef and copy.graph_degree == 16
    np.testing.assert_array_equal(copy.query(queries[400:], k=5)[1], i)
    trees_only = forest.tune(0.9, k=5, queries=queries[:400], method="trees")
    assert trees_only["ef"] == 0 and forest.ef == 0


def test_graph_options_are_checked():
    data = descriptors(300, 8, 14)
    with pytest.raises(ValueError, match="graph must be"):
        kdspace.Forest(data, graph="sometimes")
    with pytest.raises(ValueError, match="graph_degree"):
        kdspace.Forest(data, degree=1)
    forest = kdspace.Forest(data)
    with pytest.raises(ValueError, match="one or the other"):
        forest.query(data[:2], k=2, ef=8, checks=8)
    with pytest.raises(ValueError, match="ef must be at least 1"):
        forest.query(data[:2], k=2, ef=0)
    with pytest.raises(ValueError, match="has none"):
        kdspace.Forest(data, graph=False).query(data[:2], k=2, ef=8)
    with pytest.raises(ValueError, match="needs a forest built with its graph"):
        kdspace.Forest(data, graph=False).tune(0.9, k=2, method="graph")
