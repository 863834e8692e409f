#!/usr/bin/env bash
# Plots the benchmark results: docs/bench_points.png (exact 10-NN queries/s against dimension, one
# line per library, uniform and clustered workloads side by side), docs/bench_rays.png (per scene,
# kdspace's trace speed and build time against Embree user geometry's, 1 thread, with the targets)
# and docs/bench_ann.png (approximate 10-NN: queries/s against recall@10, one panel per data set,
# one line per library).
#
# usage: bench/plot.sh [RESULTS_DIR [OUT_DIR]]     (defaults: bench/results, docs)
#
# Reads RESULTS_DIR/points.jsonl and, when present, RESULTS_DIR/rays.jsonl (the JSON lines of
# kdspace-bench and kdspace-rays-bench) and RESULTS_DIR/ann.jsonl (kdspace-ann-bench);
# python3 (standard library only) turns them into .dat files
# and the plot commands, bench/plot.gp draws them with gnuplot. Without rays.jsonl (or with no
# summary lines in it) the rays picture is not made.
set -euo pipefail

here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/.." && pwd)
results=${1:-$root/bench/results}
out=${2:-$root/docs}

command -v gnuplot >/dev/null || { echo "plot.sh: gnuplot not found (apt-get install gnuplot-nox)" >&2; exit 2; }
command -v python3 >/dev/null || { echo "plot.sh: python3 not found" >&2; exit 2; }
[ -f "$results/points.jsonl" ] || { echo "plot.sh: $results/points.jsonl not found (run bench/run_all.sh)" >&2; exit 2; }
mkdir -p "$out"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

python3 - "$results" "$work" <<'PYTHON'
import json, os, sys

results, work = sys.argv[1], sys.argv[2]

def read_jsonl(path, bench):
    rows = []
    if not os.path.exists(path):
        return rows
    with open(path) as f:
        for number, line in enumerate(f, 1):
            line = line.strip()
            if not line.startswith("{"):
                continue
            try:
                row = json.loads(line)
            except json.JSONDecodeError as e:
                sys.exit(f"plot.sh: {path}: line {number}: {e}")
            if row.get("bench") == bench:
                rows.append(row)
    return rows

KNOWN_COLOURS = {
    "kdspace-rt": "#d62728", "kdspace-ct": "#ff7f0e", "flann": "#1f77b4",
    "nanoflann-rt": "#2ca02c", "nanoflann-ct": "#17becf",
}
PALETTE = ["#d62728", "#1f77b4", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#e377c2", "#17becf", "#7f7f7f"]

def colour_for(name, order):
    if name in KNOWN_COLOURS:
        return KNOWN_COLOURS[name]
    return PALETTE[order.index(name) % len(PALETTE)]

def gp_quote(s):
    return "'" + str(s).replace("'", "''") + "'"

def write_series(name, points):
    path = os.path.join(work, name + ".dat")
    with open(path, "w") as f:
        for x, y in sorted(points.items()):
            f.write(f"{x} {y}\n")
    return path

def plot_command(series, order):
    """series: list of (file, title, library, dashtype)."""
    if not series:  # an empty panel: a blank plot that says so
        return ("set key off; set label 99 'no data' at graph 0.5, 0.5 center; "
                "plot [][1:10] 1 lc rgb 'white' notitle; unset label 99; set key on")
    parts = []
    for path, title, library, dash in series:
        parts.append(f"{gp_quote(path)} using 1:2 with linespoints lw 2 pt 7 ps 0.8 dt {dash} "
                     f"lc rgb {gp_quote(colour_for(library, order))} title {gp_quote(title)}")
    return "plot " + ", ".join(parts)

commands = []

# ---- (a) points: exact 10-NN on one thread, q/s against dimension -----------------------------------
# kdspace and FLANN through their batch calls (threads = 1), nanoflann one query at a time.
points = read_jsonl(os.path.join(results, "points.jsonl"), "points")
knn = [r for r in points if r.get("op") == "knn10" and r.get("threads") == 1 and "qps" in r
       and r.get("data") in ("uniform", "clustered")
       and (r.get("api") == "batch" or not r["library"].startswith("kdspace"))]
lib_order = sorted({r["library"] for r in knn}, key=lambda l: (list(KNOWN_COLOURS).index(l) if l in KNOWN_COLOURS else 99, l))
n_by_dim = {}
for data in ("uniform", "clustered"):
    series = []
    for library in lib_order:
        values = {int(r["dim"]): float(r["qps"]) for r in knn if r["data"] == data and r["library"] == library}
        if values:
            series.append((write_series(f"points_{data}_{library}", values), library, library, 1))
    for r in knn:
        if r["data"] == data:
            n_by_dim.setdefault(int(r["dim"]), set()).add(int(r["n"]))
    commands.append(f"plot_points_{data} = {gp_quote(plot_command(series, lib_order))}")

def short(n):
    exp = len(str(n)) - 1
    return f"1e{exp}" if n == 10 ** exp else f"{n:,}"

tics = ", ".join(f'"{d}\\n(n {"/".join(short(n) for n in sorted(ns))})" {d}' for d, ns in sorted(n_by_dim.items()))
commands.append(f"points_xtics = {gp_quote('set xtics (' + tics + ')' if tics else 'set xtics')}")

with open(os.path.join(work, "series.gp"), "w") as f:
    f.write("\n".join(commands) + "\n")
print(f"plot.sh: {len(knn)} 10-NN measurements ({', '.join(lib_order)})")
PYTHON

gnuplot -e "series='$work/series.gp'; out_points='$out/bench_points.png'" "$here/plot.gp"
echo "plot.sh: wrote $out/bench_points.png"

# ---- (c) approximate search: queries/s against recall@10, a complete gnuplot script made here ---------
if [ -f "$results/ann.jsonl" ]; then
  python3 - "$results/ann.jsonl" "$work" "$out/bench_ann.png" <<'PYTHON'
import json, os, sys
path, work, png = sys.argv[1:4]
rows = [json.loads(l) for l in open(path) if l.startswith("{")]
rows = [r for r in rows if r.get("bench") == "ann" and r.get("op") == "curve"]
datasets = []
for r in rows:
    if r["dataset"] not in datasets:
        datasets.append(r["dataset"])
# One line per library; the forest's settings are split by number of trees.
def line_of(r):
    if r["library"] == "kdspace forest":
        return "kdspace forest, " + r["setting"].split(",")[0]
    return r["library"]
colours = {"kdspace graph": "#d62728", "kdspace forest, trees 1": "#fdae6b", "kdspace forest, trees 4": "#e6550d",
           "hnswlib": "#1f77b4", "faiss HNSW": "#2ca02c", "faiss IVF-Flat": "#9467bd", "FLANN": "#7f7f7f"}
columns = min(3, max(1, len(datasets)))
script = ["set terminal pngcairo size 1500,%d enhanced font 'DejaVu Sans,11'" % (450 * ((len(datasets) + 2) // 3)),
          f"set output '{png}'",
          "set grid xtics ytics lc rgb '#dddddd'",
          "set key bottom left box opaque samplen 3 font ',9'",
          "set logscale y 10", "set xrange [0.8:1.002]", "set xlabel 'recall at k = 10'", "set ylabel 'queries / s (1 thread)'",
          f"set multiplot layout {(len(datasets) + 2) // 3},{columns} title "
          "'kdspace-ann-bench: approximate 10-NN, one line per library (its budget grows along the line)' font ',13'"]
for d in datasets:
    parts = []
    for line, colour in colours.items():
        pts = [(r["recall10"], r["qps"]) for r in rows if r["dataset"] == d and line_of(r) == line]
        if not pts:
            continue
        dat = os.path.join(work, f"ann_{d}_{line}.dat".replace("/", "_").replace(" ", "_").replace(",", ""))
        with open(dat, "w") as f:
            for rec, qps in pts:  # in the order of the budgets
                f.write(f"{rec} {qps}\n")
        width = 3 if line == "kdspace graph" else 2
        parts.append(f"'{dat}' using 1:2 with linespoints lw {width} pt 7 ps 0.6 lc rgb '{colour}' title '{line}'")
    first = next(r for r in rows if r["dataset"] == d)
    script.append(f"set title '{os.path.basename(d)} ({first['dim']}-D, {first['n']:,} points)'")
    script.append("plot " + ", ".join(parts) if parts else "plot 1 notitle")
script.append("unset multiplot")
open(os.path.join(work, "ann.gp"), "w").write("\n".join(script) + "\n")
PYTHON
  gnuplot "$work/ann.gp" && echo "plot.sh: wrote $out/bench_ann.png"
fi
# ---- (b) rays: kdspace against the peer on every scene, a complete gnuplot script made here ------------
if [ -f "$results/rays.jsonl" ] && grep -q '"bench":"rays-summary"' "$results/rays.jsonl"; then
  python3 - "$results/rays.jsonl" "$work" "$out/bench_rays.png" <<'PYTHON'
import json, os, sys
path, work, png = sys.argv[1:4]
rows = [json.loads(l) for l in open(path) if l.startswith("{")]
rows = [r for r in rows if r.get("bench") == "rays-summary"]
dat = os.path.join(work, "rays_summary.dat")
with open(dat, "w") as f:
    for i, r in enumerate(rows):
        label = f"{r['scene']} ({r['boxes']:,})"
        f.write(f"{i} {r['primary_ratio']} {r['random_ratio']} {r['shadow_ratio']} {r['build_ratio']} \"{label}\"\n")
n = len(rows)
script = [f"set terminal pngcairo size {max(1000, 60 * n + 300)},900 noenhanced font 'DejaVu Sans,10'",
          f"set output '{png}'",
          "set grid ytics lc rgb '#dddddd'",
          "set key top left box opaque",
          f"set xrange [-0.7:{n - 0.3}]",
          "set xtics rotate by -45 left font ',9'",
          "set logscale y 2",
          "set multiplot layout 2,1 title 'kdspace-rays-bench: kdspace against Embree 3 user geometry (the faster build quality), 1 thread' font ',13'",
          "set ylabel 'kdspace Mrays/s / Embree Mrays/s'",
          "set title 'trace speed (above 1: kdspace faster; target 1.2)'",
          f"plot 1.2 with lines dt 2 lc rgb '#333333' title 'target 1.2', 1 with lines lc rgb '#999999' notitle, "
          f"'{dat}' using 1:2:xtic(6) with points pt 7 ps 1.3 lc rgb '#d62728' title 'primary (closest hit)', "
          f"'' using 1:3 with points pt 5 ps 1.2 lc rgb '#1f77b4' title 'random (closest hit)', "
          f"'' using 1:4 with points pt 9 ps 1.4 lc rgb '#2ca02c' title 'shadow (any hit)'",
          "set ylabel 'kdspace build s / Embree build s'",
          "set title 'build time (below 3: within the target)'",
          f"plot 3 with lines dt 2 lc rgb '#333333' title 'target 3', 1 with lines lc rgb '#999999' notitle, "
          f"'{dat}' using 1:5:xtic(6) with points pt 7 ps 1.3 lc rgb '#9467bd' title 'SAH build (sah_nlogn, 1 thread)'",
          "unset multiplot"]
open(os.path.join(work, "rays.gp"), "w").write("\n".join(script) + "\n")
PYTHON
  gnuplot "$work/rays.gp" && echo "plot.sh: wrote $out/bench_rays.png"
else
  echo "plot.sh: no rays summary in $results/rays.jsonl; bench_rays.png not made"
fi
