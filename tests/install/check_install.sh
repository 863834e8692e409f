#!/usr/bin/env bash
# Installs the built kdspace into a scratch prefix, then builds and runs a small outside program
# against it twice: through the CMake package and through pkg-config.
# usage: check_install.sh BUILD_DIR SCRATCH_DIR
set -euo pipefail
build_dir=$1
scratch=$2
here=$(cd "$(dirname "$0")" && pwd)
rm -rf "$scratch"
mkdir -p "$scratch"
prefix="$scratch/prefix"

cmake --install "$build_dir" --prefix "$prefix" >"$scratch/install.log"
test -f "$prefix/include/kdspace/kdspace.hpp"
test -f "$prefix/lib/cmake/kdspace/kdspaceConfig.cmake" || test -f "$prefix/lib/x86_64-linux-gnu/cmake/kdspace/kdspaceConfig.cmake"

# The consumer is built without sanitizers even when kdspace was; link the sanitizer runtime if so.
flags=$(grep -E '^CMAKE_CXX_FLAGS:' "$build_dir/CMakeCache.txt" | cut -d= -f2-)
san=""
if grep -q 'KDSPACE_SANITIZE:BOOL=ON' "$build_dir/CMakeCache.txt"; then san="-fsanitize=address,undefined"; fi
if grep -q 'KDSPACE_TSAN:BOOL=ON' "$build_dir/CMakeCache.txt"; then san="-fsanitize=thread"; fi

cmake -S "$here/consumer" -B "$scratch/consumer-build" -DCMAKE_PREFIX_PATH="$prefix" \
  -DCMAKE_CXX_FLAGS="$flags $san" -DCMAKE_EXE_LINKER_FLAGS="$san" >"$scratch/configure.log"
cmake --build "$scratch/consumer-build" >"$scratch/build.log"
"$scratch/consumer-build/consumer"

pcdir=$(dirname "$(find "$prefix" -name kdspace.pc | head -n 1)")
# shellcheck disable=SC2046
c++ $san "$here/consumer/consumer.cpp" -o "$scratch/consumer-pkgconfig" \
  $(PKG_CONFIG_PATH="$pcdir" pkg-config --cflags --libs kdspace)
"$scratch/consumer-pkgconfig"
echo "install check: CMake package and pkg-config both work"

# The Python module, when the build made it: installed under the prefix, imported from there (and
# from a folder away from the sources) by the interpreter the build was made for.
if [ -d "$build_dir/python/kdspace" ]; then
  python=$(grep -E '^Python3_EXECUTABLE:' "$build_dir/CMakeCache.txt" | cut -d= -f2-)
  module=$(find "$prefix" -name '_core*.so' -path '*/kdspace/*' | head -n 1)
  test -n "$module" || { echo "install check: the Python module was not installed" >&2; exit 1; }
  site=$(dirname "$(dirname "$module")")
  (cd "$scratch" && PYTHONPATH="$site" "$python" -c '
import kdspace, numpy as np
assert kdspace.__file__.startswith("'"$site"'"), kdspace.__file__
tree = kdspace.KDTree(np.eye(3))
d, i = tree.query([0.9, 0.1, 0.0])
assert i == 0, (d, i)
print("install check: Python module imported from", kdspace.__file__)')
fi
