"""kdspace.Forest: approximate k-nearest neighbours in high dimensions (image and audio descriptors).

Several randomized kd-trees over the data's principal directions, searched together best bin
first within a budget of scored points ("checks"), and (from 8 dimensions on, unless graph='off')
a neighbour graph built with them, searched best first keeping the `ef` best points found. Every
returned distance is exact, and with checks='exact' or ef='exact' the answer is the exact k-NN.
tune() finds the fastest setting (the graph's ef, or the trees' trees and checks) for a target
recall and keeps it as the forest's default. Euclidean distance only.
"""

import operator

import numpy as np

from . import _core
from ._kdtree import _real_array, _workers

__all__ = ["Forest", "recall_at_k"]


def _budget(value, name):
    if isinstance(value, str):
        if value != "exact":
            raise ValueError(f"{name} must be a positive integer or 'exact', got {value!r}")
        return _core.unlimited_checks
    value = operator.index(value)
    if value < 1:
        raise ValueError(f"{name} must be at least 1, got {value}")
    return value


def _graph_mode(graph):
    if graph in ("auto", True, False):
        return "auto" if graph == "auto" else ("on" if graph else "off")
    raise ValueError(f"graph must be 'auto', True or False, got {graph!r}")


class Forest:
    """Randomized kd-forest for approximate Euclidean k-NN.

    Parameters
    ----------
    data : array_like, shape (n, m)
        float32 stays float32; uint8 (SIFT-like descriptors) is kept as bytes, a quarter of the
        memory of float32, with the same answers; other real types become float64. Every value
        must be finite.
    trees : int
        Randomized trees (default 4); a search may use fewer (``query(trees=...)``).
    leaf_size : int
        Points at most in a leaf (default 8).
    pca : bool
        Split the data's principal directions (True, default) or its axes.
    projected_dims : int
        Principal directions the trees split on; 0 (default) chooses from the variance.
    compact : bool
        Keep byte-valued data (every value an integer 0..255) as bytes (default True).
    seed : int
        Seed of the random draws: the same seed gives the same forest.
    workers : int
        Threads for the build (-1: all cores); the forest does not depend on it.
    graph : 'auto', True or False
        Build the neighbour graph: 'auto' (default) from 8 dimensions on, where it answers faster
        than the trees at equal recall.
    degree : int
        Neighbours a point keeps in the graph (2..1024, default 32; 4 bytes each).
    """

    def __init__(self, data, trees=4, leaf_size=8, pca=True, projected_dims=0, compact=True, seed=1,
                 workers=1, graph="auto", degree=32):
        array = _real_array(data, "data")
        if array.ndim != 2:
            raise ValueError("data must be of shape (n, m), where there are n points of dimension m")
        if array.dtype == np.uint8:
            self._dtype, core, rows = np.float32, _core.ForestIndex32, np.ascontiguousarray(array)
        elif array.dtype == np.float32:
            self._dtype, core, rows = np.float32, _core.ForestIndex32, np.ascontiguousarray(array)
        else:
            self._dtype, core = np.float64, _core.ForestIndex64
            rows = np.ascontiguousarray(array, dtype=np.float64)
        params = _core.ForestParams()
        params.trees = operator.index(trees)
        params.leaf_size = operator.index(leaf_size)
        params.pca = bool(pca)
        params.projected_dims = operator.index(projected_dims)
        params.compact = bool(compact)
        params.seed = operator.index(seed)
        params.threads = _workers(workers)
        params.graph = _graph_mode(graph)
        params.graph_degree = operator.index(degree)
        self._args = (trees, leaf_size, pca, projected_dims, compact, seed, 1, graph, degree)
        self.data = array
        self._core = core(rows, params)
        self.checks = 256
        self.trees = 0
        self.ef = 0  # > 0: query() searches the graph by default (set by tune())
        self.tuning = None

    @property
    def n(self):
        return self._core.size

    @property
    def m(self):
        return self._core.dim

    @property
    def tree_count(self):
        return self._core.tree_count

    @property
    def projected_dims(self):
        return self._core.projected_dims

    @property
    def compact(self):
        """Whether the points are kept as bytes."""
        return self._core.compact

    @property
    def has_graph(self):
        """Whether the neighbour graph was built."""
        return self._core.has_graph

    @property
    def graph_degree(self):
        return self._core.graph_degree

    @property
    def memory_bytes(self):
        return self._core.memory_bytes

    @property
    def index_bytes(self):
        """Bytes held besides the copy of the points."""
        return self._core.index_bytes

    def __reduce__(self):
        # Pickled as the data and the parameters: the same seed builds the same forest.
        return (_rebuild, (self.data, self._args, self.checks, self.trees, self.ef, self.tuning))

    def _queries(self, x):
        array = _real_array(x, "x")
        if array.ndim == 0 or array.shape[-1] != self.m:
            raise ValueError("x must consist of vectors of length {} but has shape {}".format(
                self.m, np.shape(x)))
        return np.ascontiguousarray(array.reshape(-1, self.m), dtype=self._dtype), array.shape[:-1]

    def _answer(self, rows, shape, k, search):
        k = operator.index(k)
        if k < 1:
            raise ValueError(f"k must be at least 1 (got {k})")
        found = min(k, self.n)
        d, i = search(rows, found)
        if found < k:  # as KDTree.query: missing neighbours are (inf, n)
            d = np.concatenate([d, np.full((len(rows), k - found), np.inf, dtype=d.dtype)], axis=1)
            i = np.concatenate([i, np.full((len(rows), k - found), self.n, dtype=i.dtype)], axis=1)
        d, i = d.reshape(shape + (k,)), i.astype(np.intp, copy=False).reshape(shape + (k,))
        if k == 1:
            d, i = d[..., 0], i[..., 0]
            if len(shape) == 0:
                return float(d), int(i)
        return d, i

    def query(self, x, k=1, checks=None, trees=None, ef=None, workers=1):
        """The k nearest points found within the budget, as KDTree.query returns them.

        ef: search the graph, keeping the ef best points found ('exact': the exact answer).
        checks: search the trees, scoring this many points a query ('exact': until no cell can
        hold a closer point); trees: how many of the trees to search (default: all). With none of
        them, the setting tune() chose, else the trees with 256 checks.
        """
        rows, shape = self._queries(x)
        if ef is not None and (checks is not None or trees is not None):
            raise ValueError("ef searches the graph; checks and trees search the trees: give one or the other")
        if ef is not None:
            budget, use, width = _core.unlimited_checks, 0, _budget(ef, "ef")
        elif checks is not None or trees is not None or self.ef == 0:
            budget = _budget(self.checks if checks is None else checks, "checks")
            use, width = operator.index(self.trees if trees is None else trees), 0
        else:
            budget, use, width = _core.unlimited_checks, 0, self.ef
        threads = _workers(workers)
        return self._answer(rows, shape, k, lambda q, kk: self._core.knn(q, kk, budget, use, width, threads))

    def query_exact(self, x, k=1, workers=1):
        """The exact k nearest (every point scored, by blocked matrix products): the reference for
        recall."""
        rows, shape = self._queries(x)
        threads = _workers(workers)
        return self._answer(rows, shape, k, lambda q, kk: self._core.knn_exact(q, kk, threads))

    def tune(self, recall=0.9, k=10, queries=None, sample_queries=200, max_checks=0, seed=7, workers=-1,
             method="auto"):
        """Chooses the fastest setting whose mean recall@k reaches `recall` (method 'auto': the
        graph's ef or the trees' (trees, checks); 'graph' or 'trees': that one only), measured on
        up to sample_queries of the given queries (or, without them, on base points left out of
        their own answers: optimistic where points have near-copies), checks it on as many others,
        and keeps it as this forest's default. Returns what was measured (a dict; ef > 0 when the
        graph was chosen)."""
        if method not in ("auto", "graph", "trees"):
            raise ValueError(f"method must be 'auto', 'graph' or 'trees', got {method!r}")
        if method == "graph" and not self.has_graph:
            raise ValueError("method='graph' needs a forest built with its graph")
        params = _core.TuneParams()
        params.graph = method != "trees"
        params.trees = method != "graph"
        params.sample_queries = operator.index(sample_queries)
        params.max_checks = operator.index(max_checks)
        params.seed = operator.index(seed)
        params.threads = _workers(workers)
        rows = None if queries is None else self._queries(queries)[0]
        tuning = self._core.tune(float(recall), operator.index(k), rows, params)
        self.trees, self.checks, self.ef, self.tuning = tuning["trees"], tuning["checks"], tuning["ef"], tuning
        return tuning


def _rebuild(data, args, checks, trees, ef, tuning):
    forest = Forest(data, *args)
    forest.checks, forest.trees, forest.ef, forest.tuning = checks, trees, ef, tuning
    return forest


def recall_at_k(distances, exact_distances):
    """Mean recall@k of found neighbours against the exact ones (rows of k distances each, or one
    distance per query for k = 1): the share of returned points no farther than the true k-th
    nearest, so ties count as found."""
    found = np.asarray(distances, dtype=np.float64)
    exact = np.asarray(exact_distances, dtype=np.float64)
    if found.shape != exact.shape or found.ndim < 1:
        raise ValueError(f"distances of shapes {found.shape} and {exact.shape} do not match")
    kth = exact if found.ndim == 1 else exact[..., -1:]
    return float(np.mean(found <= kth))
