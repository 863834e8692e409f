#!/usr/bin/python3
"""kdspace.KDTree beside SciPy's cKDTree and pykdtree, from Python.

One command (after a release build):

    /usr/bin/python3 bench/python_bench.py [--build build/release] [--n 1000000] [--reps 3]

For each worker setting (1, and all cores) it starts itself once more with OMP_NUM_THREADS set
(pykdtree's queries use OpenMP, whose thread count is read when it starts); that process builds
each library's tree over the same points and answers the same queries, repetitions interleaved
across the libraries (median of --reps), and checks every answer against kdspace's: indices equal
and distances within 1e-6 relative (pykdtree computes in float32 for float32 data). It prints one
Markdown table: build, query and build + query seconds, and kdspace's speed-up over each peer.

Data: n uniform random 3-D points and n queries from the same distribution (seeded), float64 (all
three libraries) and float32 (kdspace and pykdtree keep it; cKDTree converts it to float64).
"""

import argparse
import json
import os
import statistics
import subprocess
import sys
import time

import numpy as np


def check(name, reference, d, i, base, queries, case):
    """The same neighbours as kdspace: distances within 1e-6 (relative), and the same rows except
    where another row lies at the same distance (ties, or near-ties that rounding orders either way:
    cKDTree computes float32 data in float64); such a row's own distance is checked."""
    ref_d, ref_i = reference
    d, i = np.asarray(d, dtype=np.float64).reshape(ref_d.shape), np.asarray(i, dtype=np.int64).reshape(ref_i.shape)
    if not np.allclose(d, ref_d, rtol=1e-6, atol=0):
        raise SystemExit(f"{name} disagrees with kdspace on distances ({case})")
    rows, ref_rows = i.reshape(len(i), -1), ref_i.reshape(len(i), -1)
    for q in np.flatnonzero((rows != ref_rows).any(axis=1)):
        own = np.sqrt(((base[rows[q]].astype(np.float64) - queries[q].astype(np.float64)) ** 2).sum(axis=1))
        if len(set(rows[q].tolist())) != rows.shape[1] or \
                not np.allclose(own, ref_d.reshape(len(i), -1)[q], rtol=1e-6, atol=0):
            raise SystemExit(f"{name} disagrees with kdspace on the rows of query {q} ({case})")


def run_one_setting(args):
    sys.path.insert(0, os.path.join(args.build, "python"))
    import kdspace
    from pykdtree.kdtree import KDTree as PyKDTree
    from scipy.spatial import cKDTree

    workers = -1 if args.workers == "all" else 1
    rng = np.random.default_rng(1)
    base64, queries64 = rng.random((args.n, 3)), rng.random((args.n, 3))
    cases = []
    for dtype in (np.float64, np.float32):
        base, queries = base64.astype(dtype), queries64.astype(dtype)
        libraries = {
            "kdspace": (lambda b: kdspace.KDTree(b), lambda t, q, k: t.query(q, k=k, workers=workers)),
            "scipy cKDTree": (lambda b: cKDTree(b), lambda t, q, k: t.query(q, k=k, workers=workers)),
            "pykdtree": (lambda b: PyKDTree(b), lambda t, q, k: t.query(q, k=k)),
        }
        for k in (1, 10):
            times = {name: {"build": [], "query": []} for name in libraries}
            reference = None
            for _ in range(args.reps):
                for name, (build, query) in libraries.items():
                    started = time.perf_counter()
                    tree = build(base)
                    built = time.perf_counter()
                    d, i = query(tree, queries, k)
                    done = time.perf_counter()
                    times[name]["build"].append(built - started)
                    times[name]["query"].append(done - built)
                    if reference is None:
                        reference = (np.asarray(d, dtype=np.float64), np.asarray(i, dtype=np.int64))
                    else:
                        check(name, reference, d, i, base, queries, f"{np.dtype(dtype).name}, k={k}")
                    del tree, d, i
            for name, t in times.items():
                cases.append({"workers": args.workers, "dtype": np.dtype(dtype).name, "k": k, "library": name,
                              "build_s": statistics.median(t["build"]), "query_s": statistics.median(t["query"])})
    for case in cases:
        print(json.dumps(case), flush=True)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--build", default=os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "build",
                                                         "release"), help="the CMake build folder (default build/release)")
    parser.add_argument("--n", type=int, default=1_000_000, help="points, and queries (default 1e6)")
    parser.add_argument("--reps", type=int, default=3, help="interleaved repetitions (median)")
    parser.add_argument("--workers", choices=["1", "all"], help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.workers:
        run_one_setting(args)
        return

    rows = []
    for workers in ("1", "all"):
        env = dict(os.environ)
        if workers == "1":
            env["OMP_NUM_THREADS"] = "1"
        else:
            env.pop("OMP_NUM_THREADS", None)
        out = subprocess.run([sys.executable, __file__, "--build", args.build, "--n", str(args.n), "--reps",
                              str(args.reps), "--workers", workers], env=env, capture_output=True, text=True)
        if out.returncode != 0:
            raise SystemExit(out.stderr or out.stdout)
        rows += [json.loads(line) for line in out.stdout.splitlines() if line.startswith("{")]

    cores = os.cpu_count()
    print(f"{args.n:,} uniform 3-D points, {args.n:,} queries; median of {args.reps} interleaved runs; "
          f"workers = 1 and all ({cores} cores)\n")
    print("| workers | dtype | k | library | build s | query s | build + query s | kdspace speed-up |")
    print("|---:|---|---:|---|---:|---:|---:|---:|")
    for row in rows:
        ours = next(r for r in rows if r["library"] == "kdspace" and
                    all(r[key] == row[key] for key in ("workers", "dtype", "k")))
        total = row["build_s"] + row["query_s"]
        speedup = total / (ours["build_s"] + ours["query_s"])
        print(f"| {row['workers']} | {row['dtype']} | {row['k']} | {row['library']} | {row['build_s']:.3f} | "
              f"{row['query_s']:.3f} | {total:.3f} | {speedup:.2f} |")


if __name__ == "__main__":
    main()
