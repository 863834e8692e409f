#!/usr/bin/python3
"""The Python peers of kdspace-bench: pykdtree and SciPy's cKDTree, one thread, in their own process.

kdspace-bench --python-peers bench/python_peers.py runs this once per workload with Debian's
interpreter (/usr/bin/python3, which sees python3-pykdtree and python3-scipy):

    /usr/bin/python3 bench/python_peers.py DIR WORKLOAD --reps R --min-time S [--clock cpu] --kdspace BUILD_S KNN1 KNN10

DIR holds base.npy and queries.npy (float32, one point a row) and exact1.npy / exact10.npy, kdspace's
exact 1-NN and 10-NN distances. Both trees are built with their default parameters (leaf size 16) on
the float32 points (cKDTree converts them to float64 itself, inside its build); each measurement
repeats until it has run S seconds (each query run answering the queries in a new order) and the
median over R interleaved repetitions is kept. Every answer is checked against the exact distances
(within 1e-5 relative). Prints a markdown side table, kdspace's figures (passed in) against each
peer's, and one JSON line per measurement.
"""
import argparse
import importlib.metadata
import json
import os
import statistics
import sys
import time

os.environ["OMP_NUM_THREADS"] = "1"  # pykdtree's OpenMP: set before its module loads

import numpy as np  # noqa: E402
from pykdtree.kdtree import KDTree  # noqa: E402
from scipy.spatial import cKDTree  # noqa: E402


CLOCK = time.perf_counter  # or time.process_time with --clock cpu (as kdspace-bench's --clock cpu)


def timed(run, min_seconds):
    """Runs `run` until the runs add up to min_seconds; mean seconds of one, and the last result."""
    total, runs = 0.0, 0
    while True:
        start = CLOCK()
        result = run()
        total += CLOCK() - start
        runs += 1
        if total >= min_seconds:
            return total / runs, result


def timed_shuffled(query, queries, min_seconds, seed):
    """As timed(query(queries)), but each run answers the queries in a new order (drawn from seed and
    the run's number, off the clock), as kdspace-bench does, so that no run is measured on a sequence
    the branch predictor has learnt; the last run's answers are returned in the given order."""
    total, runs = 0.0, 0
    while True:
        rows = np.random.default_rng([seed, runs]).permutation(queries.shape[0])
        shuffled = np.ascontiguousarray(queries[rows])
        start = CLOCK()
        result = query(shuffled)
        total += CLOCK() - start
        runs += 1
        if total >= min_seconds:
            answers = np.empty_like(result)
            answers[rows] = result
            return total / runs, answers


def disagreements(dist, exact):
    dist = np.asarray(dist, dtype=np.float64).reshape(exact.shape)
    exact = exact.astype(np.float64)
    return int(np.count_nonzero(np.abs(dist - exact) > 1e-5 * exact))


def version(package):
    try:
        return importlib.metadata.version(package)
    except importlib.metadata.PackageNotFoundError:
        return "?"


class PyKdTree:
    key, label = "pykdtree", "pykdtree %s KDTree (leaf 16)" % version("pykdtree")

    def build(self, base):
        return KDTree(base)

    def query(self, tree, queries, k):
        return tree.query(queries, k=k)[0]


class ScipyTree:
    key, label = "scipy-ckdtree", "SciPy %s cKDTree (leaf 16)" % version("scipy")

    def build(self, base):
        return cKDTree(base)

    def query(self, tree, queries, k):
        return tree.query(queries, k=k, workers=1)[0]


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("dir")
    parser.add_argument("workload")
    parser.add_argument("--reps", type=int, default=3)
    parser.add_argument("--min-time", type=float, default=0.1)
    parser.add_argument("--kdspace", type=float, nargs=3, metavar=("BUILD_S", "KNN1", "KNN10"))
    parser.add_argument("--clock", choices=("wall", "cpu"), default="wall")
    args = parser.parse_args()
    global CLOCK
    if args.clock == "cpu":
        CLOCK = time.process_time

    base = np.load(os.path.join(args.dir, "base.npy"))
    queries = np.load(os.path.join(args.dir, "queries.npy"))
    exact = {1: np.load(os.path.join(args.dir, "exact1.npy")), 10: np.load(os.path.join(args.dir, "exact10.npy"))}
    libraries = [PyKdTree(), ScipyTree()]
    seconds = {(lib.key, op): [] for lib in libraries for op in ("build", 1, 10)}
    bad = {lib.key: 0 for lib in libraries}
    for rep in range(args.reps):  # repetitions outside, libraries inside
        for lib in libraries:
            s, tree = timed(lambda: lib.build(base), args.min_time)
            seconds[(lib.key, "build")].append(s)
            for k in (1, 10):
                s, dist = timed_shuffled(lambda q: lib.query(tree, q, k), queries, args.min_time, rep * 100 + k)
                seconds[(lib.key, k)].append(s)
                bad[lib.key] = max(bad[lib.key], disagreements(dist, exact[k]))

    n, nq = base.shape[0], queries.shape[0]
    kd_build, kd1, kd10 = args.kdspace if args.kdspace else (None, None, None)
    print("Python peers (separate process, /usr/bin/python3 %d.%d, one thread, %s): kdspace's best figure ÷ the peer's"
          % (sys.version_info[0], sys.version_info[1], "process CPU time" if args.clock == "cpu" else "wall time"))
    print("(build: the peer's time ÷ kdspace's, so above 1 = kdspace faster).\n")
    print("| library | build s | 1-NN q/s | 10-NN q/s | kdspace build speed-up | kdspace 1-NN ÷ | kdspace 10-NN ÷ |"
          " k-NN distances differing |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    records = []
    for lib in libraries:
        build = statistics.median(seconds[(lib.key, "build")])
        qps = {k: nq / statistics.median(seconds[(lib.key, k)]) for k in (1, 10)}
        ratio = ["%.2f" % (build / kd_build) if kd_build else "–",
                 "%.2f" % (kd1 / qps[1]) if kd1 else "–", "%.2f" % (kd10 / qps[10]) if kd10 else "–"]
        print("| %s | %.4f | %s | %s | %s | %d |" % (lib.label, build, "{:,.0f}".format(qps[1]),
                                                    "{:,.0f}".format(qps[10]), " | ".join(ratio), bad[lib.key]))
        head = {"bench": "points-python", "workload": args.workload, "dim": int(base.shape[1]), "n": int(n),
                "library": lib.key, "reps": args.reps, "threads": 1}
        records.append(dict(head, op="build", build_s=round(build, 6)))
        for k in (1, 10):
            records.append(dict(head, op="knn%d" % k, api="batch", queries=int(nq), qps=round(qps[k], 1),
                                disagreements=bad[lib.key]))
    print()
    for record in records:
        print(json.dumps(record, separators=(",", ":")))
    sys.stdout.flush()
    return 1 if any(bad.values()) else 0


if __name__ == "__main__":
    sys.exit(main())
