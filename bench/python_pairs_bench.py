#!/usr/bin/python3
"""kdspace.KDTree's pair methods beside SciPy's cKDTree, from Python.

One command (after a release build):

    /usr/bin/python3 bench/python_pairs_bench.py [--build build/release] [--n 1000000] [--reps 3]

Over n uniform random 3-D float64 points in the unit cube (seeded), with both libraries' trees built
beforehand: query_pairs(r) (output_type='ndarray') with r chosen for about 10 pairs per point, and
count_neighbors of the tree with itself at 20 radii up to that r. Repetitions interleaved across
the libraries (median of --reps); the answers are checked equal. Prints one Markdown table:
seconds per call and kdspace's speed-up over cKDTree. One worker (neither method takes workers).
"""

import argparse
import os
import statistics
import sys
import time

import numpy as np


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--build", default=os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "build",
                                                        "release"), help="the build folder (default build/release)")
    parser.add_argument("--n", type=int, default=1_000_000, help="points (default 1e6)")
    parser.add_argument("--reps", type=int, default=3, help="interleaved repetitions (median)")
    args = parser.parse_args()
    sys.path.insert(0, os.path.join(args.build, "python"))
    import kdspace
    from scipy.spatial import cKDTree

    points = np.random.default_rng(7).random((args.n, 3))
    r = (10 * 3 / (4 * np.pi * args.n)) ** (1 / 3)  # a ball of radius r holds ~10 points
    radii = np.linspace(r / 20, r, 20)
    trees = {"kdspace": kdspace.KDTree(points), "cKDTree": cKDTree(points)}
    calls = {
        "query_pairs": lambda t: t.query_pairs(r, output_type="ndarray"),
        "count_neighbors (20 radii)": lambda t: t.count_neighbors(t, radii),
    }
    print(f"n = {args.n} uniform 3-D float64 points, r = {r:.4g}, median of {args.reps}\n")
    print("| method | kdspace s | cKDTree s | speed-up |")
    print("|---|---|---|---|")
    for name, call in calls.items():
        seconds = {lib: [] for lib in trees}
        answers = {}
        for _ in range(args.reps):
            for lib, tree in trees.items():
                start = time.perf_counter()
                answers[lib] = call(tree)
                seconds[lib].append(time.perf_counter() - start)
        a, b = answers["kdspace"], answers["cKDTree"]
        if name == "query_pairs":
            a, b = a[np.lexsort((a[:, 1], a[:, 0]))], b[np.lexsort((b[:, 1], b[:, 0]))]
        if not np.array_equal(a, b):
            raise SystemExit(f"{name}: kdspace and cKDTree disagree")
        ours, theirs = statistics.median(seconds["kdspace"]), statistics.median(seconds["cKDTree"])
        print(f"| {name} | {ours:.3f} | {theirs:.3f} | {theirs / ours:.2f}x |")


if __name__ == "__main__":
    main()
