#!/usr/bin/env bash
# Strong and weak scaling of exact k-NN over MPI ranks (kdspace-mpi-bench), with the traffic between
# ranks a query costs; prints markdown tables, kept in RESULTS_DIR/mpi.md (the JSON lines in
# RESULTS_DIR/mpi.jsonl). docs/mpi.md checks its model of the traffic against these counts.
#
# usage: bench/mpi_scaling.sh [RANKS...]          (default: 1 2 4 8 16)
# environment: BUILD_DIR (default build/bench), RESULTS_DIR (default bench/results),
#              MPIRUN (default: mpirun --oversubscribe --allow-run-as-root --bind-to none)
#
# Build first: cmake --preset bench && cmake --build build/bench -j2 --target kdspace-mpi-bench
# Runs with more ranks than cores are oversubscribed: their times measure the machine, not the
# method; their messages, bytes and ranks a query do not depend on the machine. A strong-scaling
# series computes the same answers for every P: the script fails when the answers' checksums differ.
set -uo pipefail

here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/.." && pwd)
build=${BUILD_DIR:-$root/build/bench}
results=${RESULTS_DIR:-$root/bench/results}
bench=$build/bench/kdspace-mpi-bench
read -r -a mpirun <<<"${MPIRUN:-mpirun --oversubscribe --allow-run-as-root --bind-to none}"
ranks=("$@")
[ ${#ranks[@]} -gt 0 ] || ranks=(1 2 4 8 16)
if [ ! -x "$bench" ]; then
  echo "mpi_scaling.sh: $bench not built; run: cmake --preset bench && cmake --build build/bench -j2 --target kdspace-mpi-bench" >&2
  exit 2
fi
mkdir -p "$results"
jsonl=$results/mpi.jsonl
: >"$jsonl"
status=0

# series TITLE ARGS...: one run per P; a table row each.
series() {
  local title=$1
  shift
  echo
  echo "### $title"
  echo
  echo "\`kdspace-mpi-bench $*\` ($(nproc) cores; P above that oversubscribed)"
  echo
  echo "| P | build s | query s | queries/s | speed-up | ranks/query | messages/query | bytes/query | candidates/query | build bytes/point | points/rank min..max |"
  echo "|---|---|---|---|---|---|---|---|---|---|---|"
  local first_qps="" first_sum="" line
  for p in "${ranks[@]}"; do
    if ! line=$("${mpirun[@]}" -np "$p" "$bench" "$@" 2>&1 | grep '^{'); then
      echo "| $p | failed |"
      status=1
      continue
    fi
    echo "$line" >>"$jsonl"
    python3 - "$line" "$first_qps" "$first_sum" <<'PYTHON'
import json, sys
r = json.loads(sys.argv[1])
base = float(sys.argv[2]) if sys.argv[2] else r["queries_per_s"]
print("| %d | %.3f | %.3f | %.0f | %.2f | %.3f | %.4f | %.1f | %.2f | %.1f | %d..%d |" % (
    r["ranks"], r["build_s"], r["query_s"], r["queries_per_s"], r["queries_per_s"] / base, r["ranks_per_query"],
    r["messages_per_query"], r["bytes_per_query"], r["candidates_per_query"], r["build_bytes_per_point"],
    r["points_per_rank_min"], r["points_per_rank_max"]))
PYTHON
    local qps sum
    qps=$(python3 -c 'import json,sys; print(json.loads(sys.argv[1])["queries_per_s"])' "$line")
    sum=$(python3 -c 'import json,sys; print(json.loads(sys.argv[1])["checksum"])' "$line")
    [ -n "$first_qps" ] || first_qps=$qps
    if [ -z "$first_sum" ]; then
      first_sum=$sum
    elif [ "$sum" != "$first_sum" ] && [[ " $* " == *" strong "* ]]; then
      echo "mpi_scaling.sh: P=$p gives other answers than P=${ranks[0]} (checksum $sum, not $first_sum)" >&2
      status=1
    fi
  done
}

{
echo "## kdspace-mpi-bench: $(date -u +%Y-%m-%d), $(nproc) cores, load average $(cut -d' ' -f1-3 /proc/loadavg)"
series "Strong scaling: 1M clustered 3-D points, 100k queries, k = 10" \
  --scaling strong --shape clustered --points 1000000 --queries 100000 --dim 3 --k 10
series "Weak scaling: 250k clustered 3-D points and 25k queries a rank, k = 10" \
  --scaling weak --shape clustered --points 250000 --queries 25000 --dim 3 --k 10
series "Strong scaling, uniform 3-D: 1M points, 20k queries, k = 10" \
  --scaling strong --shape uniform --points 1000000 --queries 20000 --dim 3 --k 10
series "Strong scaling, uniform 8-D: 200k points, 20k queries, k = 10" \
  --scaling strong --shape uniform --points 200000 --queries 20000 --dim 8 --k 10
} >"$results/mpi.md"
cat "$results/mpi.md"
exit $status
