#!/usr/bin/env python3
"""Condenses bench/results/points.jsonl (kdspace-bench) into one markdown table: per workload,
kdspace's better variant against the best peer for each operation. The peers: FLANN, nanoflann,
CGAL, FAISS's flat index and, from the Python side tables, pykdtree and SciPy's cKDTree.

usage: bench/summary.py [points.jsonl]   (default bench/results/points.jsonl); markdown on stdout
"""
import json
import sys
from collections import defaultdict

path = sys.argv[1] if len(sys.argv) > 1 else "bench/results/points.jsonl"
by = defaultdict(dict)  # (workload) -> {(library, op, threads): record}
order = []
for line in open(path):
    r = json.loads(line)
    if r.get("bench") not in ("points", "points-python"):
        continue
    w = r["workload"]
    if w not in order:
        order.append(w)
    by[w][(r["library"], r["op"], r.get("threads", 1), r.get("api"))] = r

KD = ("kdspace-rt", "kdspace-ct")
PEERS = ("flann", "nanoflann-rt", "nanoflann-ct", "cgal", "faiss-flat", "pykdtree", "scipy-ckdtree")


def best(rec, libs, op, key, threads=1, lower=False, api=None):
    vals = [r[key] for (lib, o, t, a), r in rec.items()
            if lib in libs and o == op and t == threads and (api is None or a == api) and key in r]
    if not vals:
        return None
    return min(vals) if lower else max(vals)


def ratio(a, b):
    return "–" if a is None or b is None or b == 0 else "%.2f" % (a / b)


print("| workload | 1-NN | 10-NN | radius ~10 | radius ~100 | ε = 0.5 | ε = 2 | build time | index B/pt | "
      "kdspace 2 thr ÷ 1 thr |")
print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
for w in order:
    rec = by[w]
    cells = []
    for op in ("knn1", "knn10", "radius10", "radius100", "approx_eps0.5", "approx_eps2"):
        cells.append(ratio(best(rec, KD, op, "qps", api="batch"), best(rec, PEERS, op, "qps")))
    kd_build = best(rec, KD, "build", "build_s", lower=True)
    peer_build = best(rec, PEERS, "build", "build_s", lower=True)
    cells.append("%.3f s vs %.3f s" % (kd_build, peer_build))
    cells.append("%.1f vs %.1f" % (best(rec, KD, "build", "index_bytes_per_point", lower=True),
                                   best(rec, PEERS, "build", "index_bytes_per_point", lower=True)))
    speedups = [r["speedup_vs_1"] for (lib, o, t, a), r in rec.items() if lib in KD and o == "batch10" and t == 2]
    cells.append("%.2f" % max(speedups) if speedups else "–")
    first = next(iter(rec.values()))
    name = "%s (%s, %s-D, n %g)" % (w, first["data"], first["dim"], first["n"])
    print("| " + name + " | " + " | ".join(cells) + " |")
