#!/usr/bin/python3
"""`kdspace pairs` and `kdspace count` against SciPy's cKDTree (query_pairs, query_ball_tree,
count_neighbors, sparse_distance_matrix), with and without periodic boundaries (boxsize), under L2,
L1 and Linf, on uniform, clustered, duplicate-heavy and gridded points from 1 to 64 dimensions.

usage: scipy_joins.py KDSPACE_BINARY SCRATCH_DIR

Points are written as float64 .npy, which kdspace reads in double precision, so both compute the
same distances: pairs and counts must be equal, distances equal to 1 ulp (SciPy takes the root with
pow). Radii fall exactly on distances of gridded points (integer coordinates: squared distances are
integers) and on either side of them. Prints PASS/FAIL per check, then "N passed, M failed"; exits 1
if any check failed. Runs with Debian's interpreter (python3-numpy, python3-scipy).
"""
import json
import os
import struct
import subprocess
import sys

import numpy as np
from scipy.spatial import cKDTree

KDSPACE, SCRATCH = sys.argv[1], sys.argv[2]
os.makedirs(SCRATCH, exist_ok=True)
passed = failed = 0
P = {"l2": 2, "l1": 1, "linf": np.inf}


def check(name, ok, detail=""):
    global passed, failed
    if ok:
        passed += 1
        print("PASS", name)
    else:
        failed += 1
        print("FAIL", name, detail)


def kdspace(*args):
    done = subprocess.run([KDSPACE, *args], capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError("kdspace %s: exit %d: %s" % (" ".join(args), done.returncode, done.stderr))
    return done.stdout


def save(name, points):
    path = os.path.join(SCRATCH, name + ".npy")
    np.save(path, np.ascontiguousarray(points, dtype=np.float64))
    return path


def read_pairs(path):
    with open(path, "rb") as f:
        (m,) = struct.unpack("<Q", f.read(8))
        return np.frombuffer(f.read(8 * m), dtype="<u4").reshape(m, 2).astype(np.int64)


def sorted_pairs(pairs):
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    return pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))]


def data_sets(rng):
    """(name, points, others, boxsize for the torus runs, radii): radii in ascending order."""
    uniform3 = rng.random((1500, 3))
    blobs = np.concatenate([c + 0.02 * rng.standard_normal((300, 5)) for c in rng.random((4, 5))])
    blobs = np.mod(blobs, 1.0)
    dupes = rng.random((12, 2))[rng.integers(0, 12, 800)]
    grid3 = rng.integers(0, 8, (900, 3)).astype(np.float64)
    line = rng.random((700, 1))
    wide = rng.random((400, 16))
    grid64 = rng.integers(0, 3, (150, 64)).astype(np.float64)
    exact = [1.0, np.sqrt(2.0), np.sqrt(3.0), 2.0, np.sqrt(5.0)]
    around = sorted(exact + [np.nextafter(r, 0) for r in exact] + [np.nextafter(r, 9) for r in exact])
    return [
        ("uniform-3d", uniform3, rng.random((600, 3)), [1.0], [0.0, 0.02, 0.05, 0.1]),
        ("clustered-5d", blobs, np.mod(blobs[::3] + 0.01, 1.0), [1.0, 1.0, 0.0, 1.0, 1.0], [0.01, 0.03, 0.1]),
        ("duplicates-2d", dupes, dupes[::5], [1.0], [0.0, 0.05, 0.2]),
        ("grid-3d", grid3, rng.integers(0, 8, (300, 3)).astype(np.float64), [8.0], [0.0] + around),
        ("line-1d", line, rng.random((200, 1)), [1.0], [0.001, 0.01]),
        ("uniform-16d", wide, rng.random((100, 16)), [1.0], [0.6, 0.9]),
        ("grid-64d", grid64, rng.integers(0, 3, (50, 64)).astype(np.float64), [3.0], [np.sqrt(20.0), 5.0, 6.0]),
    ]


def run_case(name, a, b, boxsize, radii, metric):
    p = P[metric]
    label = "%s %s%s" % (name, metric, " periodic" if boxsize else "")
    extra = ["--metric", metric] + (["--boxsize", ",".join(repr(float(x)) for x in boxsize)] if boxsize else [])
    scipy_box = None if not boxsize else np.array(boxsize * (a.shape[1] if len(boxsize) == 1 else 1))
    ta, tb = cKDTree(a, boxsize=scipy_box), cKDTree(b, boxsize=scipy_box)
    pa, pb = save(name + "-a", a), save(name + "-b", b)
    out = os.path.join(SCRATCH, "out.pairs")
    dist = os.path.join(SCRATCH, "out.npy")
    r = radii[len(radii) // 2]

    # pairs within one set: query_pairs; their distances: sparse_distance_matrix
    kdspace("pairs", "--base", pa, "-r", repr(r), "--out", out, "--distances", dist, *extra)
    ours = read_pairs(out)
    want = sorted_pairs(ta.query_pairs(r, p=p, output_type="ndarray"))
    check(label + ": pairs within one set = query_pairs", np.array_equal(ours, want), "%d vs %d" % (len(ours), len(want)))
    sdm = ta.sparse_distance_matrix(ta, r, p=p, output_type="ndarray")
    sdm = sdm[sdm["i"] < sdm["j"]]
    sdm = sdm[np.lexsort((sdm["j"], sdm["i"]))]
    d = np.load(dist).reshape(-1)
    same = len(d) == len(sdm) and np.array_equal(ours, np.stack([sdm["i"], sdm["j"]], axis=1))
    same = same and np.allclose(d, sdm["v"], rtol=4e-16, atol=0)
    check(label + ": distances = sparse_distance_matrix", same)

    # pairs across two sets: query_ball_tree
    kdspace("pairs", "--base", pa, "--with", pb, "-r", repr(r), "--out", out, *extra)
    ours = read_pairs(out)
    lists = ta.query_ball_tree(tb, r, p=p)
    want = sorted_pairs([(i, j) for i, js in enumerate(lists) for j in js])
    check(label + ": pairs across two sets = query_ball_tree", np.array_equal(ours, want), "%d vs %d" % (len(ours), len(want)))

    # counts at all radii, in one set (unordered distinct pairs) and across two
    text = ",".join(repr(float(x)) for x in radii)
    got = json.loads(kdspace("count", "--base", pa, "-r", text, *extra))
    want = [(int(c) - len(a)) // 2 for c in ta.count_neighbors(ta, np.array(radii), p=p)]
    check(label + ": counts in one set = count_neighbors", got["counts"] == want, "%s vs %s" % (got["counts"], want))
    got = json.loads(kdspace("count", "--base", pa, "--with", pb, "-r", text, *extra))
    want = [int(c) for c in ta.count_neighbors(tb, np.array(radii), p=p)]
    check(label + ": counts across two sets = count_neighbors", got["counts"] == want, "%s vs %s" % (got["counts"], want))


def main():
    rng = np.random.default_rng(17)
    for name, a, b, boxsize, radii in data_sets(rng):
        metrics = ["l2", "l1", "linf"] if a.shape[1] <= 5 else ["l2"]
        for metric in metrics:
            for periodic in (False, True):
                try:
                    run_case(name, a, b, boxsize if periodic else None, radii, metric)
                except RuntimeError as e:
                    check("%s %s" % (name, metric), False, str(e))
    print("%d passed, %d failed" % (passed, failed))
    sys.exit(1 if failed else 0)


if __name__ == "__main__":
    main()
