#!/usr/bin/env bash
# Runs the whole benchmark and plots it:
#   build/bench/bench/kdspace-bench (all point workloads)  -> bench/results/points.md, points.jsonl
#   build/bench/bench/kdspace-rays-bench, when built       -> bench/results/rays.md, rays.jsonl
#   build/bench/bench/kdspace-forest-bench                  -> bench/results/forest.md, forest.jsonl
#   bench/summary.py                                        -> bench/results/summary.md (points, ratios)
#   bench/plot.sh                                           -> docs/bench_points.png, docs/bench_rays.png,
#                                                              docs/bench_forest.png
#
# usage: bench/run_all.sh [kdspace-bench options, e.g. --quick or --workload uniform3d]
# environment: BUILD_DIR (default build/bench), RESULTS_DIR (default bench/results), PLOT_DIR
#              (default docs), RAYS_BENCH_ARGS (options for kdspace-rays-bench), REAL_DATA_DIR (the
#              real meshes for the rays bench; default BUILD_DIR/real_data, filled by
#              bench/real_data/fetch.sh), FOREST_BENCH_ARGS
#              (options for kdspace-forest-bench), IMAGES_DIR (the photographs for the forest
#              bench; default BUILD_DIR/photos, filled from Debian's python3-skimage package)
#
# Build first: cmake --preset bench && cmake --build build/bench -j2
# Each bench's stdout is kept whole in bench/results/*.log; its JSON lines go to *.jsonl, the rest
# (the markdown tables) to *.md. Progress (stderr) shows on the terminal. The exit status is 1 when
# either bench fails (kdspace-bench exits 1 when exact answers disagree), after the plot is made.
set -uo pipefail

here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/.." && pwd)
build=${BUILD_DIR:-$root/build/bench}
results=${RESULTS_DIR:-$root/bench/results}
plots=${PLOT_DIR:-$root/docs}
points_bench=$build/bench/kdspace-bench
rays_bench=$build/bench/kdspace-rays-bench
forest_bench=$build/bench/kdspace-forest-bench
mkdir -p "$results"

if [ ! -x "$points_bench" ]; then
  echo "run_all.sh: $points_bench not built; run: cmake --preset bench && cmake --build build/bench -j2" >&2
  exit 2
fi

status=0

# Runs one bench ($1: name of the results, then the command), teeing stdout to NAME.log and
# splitting it into NAME.jsonl and NAME.md.
run_bench() {
  local name=$1
  shift
  echo "run_all.sh: $*" >&2
  "$@" | tee "$results/$name.log"
  local rc=${PIPESTATUS[0]}
  grep '^{' "$results/$name.log" > "$results/$name.jsonl" || true
  grep -v '^{' "$results/$name.log" > "$results/$name.md" || true
  if [ "$rc" -ne 0 ]; then
    echo "run_all.sh: $name bench exited with status $rc" >&2
    status=1
  fi
}

run_bench points "$points_bench" "$@"

if [ -x "$rays_bench" ]; then
  # The real scenes (triangle boxes and voxels of real meshes): bench/real_data/fetch.sh downloads
  # the Debian packages that hold the meshes (not installed) into REAL_DATA_DIR.
  real=${REAL_DATA_DIR:-$build/real_data}
  real_args=()
  if [ -f "$real/real_data.txt" ] || "$here/real_data/fetch.sh" "$real"; then
    real_args=(--real "$real")
  else
    echo "run_all.sh: bench/real_data/fetch.sh $real failed; the rays bench runs without real scenes" >&2
  fi
  # shellcheck disable=SC2086  # RAYS_BENCH_ARGS is a list of options
  run_bench rays "$rays_bench" "${real_args[@]}" ${RAYS_BENCH_ARGS:-}
else
  echo "run_all.sh: $rays_bench not built; no ray results this run" >&2
  if [ -f "$results/rays.jsonl" ]; then
    echo "run_all.sh: moving the earlier $results/rays.* aside (rays.*.old) so the plot shows this run only" >&2
    for f in "$results"/rays.log "$results"/rays.md "$results"/rays.jsonl; do
      [ -f "$f" ] && mv "$f" "$f.old"
    done
  fi
fi

# The photographs of the forest bench's image descriptor data set: Debian's python3-skimage ships
# them; its package is downloaded and unpacked here (not installed, and no Python runs).
images=${IMAGES_DIR:-$build/photos}
if [ -x "$forest_bench" ] && [ ! -f "$images/motorcycle_right.png" ]; then
  unpack=$(mktemp -d)
  if (cd "$unpack" && apt-get download python3-skimage >/dev/null 2>&1) && dpkg -x "$unpack"/python3-skimage_*.deb "$unpack/x"; then
    mkdir -p "$images"
    find "$unpack/x" -path '*skimage/data/*.png' -exec cp {} "$images"/ \;
  fi
  rm -rf "$unpack"
fi
forest_args=()
if [ -f "$images/motorcycle_right.png" ]; then
  forest_args=(--images "$images")
else
  echo "run_all.sh: no photographs in $images (apt-get download python3-skimage failed); the forest bench skips its image data set" >&2
fi

if [ -x "$forest_bench" ]; then
  # shellcheck disable=SC2086  # FOREST_BENCH_ARGS is a list of options
  run_bench forest "$forest_bench" "${forest_args[@]}" ${FOREST_BENCH_ARGS:-}
fi

python3 "$here/summary.py" "$results/points.jsonl" > "$results/summary.md" || status=1
"$here/plot.sh" "$results" "$plots" || status=1
exit $status
