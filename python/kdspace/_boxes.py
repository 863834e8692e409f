"""kdspace.BoxTree: ray shooting through 3-D boxes (closest hit, any hit) and overlapping boxes."""

import numpy as np

from . import _core
from ._kdtree import _real_array, _workers

__all__ = ["BoxTree", "overlapping_pairs"]


def _boxes(boxes, what="boxes"):
    """Boxes as an (n, 6) float32 array: min x, min y, min z, max x, max y, max z (or (n, 2, 3))."""
    array = _real_array(boxes, what)
    if array.ndim == 3 and array.shape[1:] == (2, 3):
        array = array.reshape(-1, 6)
    if array.ndim != 2 or array.shape[1] != 6:
        raise ValueError(f"{what} must be of shape (n, 6) or (n, 2, 3) (lower then upper corner), "
                         f"not {array.shape}")
    return np.ascontiguousarray(array, dtype=np.float32)


def _vectors(values, what):
    array = _real_array(values, what)
    if array.ndim == 0 or array.shape[-1] != 3:
        raise ValueError(f"{what} must consist of 3-D vectors but has shape {array.shape}")
    return np.ascontiguousarray(array.reshape(-1, 3), dtype=np.float32), array.shape[:-1]


class BoxTree:
    """A kd-tree over closed, solid axis-aligned 3-D boxes, for ray queries.

    Parameters
    ----------
    boxes : array_like, shape (n, 6) or (n, 2, 3)
        Lower corner then upper corner of each box (float32). Box i keeps index i in the answers.
    build : 'sah_nlogn' (default), 'sah', 'median' or 'binned'
        Surface Area Heuristic (Wald and Havran's O(N log N) build, or the O(N log^2 N) one, which
        makes the same tree), the median build, or the binned build (the fastest to build: for
        overlapping pairs, and scenes built again often).
    workers : int
        Threads for the build; the tree does not depend on it.
    """

    def __init__(self, boxes, build="sah_nlogn", workers=1):
        self.boxes = _boxes(boxes)
        self._core = _core.BoxIndex(self.boxes, build, _workers(workers))
        self._build = build

    @property
    def n(self):
        return self._core.size

    @property
    def depth(self):
        return self._core.depth

    @property
    def size(self):
        """The number of nodes."""
        return self._core.node_count

    @property
    def memory_bytes(self):
        return self._core.memory_bytes

    def __reduce__(self):
        return (self.__class__, (self.boxes, self._build))

    def _trace(self, origins, directions, t_min, t_max, any_hit, workers):
        o, shape = _vectors(origins, "origins")
        d, shape_d = _vectors(directions, "directions")
        if shape != shape_d:
            raise ValueError(f"origins and directions have different shapes ({shape} and {shape_d})")
        boxes, t = self._core.trace(o, d, float(t_min), float(t_max), any_hit, _workers(workers))
        boxes, t = boxes.astype(np.intp, copy=False).reshape(shape), t.reshape(shape)
        return (int(boxes), float(t)) if len(shape) == 0 else (boxes, t)

    def closest_hit(self, origins, directions, t_min=0.0, t_max=np.inf, workers=1):
        """The first box along each ray origin + t * direction with t in [t_min, t_max] (the
        smallest t, then the smallest box index). Returns (box, t): box -1 and t inf for a miss;
        arrays shaped like the rays, or scalars for one ray. The direction need not be unit
        length: t is measured in multiples of it."""
        return self._trace(origins, directions, t_min, t_max, False, workers)

    def any_hit(self, origins, directions, t_min=0.0, t_max=np.inf, workers=1):
        """Some box hit with t in [t_min, t_max] (the first the traversal meets, not necessarily
        the closest), or (-1, inf): the query for shadow rays."""
        return self._trace(origins, directions, t_min, t_max, True, workers)

    def overlaps(self, other=None, workers=1):
        """Pairs of overlapping boxes (closed: touching counts): within this tree's boxes (i < j),
        or between them and `other` (a BoxTree, or boxes, which get a binned tree; i here, j
        there). An (M, 2) array sorted by (i, j), each pair once, the same for any `workers`."""
        if other is not None and not isinstance(other, BoxTree):
            other = BoxTree(_boxes(other, "other"), build="binned", workers=workers)
        pairs = self._core.overlaps(None if other is None else other._core, _workers(workers))
        return pairs.astype(np.intp, copy=False)


def overlapping_pairs(boxes, other=None, workers=1):
    """Pairs of overlapping closed boxes of one set (i < j) or of two sets, as an (M, 2) array sorted
    by (i, j): the broad phase of collision detection, on binned trees built for the purpose."""
    return BoxTree(boxes, build="binned", workers=workers).overlaps(other, workers)
