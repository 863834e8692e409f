#!/usr/bin/env bash
# Downloads (apt-get download: no install, no root needed for the download itself) Debian packages
# that ship real 3-D scans and meshes, unpacks them under OUTDIR and writes OUTDIR/real_data.txt,
# the list of files that bench/real_data/mesh_io.hpp's read_real_meshes() reads.
#
# usage: bench/real_data/fetch.sh OUTDIR
#
# Sources (Debian 12):
#   libcgal-demo        /usr/share/doc/libcgal-dev/data.tar.gz and examples.tar.gz: range scans
#                       and scanned meshes used by CGAL's demos (building, b9, radar, kitten,
#                       bunny, armadillo, elephant, ...) and an airborne LIDAR tile (urban.las)
#   assimp-testmodels   /usr/share/assimp/models: Wuson.stl (a mesh, binary STL; its .ply twin
#                       has a malformed header line and is not listed)
# None of the Debian 12 packages looked at holds a real scan of 500k points or more (searched:
# pcl-tools, libpcl-doc, meshlab, cloudcompare, vtk9-examples, open3d-gui-data, freecad-common,
# opencv-data, pymol-data, python3-vedo-examples, mrpt-common); the largest here is building.ply
# with 100,000 points.
#
# Runs again quickly: a package already downloaded into OUTDIR/debs is not fetched again.
set -euo pipefail

if [ $# -ne 1 ]; then
  echo "usage: $0 OUTDIR" >&2
  exit 2
fi
out=$1
mkdir -p "$out/debs"
out=$(cd "$out" && pwd)

fetch() {  # fetch PACKAGE: downloads its .deb into OUTDIR/debs and unpacks it into OUTDIR/PACKAGE
  local package=$1
  if ! ls "$out/debs/${package}"_*.deb >/dev/null 2>&1; then
    (cd "$out/debs" && apt-get download "$package") >&2
  fi
  rm -rf "${out:?}/$package"
  dpkg -x "$out/debs/${package}"_*.deb "$out/$package"
}

fetch libcgal-demo
mkdir -p "$out/cgal"
tar -xzf "$out/libcgal-demo/usr/share/doc/libcgal-dev/data.tar.gz" -C "$out/cgal" data/points_3 data/meshes
tar -xzf "$out/libcgal-demo/usr/share/doc/libcgal-dev/examples.tar.gz" -C "$out/cgal" \
  examples/Point_set_processing_3/data/urban.las
rm -rf "${out:?}/libcgal-demo"

fetch assimp-testmodels
models=$out/assimp-testmodels/usr/share/assimp/models

# assimp's PLY/pond.0.ply (a 70k-point scan) is not listed: the packaged file is damaged. It
# declares 70051 records of 31 bytes but holds 69 bytes less, and from record 692 on the values are
# garbage (1e37, NaN): bytes were lost inside the data (a line-ending conversion would do this).

# The list: real scans (points only) first, then scanned or modelled meshes with triangles.
# Synthetic shapes in the same packages (spheres, cubes, tori) are left out.
list=$out/real_data.txt.tmp
cat > "$list" <<LIST
# Real 3-D scans and meshes from Debian packages, written by bench/real_data/fetch.sh.
# One path a line, relative to this folder. Read by kdspace::bench::read_real_meshes().
# scans (points only)
cgal/data/points_3/building.ply
cgal/data/points_3/b9_training.ply
cgal/data/points_3/radar.xyz
cgal/examples/Point_set_processing_3/data/urban.las
cgal/data/points_3/poste_france.xyz
cgal/data/points_3/hippo1.ply
cgal/data/points_3/kitten.xyz
# meshes (vertices and triangles)
cgal/data/meshes/refined_elephant.off
cgal/data/meshes/bunny00.off
cgal/data/meshes/armadillo.off
cgal/data/meshes/diplodocus.off
cgal/data/meshes/man.off
cgal/data/meshes/bear.off
cgal/data/meshes/mannequin-devil.off
cgal/data/meshes/ChineseDragon-10kv.off
cgal/data/meshes/camel.off
cgal/data/meshes/lion-head.off
${models#"$out"/}/STL/Wuson.stl
LIST
while read -r path; do
  case $path in '#'* | '') continue ;; esac
  if [ ! -f "$out/$path" ]; then
    echo "$0: $out/$path is missing from its package" >&2
    exit 1
  fi
done < "$list"
mv "$list" "$out/real_data.txt"
echo "$0: $(grep -vc '^#' "$out/real_data.txt") files listed in $out/real_data.txt" >&2
