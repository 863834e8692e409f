#!/usr/bin/env bash
# Runs the collision benchmark (kdspace-collide-bench) on generated scenes and on the triangles of
# CGAL's example meshes, which Debian ships in the libcgal-demo package: the package is downloaded
# (apt-get download, no installation) and three meshes unpacked into the build folder, once.
#
# usage: bench/run_collide.sh [kdspace-collide-bench options, e.g. --quick]
# environment: BUILD_DIR (default build/bench), RESULTS_DIR (default bench/results), MESHES_DIR
#              (default BUILD_DIR/meshes)
# Build first: cmake --preset bench && cmake --build build/bench -j2 --target kdspace-collide-bench
# Writes RESULTS_DIR/collide.log (stdout whole), collide.jsonl (its JSON lines) and collide.md (the
# tables). Exits with the bench's status (1: the libraries disagreed on a pair set).
set -uo pipefail

here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/.." && pwd)
build=${BUILD_DIR:-$root/build/bench}
results=${RESULTS_DIR:-$root/bench/results}
meshes=${MESHES_DIR:-$build/meshes}
bench=$build/bench/kdspace-collide-bench
if [ ! -x "$bench" ]; then
  echo "run_collide.sh: $bench not built; run: cmake --preset bench && cmake --build build/bench -j2 --target kdspace-collide-bench" >&2
  exit 2
fi
mkdir -p "$results"

if [ ! -f "$meshes/bunny00.off" ]; then
  unpack=$(mktemp -d)
  if (cd "$unpack" && apt-get download libcgal-demo >/dev/null 2>&1) && dpkg -x "$unpack"/libcgal-demo_*.deb "$unpack/x" &&
    tar xzf "$unpack"/x/usr/share/doc/libcgal-dev/data.tar.gz -C "$unpack" data/meshes/bunny00.off \
      data/meshes/armadillo.off data/meshes/refined_elephant.off; then
    mkdir -p "$meshes"
    cp "$unpack"/data/meshes/*.off "$meshes"/
  fi
  rm -rf "$unpack"
fi
args=()
if [ -f "$meshes/bunny00.off" ]; then
  args=(--meshes "$meshes")
else
  echo "run_collide.sh: no meshes in $meshes (apt-get download libcgal-demo failed); the bench skips them" >&2
fi

echo "run_collide.sh: $bench ${args[*]} $*" >&2
"$bench" "${args[@]}" "$@" | tee "$results/collide.log"
status=${PIPESTATUS[0]}
grep '^{' "$results/collide.log" > "$results/collide.jsonl" || true
grep -v '^{' "$results/collide.log" > "$results/collide.md" || true
exit "$status"
