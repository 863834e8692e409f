#!/usr/bin/env bash
# Runs the whole benchmark and plots it:
#   build/bench/bench/kdspace-bench (all point workloads, the real scans of bench/real_data/fetch.sh,
#     the image descriptors, the Python peers)             -> bench/results/points.md, points.jsonl
#   build/bench/bench/kdspace-scan-bench, when built       -> bench/results/scan.md, scan.jsonl
#   build/bench/bench/kdspace-rays-bench, when built       -> bench/results/rays.md, rays.jsonl
#   build/bench/bench/kdspace-ann-bench                     -> bench/results/ann.md, ann.jsonl
#   bench/run_collide.sh (kdspace-collide-bench), when built -> bench/results/collide.md, collide.jsonl
#   bench/summary.py                                        -> bench/results/summary.md (points, ratios)
#   bench/plot.sh                                           -> docs/bench_points.png, docs/bench_rays.png,
#                                                              docs/bench_ann.png
#
# usage: bench/run_all.sh [kdspace-bench options, e.g. --quick or --workload uniform3d]
# environment: BUILD_DIR (default build/bench), RESULTS_DIR (default bench/results), PLOT_DIR
#              (default docs), RAYS_BENCH_ARGS (options for kdspace-rays-bench), REAL_DATA_DIR (the
#              real meshes for the rays bench; default BUILD_DIR/real_data, filled by
#              bench/real_data/fetch.sh), ANN_BENCH_ARGS
#              (options for kdspace-ann-bench), IMAGES_DIR (the photographs for kdspace-bench and the
#              ann bench; default BUILD_DIR/photos, from Debian's python3-skimage package), AUDIO_DIR
#              (the recordings for the ann bench; default BUILD_DIR/audio, from Debian's
#              asterisk-core-sounds-en-wav and asc-music packages), REAL_DIR (the real scans for
#              kdspace-bench; default BUILD_DIR/real_data, filled by bench/real_data/fetch.sh),
#              COLLIDE_BENCH_ARGS (options for kdspace-collide-bench; the meshes: see run_collide.sh)
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
ann_bench=$build/bench/kdspace-ann-bench
collide_bench=$build/bench/kdspace-collide-bench
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

# The data of kdspace-bench's image descriptors and the ann bench's real data sets, from Debian
# packages downloaded and unpacked here (not installed; no Python runs): the photographs of
# python3-skimage, a recorded voice (asterisk-core-sounds-en-wav) and recorded music (asc-music).
# A package that cannot be fetched leaves its data sets out.
fetch() {  # fetch PACKAGE DIR PATTERN: the files of PACKAGE whose path matches PATTERN, into DIR
  local unpack
  unpack=$(mktemp -d)
  if (cd "$unpack" && apt-get download "$1" >/dev/null 2>&1) && dpkg -x "$unpack"/"$1"_*.deb "$unpack/x"; then
    mkdir -p "$2"
    (cd "$unpack/x" && find . -path "$3" -exec cp --parents {} "$2"/ \;)  # keeping their folders
  else
    echo "run_all.sh: apt-get download $1 failed" >&2
  fi
  rm -rf "$unpack"
}
images=${IMAGES_DIR:-$build/photos}
audio=${AUDIO_DIR:-$build/audio}
if [ ! -f "$images/motorcycle_right.png" ]; then  # the benches want the photographs in one folder
  fetch python3-skimage "$images.tmp" '*skimage/data/*.png'
  mkdir -p "$images" && find "$images.tmp" -name '*.png' -exec cp {} "$images"/ \; && rm -rf "$images.tmp"
fi
if [ -x "$ann_bench" ]; then
  [ -d "$audio/speech" ] || fetch asterisk-core-sounds-en-wav "$audio/speech" '*/sounds/en_US_f_Allison/*.wav'
  [ -d "$audio/music" ] || fetch asc-music "$audio/music" '*/asc/music/*.mp3'
fi

# Real 3-D scans and meshes from Debian packages (bench/real_data/fetch.sh: apt-get download, no
# install) for kdspace-bench's real workloads.
real=${REAL_DIR:-$build/real_data}
if [ ! -f "$real/real_data.txt" ]; then
  "$here/real_data/fetch.sh" "$real" || echo "run_all.sh: fetching the real scans failed; kdspace-bench runs without them" >&2
fi
points_args=()
[ -f "$real/real_data.txt" ] && points_args+=(--real "$real")
[ -f "$images/motorcycle_right.png" ] && points_args+=(--images "$images")
# The Python peers (pykdtree, SciPy's cKDTree) run with Debian's interpreter, which sees their packages.
if /usr/bin/python3 -c 'import pykdtree, scipy' 2>/dev/null; then
  points_args+=(--python-peers "$here/python_peers.py")
else
  echo "run_all.sh: /usr/bin/python3 lacks pykdtree or scipy (python3-pykdtree, python3-scipy); no Python peers" >&2
fi

run_bench points "$points_bench" "${points_args[@]}" "$@"

# Exact 128-D batches: the blocked scan against FAISS's IndexFlatL2, one thread.
scan_bench=$build/bench/kdspace-scan-bench
if [ -x "$scan_bench" ]; then
  scan_args=()
  [ -f "$images/motorcycle_right.png" ] && scan_args+=(--images "$images")
  run_bench scan "$scan_bench" "${scan_args[@]}"
fi

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

ann_args=()
if [ -f "$images/motorcycle_right.png" ]; then ann_args+=(--images "$images"); fi
if [ -d "$audio/speech" ] && [ -d "$audio/music" ]; then ann_args+=(--audio "$audio"); fi

if [ -x "$ann_bench" ]; then
  # shellcheck disable=SC2086  # ANN_BENCH_ARGS is a list of options
  run_bench ann "$ann_bench" "${ann_args[@]}" ${ANN_BENCH_ARGS:-}
fi

if [ -x "$collide_bench" ]; then
  # shellcheck disable=SC2086  # COLLIDE_BENCH_ARGS is a list of options
  BUILD_DIR=$build RESULTS_DIR=$results "$here/run_collide.sh" ${COLLIDE_BENCH_ARGS:-} || status=1
fi

python3 "$here/summary.py" "$results/points.jsonl" > "$results/summary.md" || status=1
"$here/plot.sh" "$results" "$plots" || status=1
exit $status
