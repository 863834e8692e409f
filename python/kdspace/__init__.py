"""kdspace: exact and approximate search in k-dimensional space with kd-trees, for NumPy arrays.

- KDTree: exact k-nearest-neighbour, radius and pair queries; a drop-in for
  scipy.spatial.cKDTree (same arguments, shapes and types), with float32 kept as float32.
- Forest: approximate k-NN in high dimensions (randomized kd-forest, tune() for a target recall).
- BoxTree: ray shooting through 3-D boxes (closest hit, any hit) and overlapping boxes.
- read_points, write_points, read_rows, read_boxes, read_rays, read_hits, ...: the file formats.

The compiled core (kdspace._core) releases the GIL while it builds and searches.
"""

from ._boxes import BoxTree, overlapping_pairs
from ._core import __version__
from ._forest import Forest, recall_at_k
from ._io import (read_boxes, read_hits, read_points, read_rays, read_rows, write_boxes, write_points,
                  write_rays, write_rows)
from ._kdtree import KDTree, KDTreeNode

__all__ = ["KDTree", "KDTreeNode", "Forest", "recall_at_k", "BoxTree", "overlapping_pairs", "read_points",
           "write_points", "read_rows", "write_rows", "read_boxes", "write_boxes", "read_rays", "write_rays",
           "read_hits", "__version__"]
