"""kdspace: exact and approximate search in k-dimensional space with kd-trees, for NumPy arrays.

- KDTree: exact k-nearest-neighbour, radius and pair queries; a drop-in for
  scipy.spatial.cKDTree (same arguments, shapes and types), with float32 kept as float32.

The compiled core (kdspace._core) releases the GIL while it builds and searches.
"""

from ._core import __version__
from ._kdtree import KDTree, KDTreeNode

__all__ = ["KDTree", "KDTreeNode", "__version__"]
