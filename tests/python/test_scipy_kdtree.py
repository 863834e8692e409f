"""SciPy's own kd-tree tests, run against kdspace.KDTree.

The file scipy/spatial/tests/test_kdtree.py that Debian's python3-scipy installs is loaded as it
is (nothing of it is copied here), with the names it imports for SciPy's trees bound to kdspace's
while it loads:

- cKDTree -> kdspace.KDTree (under the name cKDTree, so that the file's generated test classes
  keep distinct names);
- KDTree -> kdspace.KDTree made the way SciPy makes its KDTree from its cKDTree: leafsize
  defaults to 10, and the row of a one-point, k = 1 query is a NumPy integer (cKDTree's is a
  Python int);
- cKDTreeNode -> kdspace.KDTreeNode, the node view.

Its test functions, classes and fixtures are then collected from this module. Tests that need a
SciPy-internal type that kdspace does not imitate, or that test a SciPy class with no tree in it,
are skipped here with the reason (the README lists them).
"""

import importlib.util
import os

import numpy as np
import pytest

import kdspace

scipy_spatial = pytest.importorskip("scipy.spatial")
import scipy.spatial._ckdtree  # noqa: E402  (after the skip above)


class cKDTree(kdspace.KDTree):
    """kdspace.KDTree under the name of SciPy's cKDTree."""


class KDTree(kdspace.KDTree):
    """kdspace.KDTree with the two differences of SciPy's KDTree from its cKDTree."""

    def __init__(self, data, leafsize=10, compact_nodes=True, copy_data=False, balanced_tree=True,
                 boxsize=None):
        super().__init__(data, leafsize, compact_nodes, copy_data, balanced_tree, boxsize)

    def query(self, x, k=1, eps=0, p=2, distance_upper_bound=float("inf"), workers=1):
        d, i = super().query(x, k, eps, p, distance_upper_bound, workers)
        return d, (np.intp(i) if isinstance(i, int) else i)


SUITE_PATH = os.path.join(os.path.dirname(scipy_spatial.__file__), "tests", "test_kdtree.py")
if not os.path.exists(SUITE_PATH):
    pytest.skip(f"SciPy's kd-tree tests are not installed ({SUITE_PATH})", allow_module_level=True)


def _load_suite():
    """Imports SciPy's test file as a module of its own, with kdspace's classes in place of SciPy's."""
    names = {(scipy_spatial, "KDTree"): KDTree, (scipy_spatial, "cKDTree"): cKDTree,
             (scipy.spatial._ckdtree, "cKDTreeNode"): kdspace.KDTreeNode}
    saved = {key: getattr(*key) for key in names}
    spec = importlib.util.spec_from_file_location("scipy_test_kdtree_on_kdspace", SUITE_PATH)
    suite = importlib.util.module_from_spec(spec)
    try:
        for (module, name), replacement in names.items():
            setattr(module, name, replacement)
        spec.loader.exec_module(suite)
    finally:
        for (module, name), original in saved.items():
            setattr(module, name, original)
    assert suite.cKDTree is cKDTree and suite.KDTree is KDTree
    return suite


_suite = _load_suite()
globals().update({name: value for name, value in vars(_suite).items()
                  if name.startswith(("test_", "Test")) or name == "kdtree_type"})

# Tests of SciPy-internal types, skipped by conftest.py: (test id prefix, reason).
NOT_RUN = [
    ("Test_rectangle", "tests SciPy's Rectangle class (SciPy-internal type); no tree is involved"),
    ("test_kdtree_comparisons", "compares SciPy's KDTree.node objects (SciPy-internal type)"),
    ("test_kdtree_tree_access", "walks SciPy's KDTree.innernode / KDTree.leafnode wrappers "
                                "(SciPy-internal types); kdspace's node view is KDTreeNode"),
    ("test_kdtree_duplicated_inputs[KDTree]", "reads the node through SciPy's KDTree.node wrapper "
                                              "(tree._node, a SciPy-internal type); the cKDTree "
                                              "form of the same test runs"),
]

