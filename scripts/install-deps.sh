#!/usr/bin/env bash
# Installs the Debian packages kdspace needs to build, test and benchmark.
# As root it runs apt-get; as another user it prints the command to run.
set -euo pipefail

packages=(
  build-essential cmake ninja-build pkg-config git python3  # toolchain
  libpng-dev                                                 # kdspace render
  libeigen3-dev                                              # the blocked scan (library)
  catch2                                                     # tests
  libflann-dev liblz4-dev                                    # FLANN: validation tests and benchmarks
  libnanoflann-dev libembree-dev                             # benchmark peers
  libhnswlib-dev libfaiss-dev                                # approximate search peers (kdspace-ann-bench)
  libsndfile1-dev                                            # recordings for kdspace-ann-bench's MFCC
  libcgal-dev libopenblas-dev                                # kdspace-bench peers: CGAL Kd_tree, FAISS flat (OpenBLAS sgemm)
  clang libclang-rt-14-dev                                   # fuzzing (libFuzzer): fuzz/
  libbullet-dev                                              # collision benchmark peer (CGAL: collision tests)
  gnuplot-nox                                                # benchmark plots
  pybind11-dev python3-dev python3-numpy                     # the Python module (python/)
  python3-scipy python3-pytest                               # its tests (SciPy's kd-tree tests run against it)
  python3-pykdtree python3-opencv                            # its benchmark peer; the photo-matching example
  libopenmpi-dev openmpi-bin                                 # kdspace-mpi (search over MPI ranks), its tests
)

missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -eq 0 ]; then
  echo "install-deps: all packages present"
  exit 0
fi
if [ "$(id -u)" -ne 0 ]; then
  echo "install-deps: missing packages; run as root:" >&2
  echo "  apt-get update && apt-get install -y ${missing[*]}" >&2
  exit 1
fi
export DEBIAN_FRONTEND=noninteractive
apt-get update -qq
apt-get install -y -qq --no-install-recommends "${missing[@]}"
