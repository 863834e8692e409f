#!/usr/bin/python3
"""The peers of kdspace-joins-bench, run in a process of their own: SciPy's cKDTree (workers=1) and
pykdtree (OMP_NUM_THREADS=1) on the points of a .npy file (float64, n x dim).

usage: joins_peers.py POINTS.npy --k K --r R --radii R1,R2,... [--save PREFIX]

Times (wall seconds, time.perf_counter) the builds and: all-kNN (each point's K nearest others, asked
as K + 1 nearest, the point itself among them), pairs within R (query_pairs, output_type='ndarray'),
pair counts at every radius (count_neighbors of the tree with itself, in one call). Prints one JSON
object. Counts are given as unordered pairs of distinct points, (c - n) / 2, to match kdspace's.
With --save, writes the answers for the bench's cross-check: PREFIX.scipy_ids.npy (int32, n x K+1),
PREFIX.scipy_dists.npy, PREFIX.pykdtree_ids.npy, PREFIX.pykdtree_dists.npy, PREFIX.scipy_pairs.npy
(int32, M x 2, sorted by (a, b); the sort is not timed).
"""
import argparse
import json
import os
import sys
import time

os.environ["OMP_NUM_THREADS"] = "1"  # pykdtree parallelises queries with OpenMP

import numpy as np  # noqa: E402
import scipy  # noqa: E402
from scipy.spatial import cKDTree  # noqa: E402

try:
    from pykdtree.kdtree import KDTree as PyKDTree
except ImportError:  # a side table only
    PyKDTree = None


def timed(f):
    start = time.perf_counter()
    value = f()
    return value, time.perf_counter() - start


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("points")
    parser.add_argument("--k", type=int, required=True)
    parser.add_argument("--r", type=float, required=True)
    parser.add_argument("--radii", required=True)
    parser.add_argument("--save")
    args = parser.parse_args()
    x = np.load(args.points)
    n = x.shape[0]
    radii = np.array([float(v) for v in args.radii.split(",")])
    out = {"scipy_version": scipy.__version__, "n": n}

    tree, out["scipy_build_s"] = timed(lambda: cKDTree(x, leafsize=16))
    (dists, ids), out["scipy_knn_s"] = timed(lambda: tree.query(x, k=args.k + 1, workers=1))
    pairs, out["scipy_pairs_s"] = timed(lambda: tree.query_pairs(args.r, output_type="ndarray"))
    counts, out["scipy_count_s"] = timed(lambda: tree.count_neighbors(tree, radii))
    out["scipy_pairs"] = int(len(pairs))
    out["scipy_counts"] = [int((c - n) // 2) for c in counts]
    if args.save:
        np.save(args.save + ".scipy_ids.npy", ids.astype(np.int32))
        np.save(args.save + ".scipy_dists.npy", dists)
        order = np.lexsort((pairs[:, 1], pairs[:, 0]))
        np.save(args.save + ".scipy_pairs.npy", pairs[order].astype(np.int32))
    del dists, ids, pairs

    if PyKDTree is not None:
        ptree, out["pykdtree_build_s"] = timed(lambda: PyKDTree(x, leafsize=16))
        (dists, ids), out["pykdtree_knn_s"] = timed(lambda: ptree.query(x, k=args.k + 1))
        if args.save:
            np.save(args.save + ".pykdtree_ids.npy", ids.astype(np.int32))
            np.save(args.save + ".pykdtree_dists.npy", dists)
    json.dump(out, sys.stdout)
    sys.stdout.write("\n")


if __name__ == "__main__":
    main()
