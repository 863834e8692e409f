#!/usr/bin/env bash
# Runs the collision benchmark (kdspace-collide-bench) on generated scenes and on the triangles of
# the real meshes that bench/real_data/fetch.sh downloads (apt-get download, no installation) and
# unpacks into the build folder, once.
#
# usage: bench/run_collide.sh [kdspace-collide-bench options, e.g. --quick]
# environment: BUILD_DIR (default build/bench), RESULTS_DIR (default bench/results), REAL_DATA_DIR
#              (default BUILD_DIR/real_data)
# Build first: cmake --preset bench && cmake --build build/bench -j2 --target kdspace-collide-bench
# Writes RESULTS_DIR/collide.log (stdout whole), collide.jsonl (its JSON lines) and collide.md (the
# tables). Exits with the bench's status (1: the libraries disagreed on a pair set).
set -uo pipefail

here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/.." && pwd)
build=${BUILD_DIR:-$root/build/bench}
results=${RESULTS_DIR:-$root/bench/results}
real_data=${REAL_DATA_DIR:-$build/real_data}
bench=$build/bench/kdspace-collide-bench
if [ ! -x "$bench" ]; then
  echo "run_collide.sh: $bench not built; run: cmake --preset bench && cmake --build build/bench -j2 --target kdspace-collide-bench" >&2
  exit 2
fi
mkdir -p "$results"

args=()
if [ -f "$real_data/real_data.txt" ] || "$here/real_data/fetch.sh" "$real_data"; then
  args=(--meshes "$real_data")
else
  echo "run_collide.sh: bench/real_data/fetch.sh failed; the bench skips the real meshes" >&2
fi

echo "run_collide.sh: $bench ${args[*]} $*" >&2
"$bench" "${args[@]}" "$@" | tee "$results/collide.log"
status=${PIPESTATUS[0]}
grep '^{' "$results/collide.log" > "$results/collide.jsonl" || true
grep -v '^{' "$results/collide.log" > "$results/collide.md" || true
exit "$status"
