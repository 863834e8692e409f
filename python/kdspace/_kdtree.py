"""kdspace.KDTree: SciPy's cKDTree interface over kdspace's exact kd-tree.

The arguments, return shapes and types follow scipy.spatial.cKDTree (SciPy's own kd-tree test
file runs against this class: see the README). Where kdspace differs, it says so here:

- float32 data stays float32 (no float64 copy); its distances come back as float32. Every other
  real dtype is converted to float64, as SciPy does. Queries are converted to the data's dtype.
- Rows holding NaN or infinity are accepted, kept in ``data`` and never returned as neighbours.
- Answers are exact, with SciPy's tie rule made definite: among points at equal distance the
  smaller row comes first (decided on the internal distance, the squared one for p = 2).
- eps > 0 in the radius queries (query_ball_point, query_ball_tree, query_pairs) returns exactly
  the points within r * (1 + eps), one of the answers SciPy's eps allows.
- The GIL is released while the tree is built and while every query runs; workers=-1 uses all
  cores.
"""

import operator
import os

import numpy as np

from . import _core

__all__ = ["KDTree", "KDTreeNode"]


def _workers(workers):
    """The thread count for `workers` (None or 1: one; -1: all cores), as SciPy checks it."""
    if workers is None:
        return 1
    count = operator.index(workers)
    if count == -1:
        cpus = os.cpu_count()
        if cpus is None:
            raise NotImplementedError(
                "Cannot determine the number of cpus using os.cpu_count(), "
                "cannot use -1 for the number of workers")
        return cpus
    if count <= 0:
        raise ValueError(f"Invalid number of workers {workers}, must be -1 or > 0")
    return count


def _real_array(values, what):
    """values as an ndarray of real numbers (complex and non-numeric data are refused)."""
    array = np.asarray(values)
    if np.iscomplexobj(array):
        raise TypeError(f"kdspace.KDTree does not work with complex data ({what} is complex)")
    if array.dtype.kind not in "biuf":
        raise TypeError(f"{what} must hold real numbers, not {array.dtype}")
    return array


def _order(p):
    """p as a float in [1, inf]."""
    p = float(p)
    if not p >= 1:
        raise ValueError(f"Only p-norms with 1<=p<=infinity permitted (got p = {p})")
    return p


def _non_negative(value, name):
    value = float(value)
    if not value >= 0 or np.isnan(value):
        raise ValueError(f"{name} must be a non-negative number, got {value}")
    return value


def _radius(r, eps):
    """A radius of the radius queries: exact for r * (1 + eps) (see the module's notes)."""
    r = np.asarray(r, dtype=np.float64)
    if np.isnan(r).any():
        raise ValueError("r must not be NaN")
    return r * (1.0 + eps) if eps > 0 else r


class KDTreeNode:
    """A read-only view of one node of a kdspace.KDTree (as SciPy's cKDTreeNode).

    Attributes: ``level`` (0 at the root), ``split_dim`` (-1 for a leaf), ``split`` (the smallest
    coordinate of the greater child along split_dim; the lesser child's points are at most
    ``left_max`` there, and kdspace keeps both tight bounds), ``children`` (points under the
    node), ``start_idx``/``end_idx`` (its run of ``KDTree.indices``), ``indices`` (those rows),
    ``data_points`` (their coordinates), ``lesser`` and ``greater`` (None for a leaf).
    """

    __slots__ = ("level", "split_dim", "split", "left_max", "children", "start_idx", "end_idx",
                 "lesser", "greater", "_tree")

    def __init__(self, tree, table, node, level):
        self._tree = tree
        self.level = level
        self.split_dim = int(table["split_dim"][node])
        self.start_idx = int(table["start"][node])
        self.end_idx = int(table["end"][node])
        self.children = self.end_idx - self.start_idx
        if self.split_dim < 0:
            self.split = self.left_max = float("nan")
            self.lesser = self.greater = None
        else:
            self.split = float(table["right_min"][node])
            self.left_max = float(table["left_max"][node])
            self.lesser = KDTreeNode(tree, table, int(table["lesser"][node]), level + 1)
            self.greater = KDTreeNode(tree, table, int(table["greater"][node]), level + 1)

    @property
    def indices(self):
        return self._tree.indices[self.start_idx:self.end_idx]

    @property
    def data_points(self):
        return self._tree.data[self.indices, :]


class KDTree:
    """kd-tree for exact nearest-neighbour and radius search (a drop-in for scipy.spatial.cKDTree).

    Parameters
    ----------
    data : array_like, shape (n, m)
        The points. float32 stays float32; other real types become float64. Not copied when it is
        already a C-ordered array of that type, unless copy_data is True (the tree keeps its own
        copy of the finite rows in leaf order in any case, so changing ``data`` afterwards does not
        change the answers).
    leafsize : int
        Points at most in a leaf (default 16, as cKDTree).
    compact_nodes : bool
        Accepted for SciPy's sake: kdspace's nodes always keep the tight bounds of their children.
    copy_data : bool
        Keep a copy of the data as ``data`` rather than the array given.
    balanced_tree : bool
        Split at the median (True, default) or at the sliding midpoint (False).
    boxsize : array_like or scalar, optional
        A periodic box (a torus): axis i has period boxsize[i] (0: not periodic); the data must lie
        in [0, boxsize[i]) on the periodic axes, and queries are wrapped into it.
    """

    def __init__(self, data, leafsize=16, compact_nodes=True, copy_data=False, balanced_tree=True,
                 boxsize=None):
        array = _real_array(data, "data")
        dtype = np.float32 if array.dtype == np.float32 else np.float64
        if copy_data:
            array = np.array(array, dtype=dtype, order="C", copy=True)
        else:
            array = np.ascontiguousarray(array, dtype=dtype)
        if array.ndim != 2:
            raise ValueError("data must be of shape (n, m), where there are n points of dimension m")
        leafsize = operator.index(leafsize)
        if leafsize < 1:
            raise ValueError("leafsize must be at least 1")
        self.data = array
        self.leafsize = leafsize
        self._compact_nodes = bool(compact_nodes)
        self._balanced_tree = bool(balanced_tree)
        self._dtype = dtype
        n, m = array.shape
        if m == 0:
            raise ValueError("data must have at least one coordinate per point (its shape is %s)"
                             % (array.shape,))

        # Rows holding NaN or infinity stay in `data` but not in the tree.
        finite = np.isfinite(array).all(axis=1)
        if finite.all():
            self._rows, self._row_ids = array, None
        else:
            self._rows, self._row_ids = np.ascontiguousarray(array[finite]), np.flatnonzero(finite)
        rows = self._rows
        self.maxes = rows.max(axis=0).astype(np.float64) if len(rows) else np.zeros(m)
        self.mins = rows.min(axis=0).astype(np.float64) if len(rows) else np.zeros(m)

        self.boxsize = None
        periodic = np.empty(0, dtype=np.float64)
        if boxsize is not None:
            box = np.array(np.broadcast_to(np.asarray(boxsize, dtype=np.float64), (m,)), copy=True)
            if not (np.isfinite(box).all() and (box >= 0).all()):
                raise ValueError(f"boxsize must hold finite numbers >= 0, got {boxsize}")
            box.flags.writeable = False
            self.boxsize = box
            axes = box > 0
            if (rows >= box[None, :])[:, axes].any():
                raise ValueError("Some input data are greater than the size of the periodic box.")
            if (rows < 0)[:, axes].any():
                raise ValueError("Negative input data are outside of the periodic box.")
            if axes.any():
                periodic = box
        self._periodic = periodic

        self._core = None
        self._view = None
        self._indices = None
        if len(rows):
            ids = self._row_ids if self._row_ids is not None else np.empty(0, dtype=np.intp)
            index = _core.PointIndex32 if dtype == np.float32 else _core.PointIndex64
            self._core = index(rows, ids.astype(np.int64), n, leafsize, self._balanced_tree, periodic)

    # ---- attributes ------------------------------------------------------------------------------

    @property
    def n(self):
        """The number of rows of ``data`` (with the rows holding NaN or infinity)."""
        return self.data.shape[0]

    @property
    def m(self):
        """The dimension of the points."""
        return self.data.shape[1]

    @property
    def size(self):
        """The number of nodes of the tree."""
        return self._core.node_count if self._core is not None else 0

    @property
    def indices(self):
        """The rows of ``data`` in the tree's leaf order; a node holds a run of them."""
        if self._indices is None:
            self._indices = (self._core.leaf_rows() if self._core is not None
                             else np.empty(0, dtype=np.intp))
            self._indices.flags.writeable = False
        return self._indices

    @property
    def tree(self):
        """The root KDTreeNode: a Python view of the whole tree, made on first use."""
        if self._view is None and self._core is not None:
            self._view = KDTreeNode(self, self._core.nodes(), 0, 0)
        return self._view

    def __reduce__(self):
        # Pickled as the data and the parameters; unpickling builds the same tree again.
        return (self.__class__, (self.data, self.leafsize, self._compact_nodes, False,
                                 self._balanced_tree, self.boxsize))

    # ---- queries ---------------------------------------------------------------------------------

    def _queries(self, x):
        """x as rows of m values of the data's dtype, and the shape of the answer."""
        array = _real_array(x, "x")
        if array.ndim == 0 or array.shape[-1] != self.m:
            raise ValueError("x must consist of vectors of length {} but has shape {}".format(
                self.m, np.shape(x)))
        rows = np.ascontiguousarray(array.reshape(-1, self.m), dtype=self._dtype)
        return rows, array.shape[:-1]

    def query(self, x, k=1, eps=0, p=2, distance_upper_bound=np.inf, workers=1):
        """The k nearest neighbours of each point of x.

        k is an int (the 1st to k-th) or a sequence of ranks (1-based). Returns (d, i): distances
        and rows of ``data``, shaped x.shape[:-1] + (len(k),), the last axis dropped when k == 1
        (Python scalars for one point). Missing neighbours (beyond distance_upper_bound, which is
        strict, or k above the number of points) are (inf, n). With eps > 0 the i-th returned
        point is within (1 + eps) of the true i-th distance.
        """
        if k is None:
            raise ValueError("k must be an integer or a sequence of integers")
        single_rank = np.ndim(k) == 0
        try:
            ranks = (np.arange(1, operator.index(k) + 1) if single_rank
                     else np.array([operator.index(r) for r in k], dtype=np.intp))
        except TypeError:
            raise ValueError("k must be an integer or a sequence of integers") from None
        if single_rank and operator.index(k) < 1:
            raise ValueError(f"k must be at least 1 (got {k})")
        if ranks.size == 0 or (ranks < 1).any():
            raise ValueError(f"every rank in k must be at least 1 (got {k})")
        rows, shape = self._queries(x)
        eps = _non_negative(eps, "eps")
        p = _order(p)
        upper_bound = float(distance_upper_bound)
        if np.isnan(upper_bound):
            raise ValueError("distance_upper_bound must not be NaN")
        threads = _workers(workers)
        kmax = int(ranks.max())

        if self._core is None:
            d = np.full((len(rows), kmax), np.inf, dtype=self._dtype)
            i = np.full((len(rows), kmax), self.n, dtype=np.intp)
        else:
            d, i = self._core.knn(rows, kmax, eps, p, upper_bound, threads)
            i = i.astype(np.intp, copy=False)
        if not np.array_equal(ranks, np.arange(1, kmax + 1)):
            d, i = d[:, ranks - 1], i[:, ranks - 1]
        d = d.reshape(shape + (len(ranks),))
        i = i.reshape(shape + (len(ranks),))
        if single_rank and kmax == 1:
            d, i = d[..., 0], i[..., 0]
            if len(shape) == 0:
                return float(d), int(i)
        return d, i

    def query_ball_point(self, x, r, p=2, eps=0, workers=1, return_sorted=None, return_length=False):
        """The rows within distance r (closed ball) of each point of x.

        r is a scalar or one radius per point (broadcast to x.shape[:-1]). Returns a list of rows
        for one point, else an object array of lists shaped x.shape[:-1]; rows ascending when
        return_sorted (by default for several points, not for one), otherwise in no set order.
        With return_length, the counts instead.
        """
        rows, shape = self._queries(x)
        p = _order(p)
        eps = _non_negative(eps, "eps")
        threads = _workers(workers)
        radii = np.ascontiguousarray(np.broadcast_to(_radius(r, eps), shape), dtype=np.float64).reshape(-1)
        sort_rows = bool(return_sorted) or (return_sorted is None and len(shape) > 0)
        if return_length:
            counts = (self._core.ball_counts(rows, radii, p, threads) if self._core is not None
                      else np.zeros(len(rows), dtype=np.intp))
            result = counts.astype(np.intp, copy=False).reshape(shape)
        else:
            if self._core is not None:
                lists = self._core.ball_lists(rows, radii, p, threads, sort_rows)
            else:
                lists = np.empty(len(rows), dtype=object)
                for j in range(len(rows)):
                    lists[j] = []
            result = lists.reshape(shape)
        return result[()] if len(shape) == 0 else result

    def _check_other(self, other, method):
        if not isinstance(other, KDTree):
            raise TypeError(f"{method} needs another kdspace.KDTree, not {type(other).__name__}")
        if self.m != other.m:
            raise ValueError(f"Trees passed to {method} have different dimensionality")

    def _query_rows(self):
        """This tree's finite rows (as queries) and their row numbers."""
        ids = self._row_ids if self._row_ids is not None else np.arange(self.n, dtype=np.int64)
        return self._rows, ids.astype(np.int64, copy=False)

    def query_ball_tree(self, other, r, p=2, eps=0):
        """For each row i of this tree, the rows of ``other`` within distance r of it (ascending)."""
        self._check_other(other, "query_ball_tree")
        p = _order(p)
        eps = _non_negative(eps, "eps")
        radius = float(_radius(r, eps))
        results = [[] for _ in range(self.n)]
        if self._core is None or other._core is None:
            return results
        joined = self._core.join_pairs(other._core, radius, p, "lists")
        if joined is not None:
            return joined
        queries, ids = self._query_rows()
        lists = other._core.ball_lists(queries, np.full(len(queries), radius), p, 1, True)
        for row, found in zip(ids.tolist(), lists):
            results[row] = found
        return results

    def query_pairs(self, r, p=2, eps=0, output_type="set"):
        """Every pair (i, j), i < j, of rows within distance r: a set of tuples, or with
        output_type='ndarray' an (M, 2) array ordered by (i, j)."""
        p = _order(p)
        eps = _non_negative(eps, "eps")
        if output_type not in ("set", "ndarray"):
            raise ValueError("Invalid output type")
        radius = float(_radius(r, eps))
        if self._core is None:
            first = second = np.empty(0, dtype=np.intp)
        else:
            joined = self._core.join_pairs(None, radius, p, "pairs")
            if joined is not None:
                first, second = joined
            else:
                queries, ids = self._query_rows()
                first, second, _ = self._core.ball_pairs(queries, radius, p, 1, ids, True)
        if output_type == "set":
            return set(zip(first.tolist(), second.tolist()))
        return np.stack([first, second], axis=1).astype(np.intp, copy=False).reshape(-1, 2)

    def _build_weights(self, weights):
        """The total weight of each node (SciPy's internal helper, in this tree's node order)."""
        weights = np.ascontiguousarray(weights, dtype=np.float64)
        if weights.ndim != 1 or len(weights) != self.n:
            raise ValueError("Number of weights differ from the number of data points")
        if self._core is None:
            return np.zeros(0)
        table = self._core.nodes()
        sums = np.concatenate([[0.0], np.cumsum(weights[self.indices])])
        return sums[table["end"]] - sums[table["start"]]

    def count_neighbors(self, other, r, p=2, weights=None, cumulative=True):
        """The number of pairs (x1 in self, x2 in other) with distance(x1, x2) <= r, for each r.

        r is a number or a 1-D array (non-decreasing when not cumulative: then result[i] counts
        r[i-1] < distance <= r[i]). weights: None; an array (self and other the same tree); or a
        tuple (self's, other's), either None. Unweighted counts are integers, weighted ones floats.
        """
        self._check_other(other, "count_neighbors")
        p = _order(p)
        if np.ndim(r) > 1:
            raise ValueError("r must be either a single value or a one-dimensional array of values")
        radii = np.array(r, ndmin=1, dtype=np.float64)
        if np.isnan(radii).any():
            raise ValueError("r must not be NaN")
        if not cumulative and (np.diff(radii) < 0).any():
            raise ValueError("r must be non-decreasing for non-cumulative counting.")
        if weights is None:
            own, others = None, None
        elif isinstance(weights, tuple):
            own, others = weights
        else:
            own = others = weights
            if other is not self:
                raise ValueError("Two different trees are used. Specify weights for both in a tuple.")
        weighted = own is not None or others is not None
        if own is not None:
            own = np.ascontiguousarray(own, dtype=np.float64)
            if own.ndim != 1 or len(own) != self.n:
                raise ValueError("Number of weights differ from the number of data points")
        if others is not None:
            others = np.ascontiguousarray(others, dtype=np.float64)
            if others.ndim != 1 or len(others) != other.n:
                raise ValueError("Number of weights differ from the number of data points")

        unique, first_of, inverse = np.unique(radii, return_index=True, return_inverse=True)
        if self._core is None or other._core is None or len(unique) == 0:
            bins = np.zeros(len(unique))
        else:
            queries, ids = self._query_rows()
            query_weights = None if own is None else np.ascontiguousarray(own[ids])
            bins = other._core.pair_histogram(queries, query_weights, unique, others, p, 1)
        if not weighted:
            bins = np.rint(bins).astype(np.intp)
        if cumulative:
            result = np.cumsum(bins)[inverse]
        else:
            result = np.zeros(len(radii), dtype=bins.dtype)
            result[first_of] = bins
        if np.ndim(r) == 0:
            return int(result[0]) if not weighted else result[0]
        return result

    def sparse_distance_matrix(self, other, max_distance, p=2, output_type="dok_matrix"):
        """Distances of every pair (row of self, row of other) within max_distance.

        output_type: 'dok_matrix' (default), 'coo_matrix', 'dok_array', 'coo_array' (these need
        SciPy), 'dict' {(i, j): d} or 'ndarray' (a record array with fields i, j, v).
        """
        self._check_other(other, "sparse_distance_matrix")
        p = _order(p)
        if output_type not in ("dok_matrix", "coo_matrix", "dok_array", "coo_array", "dict", "ndarray"):
            raise ValueError("Invalid output type")
        max_distance = float(max_distance)
        if np.isnan(max_distance):
            raise ValueError("max_distance must not be NaN")
        if self._core is None or other._core is None:
            first = second = np.empty(0, dtype=np.intp)
            values = np.empty(0)
        else:
            joined = self._core.join_pairs(other._core, max_distance, p, "distances")
            if joined is not None:
                first, second, values = joined
            else:
                queries, ids = self._query_rows()
                first, second, values = other._core.ball_pairs(queries, max_distance, p, 1, ids, False)
        if output_type == "dict":
            return dict(zip(zip(first.tolist(), second.tolist()), values.tolist()))
        if output_type == "ndarray":
            records = np.empty(len(first), dtype=np.dtype([("i", np.intp), ("j", np.intp), ("v", np.float64)],
                                                          align=True))
            records["i"], records["j"], records["v"] = first, second, values
            return records
        import scipy.sparse

        make = scipy.sparse.coo_array if output_type.endswith("array") else scipy.sparse.coo_matrix
        matrix = make((values, (first, second)), shape=(self.n, other.n))
        return matrix.todok() if output_type.startswith("dok") else matrix
