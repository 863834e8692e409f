#!/usr/bin/env bash
# Tests of the `kdspace` command: exit codes, error messages and results.
#
#   usage: cli_tests.sh KDSPACE_BINARY SCRATCH_DIR
#
# Makes small input files (good and broken) with python3's standard library, runs the command on them
# and checks exit codes (0 success, 2 usage error, 1 bad data or I/O), stderr messages and outputs
# (ids compared with a brute force written in Python). Prints PASS/FAIL for each check and, last,
# "N passed, M failed"; exits 1 if any check failed.
set -u

if [ $# -ne 2 ]; then
  echo "usage: $0 KDSPACE_BINARY SCRATCH_DIR" >&2
  exit 2
fi
KDSPACE=$(cd "$(dirname "$1")" && pwd)/$(basename "$1")
SCRATCH=$2
mkdir -p "$SCRATCH" && cd "$SCRATCH" || exit 2
command -v python3 >/dev/null || { echo "python3 is needed" >&2; exit 2; }

passed=0
failed=0
pass() { echo "PASS $1"; passed=$((passed + 1)); }
fail() {
  echo "FAIL $1: $2"
  echo "  command: kdspace ${last_args:-}"
  echo "  exit code: ${rc:-}"
  echo "  stderr: $(head -c 600 err.txt 2>/dev/null)"
  failed=$((failed + 1))
}

# run ARGS...: runs the command with stdin closed; stdout in out.txt, stderr in err.txt, code in $rc.
run() {
  last_args="$*"
  "$KDSPACE" "$@" >out.txt 2>err.txt </dev/null
  rc=$?
}

# expect_error NAME CODE PATTERN... -- ARGS...: the command fails with CODE, stderr begins with
# "kdspace: error: " and contains every PATTERN (fixed strings); a usage error (2) adds the hint line.
expect_error() {
  local name=$1 code=$2
  shift 2
  local patterns=()
  while [ $# -gt 0 ] && [ "$1" != "--" ]; do
    patterns+=("$1")
    shift
  done
  shift
  run "$@"
  if [ "$rc" -ne "$code" ]; then fail "$name" "expected exit code $code, got $rc"; return; fi
  if ! head -n 1 err.txt | grep -q '^kdspace: error: '; then fail "$name" "stderr does not begin with 'kdspace: error: '"; return; fi
  local p
  for p in "${patterns[@]}"; do
    if ! grep -qF -- "$p" err.txt; then fail "$name" "stderr does not mention '$p'"; return; fi
  done
  if [ "$code" -eq 2 ] && ! grep -q "^run 'kdspace .*--help'$" err.txt; then fail "$name" "no hint line run 'kdspace ... --help'"; return; fi
  if [ -s out.txt ]; then fail "$name" "an error printed something on stdout"; return; fi
  pass "$name"
}

# expect_ok NAME ARGS...: the command succeeds and prints nothing on stderr (no progress when stderr
# is not a terminal).
expect_ok() {
  local name=$1
  shift
  run "$@"
  if [ "$rc" -ne 0 ]; then fail "$name" "expected exit code 0, got $rc"; return 1; fi
  if [ -s err.txt ]; then fail "$name" "stderr is not empty"; return 1; fi
  return 0
}

# ---- input files ---------------------------------------------------------------------------------
python3 - <<'EOF' || { echo "FAIL could not make the input files"; echo "0 passed, 1 failed"; exit 1; }
import random, struct

rng = random.Random(7)

def write_csv(path, rows, header=None):
    with open(path, "w") as f:
        if header:
            f.write(header + "\n")
        for r in rows:
            f.write(",".join(str(v) for v in r) + "\n")

def write_fvecs(path, rows):
    with open(path, "wb") as f:
        for r in rows:
            f.write(struct.pack("<i%df" % len(r), len(r), *r))

def write_bvecs(path, rows):
    with open(path, "wb") as f:
        for r in rows:
            f.write(struct.pack("<i%dB" % len(r), len(r), *r))

def write_npy(path, rows, dtype="<f4"):
    fmt = {"<f4": "f", "<f8": "d"}[dtype]
    header = "{'descr': '%s', 'fortran_order': False, 'shape': (%d, %d), }" % (dtype, len(rows), len(rows[0]))
    pad = 64 - (10 + len(header) + 1) % 64
    header = header + " " * pad + "\n"
    with open(path, "wb") as f:
        f.write(b"\x93NUMPY\x01\x00" + struct.pack("<H", len(header)) + header.encode("latin1"))
        for r in rows:
            f.write(struct.pack("<%d%s" % (len(r), fmt), *r))

# Small integer coordinates: every distance is exact in float and double, and ties are frequent, so
# the tie rule (smaller index first) is exercised too.
base = [[rng.randint(0, 9) for _ in range(3)] for _ in range(40)]
query = [[rng.randint(0, 9) for _ in range(3)] for _ in range(7)]
write_csv("base.csv", base, header="x,y,z")
write_csv("query.csv", query)
write_npy("base.npy", base)
write_npy("base64.npy", base, "<f8")
write_fvecs("query.fvecs", query)
write_bvecs("base.bvecs", base)
write_csv("query4.csv", [[1, 2, 3, 4], [5, 6, 7, 8]])
write_csv("query_neg.csv", [[1, 2, 3], [3, 3, -1]])  # row 2 lies outside a periodic box [0, L)
# 16-D, for the neighbour graph (built from dimension 8 on).
wide = [[rng.randint(0, 9) for _ in range(16)] for _ in range(300)]
write_csv("wide.csv", wide)
write_bvecs("wide.bvecs", wide)
write_csv("wide_query.csv", [[rng.randint(0, 9) for _ in range(16)] for _ in range(12)])

# 2-D and 3-D sets searched by a compile-time-dimension tree, and the same points with zero columns
# added up to 4-D, searched by the run-time-dimension tree: a zero term changes no distance, so the
# two must write the same bytes. Random coordinates (rounding matters) with some repeated points.
for d in (2, 3):
    pts = [[round(rng.uniform(-5, 5), 6) for _ in range(d)] for _ in range(300)]
    pts += [pts[i][:] for i in range(0, 300, 7)]
    qs = [[round(rng.uniform(-5, 5), 6) for _ in range(d)] for _ in range(25)] + pts[:5]
    pad = lambda rows: [r + [0.0] * (4 - d) for r in rows]
    for name, rows in (("dimbase%d" % d, pts), ("dimquery%d" % d, qs)):
        write_csv(name + ".csv", rows)
        write_csv(name + "pad.csv", pad(rows))
        write_npy(name + ".npy", rows)
        write_npy(name + "pad.npy", pad(rows))
    # The same in [0, 10) for --boxsize 10 (the padded axis, all zeros, adds nothing on the torus either).
    for name, rows in (("dimbase%dbox" % d, pts), ("dimquery%dbox" % d, qs)):
        moved = [[x + 5 for x in r] for r in rows]
        write_csv(name + ".csv", moved)
        write_csv(name + "pad.csv", pad(moved))

# Radius: two tight groups far apart and a few points between, so rows differ in length.
cl = [[0, 0], [1, 0], [0, 1], [1, 1], [2, 2], [10, 10], [11, 10], [20, 0], [30, 30], [31, 31]]
write_csv("cluster.csv", cl)
write_csv("cluster_query.csv", [[0, 0], [10, 10], [30, 30], [50, 50], [5, 5]])

# Broken files.
rows = [[1.5, 2.5, 3.5]] * 5
rows_nan = [r[:] for r in rows]
rows_nan[2][1] = float("nan")
write_csv("nan.csv", rows_nan, header="a,b,c")        # data row 3 holds a NaN
write_fvecs("trunc.fvecs", [[1, 2, 3, 4]] * 3)
data = open("trunc.fvecs", "rb").read()
open("trunc.fvecs", "wb").write(data[:-6])             # row 3 cut short
write_bvecs("trunc.bvecs", base[:4])
data = open("trunc.bvecs", "rb").read()
open("trunc.bvecs", "wb").write(data[:-1])             # row 4 cut short
open("empty.csv", "w").close()
open("empty.fvecs", "wb").close()
write_csv("ragged.csv", [[1, 2, 3], [4, 5, 6], [7, 8]])
write_csv("base.txt", base)
EOF

# ---- usage errors: exit 2 ------------------------------------------------------------------------
expect_error "unknown option" 2 "--bogus" -- knn --base base.csv --query query.csv -k 3 --out ids.ivecs --bogus
expect_error "missing --base" 2 "--base" -- knn --query query.csv -k 3 --out ids.ivecs
expect_error "missing value" 2 "--out" -- knn --base base.csv --query query.csv -k 3 --out
expect_error "-k 0 is a usage error" 2 "-k" -- knn --base base.csv --query query.csv -k 0 --out ids.ivecs
expect_error "-k ten" 2 "-k" "ten" -- knn --base base.csv --query query.csv -k ten --out ids.ivecs
expect_error "-k -3" 2 "-k" "-3" -- knn --base base.csv --query query.csv -k -3 --out ids.ivecs
expect_error "--leaf 0" 2 "--leaf" -- knn --base base.csv --query query.csv -k 3 --out ids.ivecs --leaf 0
expect_error "--metric bad" 2 "--metric" "l3" -- knn --base base.csv --query query.csv -k 3 --out ids.ivecs --metric l3
expect_error "--forest 0" 2 "--forest" -- knn --base base.csv --query query.csv -k 3 --out ids.ivecs --forest 0
expect_error "--checks without --forest" 2 "--checks needs --forest" -- knn --base base.csv --query query.csv -k 3 --out ids.ivecs --checks 10
expect_error "--checks -5" 2 "--checks" -- knn --base base.csv --query query.csv -k 3 --out ids.ivecs --forest 2 --checks -5
expect_error "--recall 0" 2 "--recall must be in (0, 1]" -- knn --base base.csv --query query.csv -k 3 --out ids.ivecs --recall 0
expect_error "--recall 1.5" 2 "--recall" "1.5" -- knn --base base.csv --query query.csv -k 3 --out ids.ivecs --recall 1.5
expect_error "--recall with --checks" 2 "exclude each other" -- knn --base base.csv --query query.csv -k 3 --out ids.ivecs --recall 0.9 --checks 9
expect_error "--forest with --eps" 2 "--eps" -- knn --base base.csv --query query.csv -k 3 --out ids.ivecs --forest 2 --eps 0.5
expect_error "--forest with --metric l1" 2 "l2 only" -- knn --base base.csv --query query.csv -k 3 --out ids.ivecs --forest 2 --metric l1
expect_error "--forest with --axis" 2 "--axis" -- knn --base base.csv --query query.csv -k 3 --out ids.ivecs --forest 2 --axis cycle
expect_error "--ef without --graph" 2 "--ef needs --graph" -- knn --base base.csv --query query.csv -k 3 --out ids.ivecs --ef 10
expect_error "--ef with --forest" 2 "--ef needs --graph" -- knn --base base.csv --query query.csv -k 3 --out ids.ivecs --forest 2 --ef 10
expect_error "--forest with --graph" 2 "exclude each other" -- knn --base base.csv --query query.csv -k 3 --out ids.ivecs --forest 2 --graph
expect_error "--recall with --ef" 2 "exclude each other" -- knn --base base.csv --query query.csv -k 3 --out ids.ivecs --recall 0.9 --graph --ef 9
expect_error "--degree 1" 2 "--degree" -- knn --base base.csv --query query.csv -k 3 --out ids.ivecs --graph --degree 1
expect_error "--degree with --forest" 2 "--degree applies to the graph" -- knn --base base.csv --query query.csv -k 3 --out ids.ivecs --forest 2 --degree 8
expect_error "--degree alone" 2 "--degree needs --graph or --recall" -- knn --base base.csv --query query.csv -k 3 --out ids.ivecs --degree 8
expect_error "--graph with --eps" 2 "--eps" -- knn --base base.csv --query query.csv -k 3 --out ids.ivecs --graph --eps 0.5
expect_error "negative radius" 2 "-r" -- radius --base base.csv --query query.csv -r -0.5 --out ids.ivecs
expect_error "NaN radius" 2 "-r" -- radius --base base.csv --query query.csv -r nan --out ids.ivecs
expect_error "unknown command" 2 "frobnicate" -- frobnicate

# ---- bad data and I/O: exit 1 --------------------------------------------------------------------
expect_error "k > n" 1 "k = 41" "40" -- knn --base base.csv --query query.csv -k 41 --out ids.ivecs
expect_error "dimension mismatch" 1 "query4.csv" "base.csv" "dimension 4" "dimension 3" -- \
  knn --base base.csv --query query4.csv -k 3 --out ids.ivecs
expect_error "NaN in a csv base" 1 "nan.csv: row 3" "not finite" -- knn --base nan.csv --query query.csv -k 1 --out ids.ivecs
expect_error "NaN in csv queries" 1 "nan.csv: row 3" -- knn --base base.csv --query nan.csv -k 1 --out ids.ivecs
expect_error "NaN in csv queries with --recall" 1 "nan.csv: row 3" -- knn --base base.csv --query nan.csv -k 1 --out ids.ivecs --recall 0.9
expect_error "truncated fvecs" 1 "trunc.fvecs: row 3" -- knn --base trunc.fvecs --query query.csv -k 1 --out ids.ivecs
expect_error "empty csv" 1 "empty.csv" -- knn --base empty.csv --query query.csv -k 1 --out ids.ivecs
expect_error "empty fvecs" 1 "empty.fvecs" -- knn --base base.csv --query empty.fvecs -k 1 --out ids.ivecs
expect_error "rows of different lengths" 1 "ragged.csv: row 3" -- knn --base ragged.csv --query query.csv -k 1 --out ids.ivecs
expect_error "nonexistent file" 1 "missing.fvecs" -- knn --base missing.fvecs --query query.csv -k 1 --out ids.ivecs
expect_error "unknown extension" 1 "base.txt" -- knn --base base.txt --query query.csv -k 1 --out ids.ivecs
expect_error "unwritable output" 1 "no-such-dir/ids.ivecs" -- knn --base base.csv --query query.csv -k 1 --out no-such-dir/ids.ivecs

# ---- results -------------------------------------------------------------------------------------
# check_results NAME MODE METRIC PARAM BASE QUERY: ids.ivecs and dist.fvecs equal a Python brute force
# (ascending distance, ties by smaller index; MODE knn: PARAM = k, MODE radius: PARAM = r).
check_results() {
  local name=$1
  if python3 - "$@" <<'EOF' >check.txt 2>&1; then pass "$name"; else fail "$name" "$(cat check.txt)"; fi
import math, struct, sys
_, mode, metric, param, base_path, query_path = sys.argv[1:7]

def read_csv(path):
    rows = []
    for line in open(path):
        line = line.strip()
        if line and not line[0].isalpha():
            rows.append([float(v) for v in line.split(",")])
    return rows

def read_vecs(path, fmt):
    data, rows, at = open(path, "rb").read(), [], 0
    while at < len(data):
        (d,) = struct.unpack_from("<i", data, at)
        rows.append(list(struct.unpack_from("<%d%s" % (d, fmt), data, at + 4)))
        at += 4 + 4 * d
    return rows

def dist(a, b):
    diffs = [abs(x - y) for x, y in zip(a, b)]
    return {"l2": math.sqrt(sum(t * t for t in diffs)), "l1": sum(diffs), "linf": max(diffs)}[metric]

base, queries = read_csv(base_path), read_csv(query_path)
ids, dists = read_vecs("ids.ivecs", "i"), read_vecs("dist.fvecs", "f")
assert len(ids) == len(queries), "%d rows of ids for %d queries" % (len(ids), len(queries))
for q, (query, got, got_d) in enumerate(zip(queries, ids, dists)):
    order = sorted((dist(query, p), i) for i, p in enumerate(base))
    want = order[: int(param)] if mode == "knn" else [(d, i) for d, i in order if d <= float(param)]
    assert got == [i for _, i in want], "query %d: ids %s, expected %s" % (q + 1, got, [i for _, i in want])
    for (d, _), g in zip(want, got_d):
        assert abs(d - g) <= 1e-6 * max(1.0, d), "query %d: distance %r, expected %r" % (q + 1, g, d)
if mode == "radius":
    lengths = sorted(set(len(r) for r in ids))
    assert len(lengths) > 1, "all radius rows have the same length %s" % lengths
print("ok")
EOF
}

if expect_ok "knn csv" knn --base base.csv --query query.csv -k 5 --out ids.ivecs --distances dist.fvecs; then
  check_results "knn csv equals brute force" knn l2 5 base.csv query.csv
fi
if expect_ok "knn npy float32 base, fvecs queries" knn --base base.npy --query query.fvecs -k 7 --out ids.ivecs --distances dist.fvecs --threads 2; then
  check_results "knn npy equals brute force" knn l2 7 base.csv query.csv
fi
if expect_ok "knn float64 npy base" knn --base base64.npy --query query.csv -k 4 --out ids.ivecs --distances dist.fvecs; then
  check_results "knn float64 npy equals brute force" knn l2 4 base.csv query.csv
fi
for metric in l1 linf; do
  if expect_ok "knn --metric $metric" knn --base base.csv --query query.csv -k 6 --out ids.ivecs --distances dist.fvecs \
    --metric=$metric --axis cycle --position sliding --leaf 2; then
    check_results "knn --metric $metric equals brute force" knn $metric 6 base.csv query.csv
  fi
done
if expect_ok "knn k = n" knn --base base.csv --query query.csv -k 40 --out ids.ivecs --distances dist.fvecs --position middle --leaf 1; then
  check_results "knn k = n equals brute force" knn l2 40 base.csv query.csv
fi
# A forest whose budget covers every point is exact.
if expect_ok "knn --forest, checks = n" knn --base base.csv --query query.csv -k 5 --out ids.ivecs --distances dist.fvecs \
  --forest 3 --checks 40 --leaf 2; then
  check_results "knn --forest with checks = n equals brute force" knn l2 5 base.csv query.csv
fi
if expect_ok "knn --forest on a float32 base" knn --base base.npy --query query.fvecs -k 7 --out ids.ivecs --distances dist.fvecs \
  --forest 2 --checks 40 --threads 2; then
  check_results "knn --forest float32 equals brute force" knn l2 7 base.csv query.csv
fi
# A .bvecs base is read as bytes and kept as bytes, with the same answers.
if expect_ok "knn --forest on a bvecs base" knn --base base.bvecs --query query.fvecs -k 6 --out ids.ivecs --distances dist.fvecs \
  --forest 2 --checks 40 --threads 2; then
  check_results "knn --forest on a bvecs base equals brute force" knn l2 6 base.csv query.csv
fi
if expect_ok "knn --forest --stats on a bvecs base" knn --base base.bvecs --query query.csv -k 3 --out ids.ivecs --forest 2 --stats; then
  if grep -qF '"stored_as": "bytes"' out.txt; then pass "a bvecs base is stored as bytes"
  else fail "a bvecs base is stored as bytes" "stdout: $(head -c 400 out.txt)"; fi
fi
# The graph: with a pool as large as the data the answer is exact (from the trees); on a bvecs base too.
if expect_ok "knn --graph, ef = n" knn --base wide.csv --query wide_query.csv -k 5 --out ids.ivecs --distances dist.fvecs \
  --graph --ef 300 --threads 2; then
  check_results "knn --graph with ef = n equals brute force" knn l2 5 wide.csv wide_query.csv
fi
if expect_ok "knn --graph on a bvecs base, ef = n" knn --base wide.bvecs --query wide_query.csv -k 4 --out ids.ivecs \
  --distances dist.fvecs --graph --ef 300 --degree 8; then
  check_results "knn --graph on a bvecs base equals brute force" knn l2 4 wide.csv wide_query.csv
fi
expect_error "knn --forest on a truncated bvecs base" 1 "trunc.bvecs: row 4: truncated" -- \
  knn --base trunc.bvecs --query query.csv -k 3 --out ids.ivecs --forest 2
if expect_ok "radius" radius --base cluster.csv --query cluster_query.csv -r 1.5 --out ids.ivecs --distances dist.fvecs; then
  check_results "radius rows of differing lengths equal brute force" radius l2 1.5 cluster.csv cluster_query.csv
fi
if expect_ok "radius --max-results" radius --base cluster.csv --query cluster_query.csv -r 100 --max-results 3 --out ids.ivecs; then
  if python3 -c '
import struct
data, at, lengths = open("ids.ivecs", "rb").read(), 0, []
while at < len(data):
    (d,) = struct.unpack_from("<i", data, at); lengths.append(d); at += 4 + 4 * d
assert lengths == [3] * 5, lengths' 2>check.txt; then pass "radius --max-results keeps M"; else fail "radius --max-results keeps M" "$(cat check.txt)"; fi
fi

# --stats: one JSON object with the required keys.
check_stats() {
  local name=$1 keys=$2
  if python3 - "$keys" <<'EOF' 2>check.txt; then pass "$name"; else fail "$name" "$(cat check.txt)"; fi
import json, sys
text = open("out.txt").read()
assert text.count("\n") == 1, "stdout is not one line: %r" % text
stats = json.loads(text)
assert isinstance(stats, dict), "not an object"
missing = [k for k in sys.argv[1].split() if k not in stats]
assert not missing, "missing keys %s" % missing
assert stats["build_s"] >= 0 and stats["query_s"] >= 0 and stats["threads"] >= 1, stats
EOF
}
# ---- compile-time dimensions ----------------------------------------------------------------------
# same_as_padded D EXT ARGS...: the D-dimensional run and the run on the points padded to 4-D with zero
# columns write identical ids and distances (.csv: a double tree, .npy: a float tree). SET (default
# empty) picks the files dimbase${D}${SET}; KNOWN (default "compile time") is the dim_known_at of
# the D-dimensional run. With --self the runs read no query file.
same_as_padded() {
  local d=$1 ext=$2
  shift 2
  local set=${SET:-} known=${KNOWN:-compile time}
  local name="$* on ${d}-D $ext: compile-time and run-time dimension trees write the same bytes"
  local query=(--query dimquery$d$set.$ext) query_pad=(--query dimquery$d${set}pad.$ext)
  case " $* " in *" --self "*) query=() query_pad=() ;; esac
  expect_ok "$name" "$@" --base dimbase$d$set.$ext "${query[@]}" --out ids.ivecs --distances dist.fvecs --stats \
    || return 0
  if ! grep -qF "\"dim_known_at\": \"$known\"" out.txt; then fail "$name" "stdout: $(head -c 400 out.txt)"; return 0; fi
  mv ids.ivecs ids_fixed.ivecs && mv dist.fvecs dist_fixed.fvecs
  expect_ok "$name" "$@" --base dimbase$d${set}pad.$ext "${query_pad[@]}" --out ids.ivecs --distances dist.fvecs \
    --stats || return 0
  if ! grep -qF '"dim_known_at": "run time"' out.txt; then fail "$name" "stdout: $(head -c 400 out.txt)"; return 0; fi
  if cmp -s ids.ivecs ids_fixed.ivecs && cmp -s dist.fvecs dist_fixed.fvecs; then pass "$name"
  else fail "$name" "the outputs differ"; fi
}
for d in 2 3; do
  for ext in csv npy; do
    for metric in l2 l1 linf; do
      same_as_padded $d $ext knn -k 8 --metric $metric
      same_as_padded $d $ext radius -r 1.2 --metric $metric
    done
  done
done
same_as_padded 3 npy knn -k 5 --position median --leaf 3
same_as_padded 2 csv radius -r 3 --max-results 4 --position sliding --axis cycle
# The dual-tree joins (--self, --boxsize): 2-D and 3-D L2 joins run on the compile-time-dimension
# tree; L1 and Linf joins on the run-time one (their fixed-dimension joins are not compiled).
for d in 2 3; do
  same_as_padded $d npy knn --self -k 6
  SET=box same_as_padded $d csv knn -k 4 --boxsize 10
  SET=box same_as_padded $d csv radius -r 1.5 --boxsize 10
  for metric in l1 linf; do
    KNOWN="run time" same_as_padded $d csv knn --self -k 6 --metric $metric
    KNOWN="run time" SET=box same_as_padded $d csv radius -r 1.5 --boxsize 10 --metric $metric
  done
done

common_keys="build_s query_s queries_per_s threads depth leaves nodes_visited_per_query points_visited_per_query points dim queries metric index_bytes"
if expect_ok "knn --stats" knn --base base.csv --query query.csv -k 3 --out ids.ivecs --stats --threads=1; then
  check_stats "knn --stats is JSON with the required keys" "$common_keys k"
fi
if expect_ok "knn --forest --stats" knn --base base.csv --query query.csv -k 3 --out ids.ivecs --forest 4 --checks 8 --stats; then
  check_stats "knn --forest --stats is JSON with the required keys" \
    "$common_keys k trees trees_built projected_dims stored_as checks recall recall_queries"
fi
if expect_ok "knn --recall --stats" knn --base base.csv --query query.csv -k 3 --out ids.ivecs --recall 0.9 --stats; then
  check_stats "knn --recall --stats is JSON with the tuning keys" \
    "$common_keys k method trees checks recall target_recall tune_s tuning_recall validation_recall"
fi
if expect_ok "knn --graph --stats" knn --base wide.csv --query wide_query.csv -k 3 --out ids.ivecs --graph --ef 8 --stats; then
  check_stats "knn --graph --stats is JSON with the graph's keys" \
    "$common_keys k method ef graph_degree graph_build_s recall recall_queries"
  if grep -qF '"method": "graph"' out.txt; then pass "knn --graph --stats says method graph"
  else fail "knn --graph --stats says method graph" "stdout: $(head -c 400 out.txt)"; fi
fi
if expect_ok "knn --recall on 16-D data --stats" knn --base wide.csv --query wide_query.csv -k 3 --out ids.ivecs --recall 0.95 \
  --stats; then
  check_stats "knn --recall --stats on 16-D data is JSON with the tuning keys" \
    "$common_keys k method graph_degree graph_build_s recall target_recall tune_s tuning_recall validation_recall"
fi
if expect_ok "radius --stats" radius --base cluster.csv --query cluster_query.csv -r 2 --out ids.ivecs --stats; then
  check_stats "radius --stats is JSON with the required keys" "$common_keys radius"
fi

# ---- pairs, count, knn --self, --boxsize (dual-tree joins) ---------------------------------------
expect_error "pairs: missing -r" 2 "-r" -- pairs --base base.csv --out p.pairs
expect_error "pairs: negative radius" 2 "-r" -- pairs --base base.csv -r -1 --out p.pairs
expect_error "pairs: --out not .pairs" 2 "--out" ".pairs" -- pairs --base base.csv -r 1 --out p.ivecs
expect_error "count: a radius that is not a number" 2 "-r" "x" -- count --base base.csv -r 1,x
expect_error "count: negative boxsize" 2 "--boxsize" -- count --base base.csv -r 1 --boxsize 10,-2,10
expect_error "knn --self with --query" 2 "exclude each other" -- knn --base base.csv --query query.csv --self -k 3 --out ids.ivecs
expect_error "knn --self with --forest" 2 "--self" -- knn --base base.csv --self -k 3 --out ids.ivecs --forest 2
expect_error "knn --boxsize with --eps" 2 "--eps" -- knn --base base.csv --query query.csv -k 3 --out ids.ivecs --boxsize 10 --eps 1
expect_error "pairs: points outside the box" 1 "base.csv: row" "lies outside the periodic box [0, 5" -- \
  pairs --base base.csv -r 1 --out p.pairs --boxsize 5
expect_error "pairs: boxsize of the wrong length" 1 "boxsize has 2 values" -- pairs --base base.csv -r 1 --out p.pairs --boxsize 10,10
expect_error "pairs: dimension mismatch" 1 "query4.csv" "dimension 4" -- pairs --base base.csv --with query4.csv -r 1 --out p.pairs
expect_error "pairs: NaN" 1 "nan.csv: row 3" -- pairs --base nan.csv -r 1 --out p.pairs
expect_error "knn --self: k > n - 1" 1 "k = 40 exceeds the number of other points" -- knn --base base.csv --self -k 40 --out ids.ivecs
expect_error "knn --boxsize: queries outside the box" 1 "query_neg.csv: row 2: coordinate 3" "outside the periodic box" -- \
  knn --base base.csv --query query_neg.csv -k 3 --out ids.ivecs --boxsize 10
expect_error "pairs: unwritable output" 1 "no-such-dir/p.pairs" -- pairs --base base.csv -r 1 --out no-such-dir/p.pairs

# check_joins NAME WHAT ARGS...: the output of a join command equals a Python brute force. WHAT is
# pairs (p.pairs, and d.npy when written), count (stdout), self (ids.ivecs) or torus (ids.ivecs);
# ARGS: metric, radius or radii or k, base, [other], [box size].
check_joins() {
  local name=$1
  shift
  if python3 - "$@" <<'EOF2' >check.txt 2>&1; then pass "$name"; else fail "$name" "$(cat check.txt)"; fi
import json, math, os, struct, sys
what, metric, param, base_path = sys.argv[1:5]
other_path = sys.argv[5] if len(sys.argv) > 5 and sys.argv[5] != "-" else None
box = float(sys.argv[6]) if len(sys.argv) > 6 else None

def read_csv(path):
    return [[float(v) for v in line.split(",")] for line in open(path) if line.strip() and not line[0].isalpha()]

def dist(a, b):
    diffs = [abs(x - y) for x, y in zip(a, b)]
    if box is not None:
        diffs = [min(d, box - d) for d in diffs]
    return {"l2": math.sqrt(sum(t * t for t in diffs)), "l1": sum(diffs), "linf": max(diffs)}[metric]

base = read_csv(base_path)
other = read_csv(other_path) if other_path else None
if what in ("pairs", "count"):
    def pairs_within(r):
        if other is None:
            return [(i, j) for i in range(len(base)) for j in range(i + 1, len(base)) if dist(base[i], base[j]) <= r]
        return [(i, j) for i in range(len(base)) for j in range(len(other)) if dist(base[i], other[j]) <= r]
if what == "pairs":
    data = open("p.pairs", "rb").read()
    (m,) = struct.unpack_from("<Q", data)
    assert len(data) == 8 + 8 * m, "file size %d for %d pairs" % (len(data), m)
    got = [struct.unpack_from("<II", data, 8 + 8 * i) for i in range(m)]
    want = pairs_within(float(param))
    assert got == want, "got %d pairs %s..., expected %d %s..." % (len(got), got[:5], len(want), want[:5])
    if os.path.exists("d.npy"):
        raw = open("d.npy", "rb").read()
        header_len = struct.unpack_from("<H", raw, 8)[0]
        values = struct.unpack_from("<%dd" % m, raw, 10 + header_len)
        for (i, j), v in zip(got, values):
            d = dist(base[i], (other or base)[j])
            assert abs(d - v) <= 1e-12 * max(1, d), (i, j, d, v)
elif what == "count":
    out = json.loads(open("out.txt").read())
    radii = [float(r) for r in param.split(",")]
    assert out["radii"] == radii, out
    want = [len(pairs_within(r)) for r in radii]
    assert out["counts"] == want, "counts %s, expected %s" % (out["counts"], want)
else:  # self, torus: ids.ivecs
    data, rows, at = open("ids.ivecs", "rb").read(), [], 0
    while at < len(data):
        (d,) = struct.unpack_from("<i", data, at)
        rows.append(list(struct.unpack_from("<%di" % d, data, at + 4)))
        at += 4 + 4 * d
    k = int(param)
    queries = base if what == "self" else other
    assert len(rows) == len(queries), (len(rows), len(queries))
    for q, (query, got) in enumerate(zip(queries, rows)):
        order = sorted((dist(query, p), i) for i, p in enumerate(base) if not (what == "self" and i == q))
        assert got == [i for _, i in order[:k]], "row %d: %s, expected %s" % (q + 1, got, order[:k])
print("ok")
EOF2
}
rm -f d.npy
if expect_ok "pairs in one set" pairs --base base.csv -r 3 --out p.pairs; then check_joins "pairs in one set equal brute force" pairs l2 3 base.csv; fi
if expect_ok "pairs --distances" pairs --base base.csv -r 2.5 --out p.pairs --distances d.npy --metric l1; then
  check_joins "pairs --distances (l1) equal brute force" pairs l1 2.5 base.csv
fi
rm -f d.npy
if expect_ok "pairs across two sets" pairs --base base.csv --with query.fvecs -r 4 --out p.pairs --threads 2; then
  check_joins "pairs across two sets equal brute force" pairs l2 4 base.csv query.csv
fi
if expect_ok "pairs --boxsize" pairs --base base.csv -r 2 --out p.pairs --boxsize 10; then
  check_joins "pairs on a torus equal brute force" pairs l2 2 base.csv - 10
fi
if expect_ok "count" count --base base.csv -r 3,0,1,2.5,1.4142135623730951; then
  check_joins "count equals brute force" count l2 3,0,1,2.5,1.4142135623730951 base.csv
fi
if expect_ok "count --with --metric linf" count --base base.csv --with query.csv -r 1,2,3 --metric linf; then
  check_joins "count across two sets (linf) equals brute force" count linf 1,2,3 base.csv query.csv
fi
if expect_ok "count --boxsize" count --base base.csv -r 1,2,3,5 --boxsize 10; then
  check_joins "count on a torus equals brute force" count l2 1,2,3,5 base.csv - 10
fi
if expect_ok "knn --self" knn --base base.csv --self -k 5 --out ids.ivecs; then
  check_joins "knn --self equals brute force (each point's nearest others)" self l2 5 base.csv
fi
if expect_ok "knn --boxsize" knn --base base.csv --query query.csv -k 4 --out ids.ivecs --boxsize 10; then
  check_joins "knn on a torus equals brute force" torus l2 4 base.csv query.csv 10
fi
if expect_ok "pairs --stats" pairs --base base.csv -r 2 --out p.pairs --stats; then
  check_stats "pairs --stats is JSON with the required keys" "build_s query_s queries_per_s threads depth leaves nodes_visited_per_query points_visited_per_query pairs"
fi
if expect_ok "knn --self --stats" knn --base base.csv --self -k 2 --out ids.ivecs --stats; then
  check_stats "knn --self --stats is JSON with the required keys" "$common_keys k method"
fi
# A failed run leaves an earlier output as it was, and no temporary file behind.
cp p.pairs p-before.pairs
expect_error "pairs: a failure keeps the earlier output" 1 "nan.csv" -- pairs --base base.csv --with nan.csv -r 1 --out p.pairs
if cmp -s p.pairs p-before.pairs && ! ls ./*.tmp.* >/dev/null 2>&1; then pass "the earlier .pairs is intact, no temporary left"
else fail "the earlier .pairs is intact, no temporary left" "$(ls)"; fi
# ---- saved indexes (kdspace index, --index) ---------------------------------------------------------
if expect_ok "index a csv base" index --base base.csv --out tree.kdx --stats; then
  python3 -c 'import json; s = json.load(open("out.txt")); assert s["points"] == 40 and s["save_s"] >= 0 and s["file_bytes"] > 0, s' \
    2>check.txt && pass "index --stats" || fail "index --stats" "$(cat check.txt)"
fi
if expect_ok "knn --index" knn --index tree.kdx --query query.csv -k 5 --out ids.ivecs --distances dist.fvecs; then
  check_results "knn --index equals brute force" knn l2 5 base.csv query.csv
  cp ids.ivecs index-ids.ivecs && cp dist.fvecs index-dist.fvecs
  if expect_ok "knn building in the run" knn --base base.csv --query query.csv -k 5 --out ids.ivecs --distances dist.fvecs &&
    cmp -s ids.ivecs index-ids.ivecs && cmp -s dist.fvecs index-dist.fvecs; then pass "knn --index writes what building in the run writes"
  else fail "knn --index writes what building in the run writes" "outputs differ"; fi
fi
if expect_ok "knn --index --verify full" knn --index tree.kdx --verify full --query query.csv -k 5 --out ids.ivecs \
  --distances dist.fvecs && cmp -s ids.ivecs index-ids.ivecs && cmp -s dist.fvecs index-dist.fvecs; then
  pass "knn --index --verify full writes what the default load writes"
else fail "knn --index --verify full writes what the default load writes" "outputs differ"; fi
expect_error "knn --verify: an unknown level" 2 "--verify most: expected safety or full" -- \
  knn --index tree.kdx --verify most --query query.csv -k 5 --out ids.ivecs
expect_error "knn --verify without --index" 2 "--verify applies to --index" -- \
  knn --base base.csv --verify full --query query.csv -k 5 --out ids.ivecs
if expect_ok "index --metric l1 --leaf 2" index --base base.csv --out l1.kdx --metric l1 --leaf 2 &&
  expect_ok "radius --index" radius --index l1.kdx --query query.csv -r 4 --out ids.ivecs --distances dist.fvecs --stats; then
  check_results "radius --index (l1) equals brute force" radius l1 4 base.csv query.csv
  python3 -c 'import json; s = json.load(open("out.txt")); assert s["load_s"] >= 0 and s["build_s"] == 0 and s["metric"] == "l1", s' \
    2>check.txt && pass "--index --stats gives load_s" || fail "--index --stats gives load_s" "$(cat check.txt)"
fi
# The points' checksums run beside the queries (--verify safety); verified_s says when they were done.
if expect_ok "knn --index --threads 2 --stats" knn --index tree.kdx --query query.csv -k 5 --out ids.ivecs --threads 2 --stats; then
  python3 -c 'import json; s = json.load(open("out.txt")); assert s["verified_s"] >= s["load_s"] > 0, s' \
    2>check.txt && pass "--index --stats gives verified_s, after load_s" || fail "--index --stats gives verified_s, after load_s" "$(cat check.txt)"
fi
# A changed coordinate breaks no structure: only its checksum shows it, and no answer is written.
python3 - <<'EOF'
import struct
d = bytearray(open("tree.kdx", "rb").read())
for i in range(struct.unpack_from("<I", d, 28)[0]):
    kind, part, _, _, offset, length = struct.unpack_from("<IIIIQQ", d, 64 + 40 * i)
    if kind == 3:  # points
        d[offset + length // 2] ^= 0x01
open("bad-point.kdx", "wb").write(bytes(d))
EOF
rm -f ids.ivecs
for threads in 1 2; do
  expect_error "knn --index: a changed coordinate is a checksum error ($threads threads)" 1 "bad-point.kdx" \
    "section 'points'" "checksum mismatch" -- knn --index bad-point.kdx --query query.csv -k 5 --out ids.ivecs --threads $threads
done
if [ -e ids.ivecs ]; then fail "a damaged index writes no answer" "ids.ivecs was written"; else pass "a damaged index writes no answer"; fi
if expect_ok "index --forest" index --base base.npy --out forest.kdx --forest 3 --checks 40 --leaf 4 &&
  expect_ok "knn --index of a forest" knn --index forest.kdx --query query.csv -k 5 --out ids.ivecs --distances dist.fvecs; then
  check_results "knn --index of a forest searching all points equals brute force" knn l2 5 base.csv query.csv
  cp ids.ivecs index-ids.ivecs
  if expect_ok "knn --forest building in the run" knn --base base.npy --query query.csv -k 5 --out ids.ivecs \
    --forest 3 --checks 12 --leaf 4 && expect_ok "knn --index of a forest, --checks 12" knn --index forest.kdx \
    --query query.csv -k 5 --out index-ids.ivecs --checks 12 && cmp -s ids.ivecs index-ids.ivecs; then
    pass "knn --index of a forest writes what building it in the run writes"
  else fail "knn --index of a forest writes what building it in the run writes" "outputs differ"; fi
fi
if expect_ok "index --recall" index --base base.csv --out tuned.kdx --recall 0.95 -k 3 --stats; then
  python3 -c 'import json; s = json.load(open("out.txt")); assert s["kind"] == "point forest" and s["checks"] >= 1 and s["tuning_recall"] >= 0.95, s' \
    2>check.txt && pass "index --recall stores a tuned forest" || fail "index --recall stores a tuned forest" "$(cat check.txt)"
fi
# A forest index with its neighbour graph (8-D: --recall builds one), searched with the stored
# setting and with --ef.
python3 - <<'EOF'
import random
random.seed(3)
for name, rows in (("base8.csv", 300), ("query8.csv", 20)):
    with open(name, "w") as f:
        for _ in range(rows):
            f.write(",".join("%.3f" % random.uniform(0, 10) for _ in range(8)) + "\n")
EOF
if expect_ok "index --recall, 8-D (trees and graph)" index --base base8.csv --out graph.kdx --recall 0.9 -k 4 --stats; then
  python3 -c 'import json; s = json.load(open("out.txt")); assert s["graph_degree"] == 32 and s["method"] in ("graph", "forest"), s' \
    2>check.txt && pass "index --recall stores the graph" || fail "index --recall stores the graph" "$(cat check.txt)"
  expect_ok "knn --index of a forest with a graph, stored setting" knn --index graph.kdx --query query8.csv -k 4 --out ids.ivecs
  if expect_ok "knn --index --ef" knn --index graph.kdx --query query8.csv -k 4 --out ids.ivecs --distances dist.fvecs --ef 300 --stats; then
    check_results "knn --index --ef n equals brute force" knn l2 4 base8.csv query8.csv
  fi
fi
expect_error "--ef on a forest index without a graph" 2 "holds none" -- knn --index forest.kdx --query query.csv -k 3 --out ids.ivecs --ef 10
expect_error "--graph with --index" 2 "applies when building" -- knn --index forest.kdx --query query.csv -k 3 --out ids.ivecs --graph
# Updates: remove ids 0, 5, 6 and 39, add three points (ids 40, 41, 42), then compare with a brute
# force over the points held, under their ids.
python3 - <<'EOF'
import struct
with open("remove.ivecs", "wb") as f:
    f.write(struct.pack("<i3i", 3, 0, 5, 6) + struct.pack("<i1i", 1, 39))
with open("add.fvecs", "wb") as f:
    for r in ([1, 1, 1], [8, 2, 5], [1, 1, 1]):
        f.write(struct.pack("<i3f", 3, *r))
with open("remove-unknown.ivecs", "wb") as f:
    f.write(struct.pack("<i2i", 2, 1, 77))
with open("add4.fvecs", "wb") as f:
    f.write(struct.pack("<i4f", 4, 1, 2, 3, 4))
EOF
if expect_ok "index --update" index --update tree.kdx --add add.fvecs --remove remove.ivecs --out updated.kdx --stats; then
  python3 -c 'import json; s = json.load(open("out.txt")); assert (s["points"], s["added"], s["removed"], s["first_id"], s["next_id"]) == (39, 3, 4, 40, 43), s' \
    2>check.txt && pass "index --update --stats" || fail "index --update --stats" "$(cat check.txt)"
  if expect_ok "knn --index after updates" knn --index updated.kdx --query query.csv -k 7 --out ids.ivecs; then
    if python3 - <<'EOF' 2>check.txt; then pass "knn after updates equals brute force under the ids"; else fail "knn after updates equals brute force under the ids" "$(cat check.txt)"; fi
import struct
base = [[float(v) for v in l.split(",")] for l in open("base.csv") if l.strip() and not l[0].isalpha()]
queries = [[float(v) for v in l.split(",")] for l in open("query.csv") if l.strip()]
points = {i: p for i, p in enumerate(base) if i not in (0, 5, 6, 39)}
points.update({40: [1, 1, 1], 41: [8, 2, 5], 42: [1, 1, 1]})
data, at = open("ids.ivecs", "rb").read(), 0
for q in queries:
    (d,) = struct.unpack_from("<i", data, at)
    got = list(struct.unpack_from("<%di" % d, data, at + 4))
    at += 4 + 4 * d
    want = [i for _, i in sorted((sum((a - b) ** 2 for a, b in zip(q, p)), i) for i, p in points.items())[:7]]
    assert got == want, (q, got, want)
EOF
  fi
  expect_error "knn --index after updates: k above the points held" 1 "k = 40" "updated.kdx holds 39" -- \
    knn --index updated.kdx --query query.csv -k 40 --out ids.ivecs
  expect_error "update: an id no longer held" 1 "remove.ivecs: row 1: id 0 is not in updated.kdx" -- \
    index --update updated.kdx --remove remove.ivecs
fi
expect_error "update: an unknown id" 1 "remove-unknown.ivecs: row 1: id 77 is not in tree.kdx" -- \
  index --update tree.kdx --remove remove-unknown.ivecs
expect_error "update: added points of another dimension" 1 "add4.fvecs: dimension 4" "tree.kdx: dimension 3" -- \
  index --update tree.kdx --add add4.fvecs
expect_error "update: a forest" 1 "forest.kdx" "only point trees take updates" -- index --update forest.kdx --add add.fvecs
expect_error "update: nothing to do" 2 "--add" -- index --update tree.kdx
expect_error "update with --base" 2 "--base and --update" -- index --update tree.kdx --base base.csv --add add.fvecs
expect_error "index: missing --out" 2 "--out" -- index --base base.csv
expect_error "index: --checks without a forest" 2 "--checks" -- index --base base.csv --out x.kdx --checks 5
expect_error "--index with --base" 2 "--base and --index" -- knn --index tree.kdx --base base.csv --query query.csv -k 3 --out ids.ivecs
expect_error "--index with a build option" 2 "--leaf applies when building" -- \
  knn --index tree.kdx --query query.csv -k 3 --out ids.ivecs --leaf 4
expect_error "--checks on a tree index" 2 "--checks applies to forests" -- \
  knn --index tree.kdx --query query.csv -k 3 --out ids.ivecs --checks 5
expect_error "radius on a forest index" 1 "forest.kdx" "knn only" -- radius --index forest.kdx --query query.csv -r 1 --out ids.ivecs
expect_error "--index: missing file" 1 "missing.kdx: cannot open" -- knn --index missing.kdx --query query.csv -k 3 --out ids.ivecs
expect_error "--index: not an index" 1 "base.csv: not a kdspace index file" -- knn --index base.csv --query query.csv -k 3 --out ids.ivecs
expect_error "--index: queries of another dimension" 1 "query4.csv: dimension 4" "tree.kdx: dimension 3" -- \
  knn --index tree.kdx --query query4.csv -k 3 --out ids.ivecs
python3 -c 'd = bytearray(open("tree.kdx", "rb").read()); d[len(d) // 2] ^= 4; open("damaged.kdx", "wb").write(d)'
expect_error "--index: a damaged file" 1 "damaged.kdx: section" "checksum mismatch: the file is damaged" -- \
  knn --index damaged.kdx --query query.csv -k 3 --out ids.ivecs

# ---- help, version -------------------------------------------------------------------------------
if expect_ok "--version" --version && grep -qE '^kdspace [0-9]+\.[0-9]+\.[0-9]+$' out.txt; then pass "--version prints kdspace X.Y.Z"
else fail "--version prints kdspace X.Y.Z" "stdout: $(cat out.txt)"; fi
if expect_ok "--help" --help && grep -qF "kdspace knn" out.txt && grep -qF "kdspace radius" out.txt && grep -qF -- "-k 0" out.txt; then
  pass "--help prints the usage (with the rule for -k 0)"
else fail "--help prints the usage (with the rule for -k 0)" "stdout: $(head -c 300 out.txt)"; fi
for cmd in knn radius demo pairs count overlaps index; do
  if expect_ok "$cmd --help" $cmd --help && grep -qF "usage: kdspace $cmd" out.txt; then pass "$cmd --help"
  else fail "$cmd --help" "stdout: $(head -c 300 out.txt)"; fi
done
run
if [ "$rc" -eq 2 ] && grep -qF "usage: kdspace" err.txt; then pass "no arguments: usage on stderr, exit 2"
else fail "no arguments: usage on stderr, exit 2" "exit code $rc"; fi

# ---- rays and render ------------------------------------------------------------------------------
python3 - <<'EOF'
import struct
def boxes(path, items):
    with open(path, "wb") as f:
        f.write(struct.pack("<Q", len(items)))
        for b in items: f.write(struct.pack("<6f", *b))
def rays(path, items):
    with open(path, "wb") as f:
        f.write(struct.pack("<Q", len(items)))
        for r in items: f.write(struct.pack("<6f", *r))
# Three unit cubes along x; rays along +x from the left hit box 0 at t = 1 (direction length 1) or
# t = 0.5 (length 2); a ray starting inside box 1 hits it at t = 0; a ray going up misses.
boxes("scene.boxes", [(0,0,0,1,1,1), (2,0,0,3,1,1), (4,0,0,5,1,1)])
rays("scene.rays", [(-1,.5,.5,1,0,0), (-1,.5,.5,2,0,0), (2.5,.5,.5,1,0,0), (-1,.5,.5,0,0,1), (6,.5,.5,-1,0,0)])
boxes("bad.boxes", [(0,0,0,1,1,1), (3,0,0,1,1,1)])
rays("zero.rays", [(0,0,0,1,0,0), (0,0,0,0,0,0)])
open("short.boxes", "wb").write(struct.pack("<Q", 5) + b"\0" * 24)
EOF
for build in median sah sah-nlogn; do
  if expect_ok "rays --build $build" rays --boxes scene.boxes --rays scene.rays --out hits.bin --build "$build" --stats; then
    if python3 - <<'EOF' 2>check.txt; then pass "rays --build $build: hits and stats"; else fail "rays --build $build: hits and stats" "$(cat check.txt)"; fi
import json, struct, math
data = open("hits.bin", "rb").read()
(m,) = struct.unpack_from("<Q", data)
hits = [struct.unpack_from("<if", data, 8 + 8 * i) for i in range(m)]
want = [(0, 1.0), (0, 0.5), (1, 0.0), (-1, math.inf), (2, 1.0)]
assert m == 5 and len(data) == 8 + 8 * m, (m, len(data))
for got, exp in zip(hits, want):
    assert got[0] == exp[0] and (got[1] == exp[1] or abs(got[1] - exp[1]) < 1e-6), (hits, want)
s = json.load(open("out.txt"))
for key in ("build_s", "trace_s", "mrays_per_s", "threads", "depth", "leaves", "nodes_visited_per_ray", "boxes_tested_per_ray"):
    assert key in s, key
EOF
  fi
done
expect_error "rays: box with min > max" 1 "bad.boxes" "box 2" -- rays --boxes bad.boxes --rays scene.rays --out hits.bin
expect_error "rays: zero direction" 1 "zero.rays" "ray 2" "zero" -- rays --boxes scene.boxes --rays zero.rays --out hits.bin
expect_error "rays: truncated boxes file" 1 "short.boxes" -- rays --boxes short.boxes --rays scene.rays --out hits.bin
expect_error "rays: missing --rays" 2 "--rays" -- rays --boxes scene.boxes --out hits.bin
expect_error "rays: unknown build" 2 "--build" -- rays --boxes scene.boxes --rays scene.rays --out hits.bin --build octree
if expect_ok "render" render --boxes scene.boxes --out scene.png --width 64 --height 48; then
  if python3 -c 'import struct; d = open("scene.png", "rb").read(); assert d[:8] == b"\x89PNG\r\n\x1a\n"; w, h = struct.unpack(">II", d[16:24]); assert (w, h) == (64, 48), (w, h)' 2>check.txt
  then pass "render writes a 64 x 48 PNG"; else fail "render writes a 64 x 48 PNG" "$(cat check.txt)"; fi
fi
expect_error "render: width 0" 2 "--width" -- render --boxes scene.boxes --out scene.png --width 0

# ---- overlaps ------------------------------------------------------------------------------------
python3 - <<'EOF'
import random, struct
def boxes(path, items):
    with open(path, "wb") as f:
        f.write(struct.pack("<Q", len(items)))
        for b in items: f.write(struct.pack("<6f", *b))
rng = random.Random(3)
# Cubes of side 1 or 2 on an integer grid: many share faces, edges and corners exactly.
def grid(n):
    out = []
    for _ in range(n):
        s = rng.choice((1, 1, 2))
        x, y, z = (rng.randint(0, 9) for _ in range(3))
        out.append((x, y, z, x + s, y + s, z + s))
    return out
boxes("grid_a.boxes", grid(400))
boxes("grid_b.boxes", grid(150))
# Random boxes of mixed sizes, some flat.
mixed = []
for i in range(600):
    lo = [rng.uniform(-5, 5) for _ in range(3)]
    hi = [v + rng.choice((0.0, rng.uniform(0, 1.5))) for v in lo]
    mixed.append(tuple(lo + hi))
boxes("mixed.boxes", mixed)
boxes("none.boxes", [])
boxes("nan.boxes", [(0,0,0,1,1,1), (0,float("nan"),0,1,1,1)])
boxes("inverted.boxes", [(0,0,0,1,1,1), (0,0,0,1,1,1), (0,0,2,1,1,1)])
open("cut.boxes", "wb").write(struct.pack("<Q", 3) + b"\0" * 50)
open("zero_bytes.boxes", "wb").close()
EOF
# check_pairs A [B]: out.pairs equals the brute-force pairs of A (a < b) or of A x B.
check_pairs() {
  python3 - "$@" <<'EOF'
import struct, sys
def read_boxes(path):
    d = open(path, "rb").read()
    (n,) = struct.unpack_from("<Q", d)
    return [struct.unpack_from("<6f", d, 8 + 24 * i) for i in range(n)]
def overlap(p, q):
    return all(p[k] <= q[k + 3] and q[k] <= p[k + 3] for k in range(3))
a = read_boxes(sys.argv[1])
b = read_boxes(sys.argv[2]) if len(sys.argv) > 2 else None
if b is None:
    want = [(i, j) for i in range(len(a)) for j in range(i + 1, len(a)) if overlap(a[i], a[j])]
else:
    want = [(i, j) for i in range(len(a)) for j in range(len(b)) if overlap(a[i], b[j])]
d = open("out.pairs", "rb").read()
(m,) = struct.unpack_from("<Q", d)
assert len(d) == 8 + 8 * m, (m, len(d))
got = [struct.unpack_from("<II", d, 8 + 8 * i) for i in range(m)]
assert got == want, "got %d pairs, brute force %d; first difference at %s" % (
    len(got), len(want), next((k for k, (x, y) in enumerate(zip(got, want)) if x != y), min(len(got), len(want))))
EOF
}
for build in binned sah-nlogn sah median; do
  for set in grid_a mixed; do
    name="overlaps --build $build on $set"
    if expect_ok "$name" overlaps --boxes $set.boxes --out out.pairs --build $build; then
      if check_pairs $set.boxes 2>check.txt; then pass "$name: the brute-force pairs"; else fail "$name" "$(cat check.txt)"; fi
    fi
  done
done
if expect_ok "overlaps --with" overlaps --boxes grid_a.boxes --with grid_b.boxes --out out.pairs --threads 3; then
  if check_pairs grid_a.boxes grid_b.boxes 2>check.txt; then pass "overlaps --with: the brute-force pairs"; else fail "overlaps --with" "$(cat check.txt)"; fi
fi
if expect_ok "overlaps --stats" overlaps --boxes mixed.boxes --out out.pairs --stats --threads 2; then
  if python3 -c '
import json
s = json.load(open("out.txt"))
for key in ("build_s", "query_s", "pairs", "threads", "depth", "leaves"): assert key in s, key
assert s["threads"] == 2 and s["boxes"] == 600, s' 2>check.txt; then pass "overlaps --stats keys"; else fail "overlaps --stats keys" "$(cat check.txt)"; fi
fi
if expect_ok "overlaps on 0 boxes" overlaps --boxes none.boxes --with grid_b.boxes --out out.pairs; then
  if check_pairs none.boxes grid_b.boxes 2>check.txt && [ "$(wc -c < out.pairs)" -eq 8 ]; then pass "overlaps on 0 boxes: an empty pairs file"
  else fail "overlaps on 0 boxes: an empty pairs file" "$(cat check.txt)"; fi
fi
expect_error "overlaps: NaN coordinate" 1 "nan.boxes: box 2: min y is nan" -- overlaps --boxes nan.boxes --out out.pairs
expect_error "overlaps: min > max" 1 "inverted.boxes: box 3: min z 2 > max z 1" -- overlaps --boxes inverted.boxes --out out.pairs
expect_error "overlaps: truncated file" 1 "cut.boxes: truncated" -- overlaps --boxes grid_a.boxes --with cut.boxes --out out.pairs
expect_error "overlaps: empty file" 1 "zero_bytes.boxes: empty file" -- overlaps --boxes zero_bytes.boxes --out out.pairs
expect_error "overlaps: missing --out" 2 "--out" -- overlaps --boxes grid_a.boxes
expect_error "overlaps: unknown build" 2 "--build" -- overlaps --boxes grid_a.boxes --out out.pairs --build octree
expect_error "overlaps: no output folder" 1 "no/such/out.pairs" -- overlaps --boxes grid_a.boxes --out no/such/out.pairs
rm -f out.pairs
run overlaps --boxes nan.boxes --out out.pairs
if [ ! -e out.pairs ] && ! ls | grep -qF '.tmp-'; then pass "overlaps: a failed run leaves no output and no temporary"
else fail "overlaps: a failed run leaves no output and no temporary" "$(ls)"; fi

# ---- demo ----------------------------------------------------------------------------------------
if expect_ok "demo --quick" demo --quick --out demo-out; then
  if python3 - <<'EOF' 2>check.txt; then pass "demo --quick: exact is yes everywhere"; else fail "demo --quick: exact is yes everywhere" "$(cat check.txt)"; fi
# Every markdown table with an "exact" column must say yes in every row.
rows_checked, exact_col = 0, None
for line in open("out.txt"):
    cells = [c.strip() for c in line.strip().strip("|").split("|")] if line.startswith("|") else None
    if cells is None:
        exact_col = None
    elif any(c.startswith("exact") for c in cells):
        exact_col = [i for i, c in enumerate(cells) if c.startswith("exact")][0]
    elif exact_col is not None and not set(cells[0]) <= set("-: "):
        assert cells[exact_col] == "yes", "row %r" % line.strip()
        rows_checked += 1
assert rows_checked >= 3, "only %d table rows with an exact column" % rows_checked
EOF
  if [ -s demo-out/results.md ] && expect_ok "knn on the demo's files" knn --base demo-out/uniform-3d_base.fvecs \
    --query demo-out/uniform-3d_query.fvecs -k 10 --out demo-ids.ivecs --stats; then
    if python3 -c 'import json; s = json.load(open("out.txt")); assert s["points"] == 100000 and s["dim"] == 3 and s["queries"] == 1000, s' 2>check.txt
    then pass "knn on the demo's files"; else fail "knn on the demo's files" "$(cat check.txt)"; fi
  fi
fi

# Without --out the demo writes nothing: run in an empty folder, the folder stays empty.
mkdir -p demo-quiet
if (cd demo-quiet && "$KDSPACE" demo --quick >../out.txt 2>&1) && [ -z "$(ls -A demo-quiet)" ]; then
  pass "demo without --out writes nothing into the working folder"
else fail "demo without --out writes nothing into the working folder" "$(ls -A demo-quiet)"; fi

echo "$passed passed, $failed failed"
[ "$failed" -eq 0 ]
