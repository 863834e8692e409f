#!/usr/bin/env bash
# Builds the libFuzzer targets with clang (ASan + UBSan) and runs each for a while.
#
# usage: fuzz/run.sh [SECONDS_EACH]        (default 60)
# Needs clang and libclang-rt-dev (Debian: clang-14 libclang-rt-14-dev). Builds into build/fuzz;
# findings (crash-*, the input that failed) land there too.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
seconds=${1:-60}
out=$root/build/fuzz
mkdir -p "$out/corpus-read-part"
cxx=$(command -v clang++ || command -v clang++-14)
flags=(-std=c++17 -g -O1 -fsanitize=fuzzer,address,undefined -fno-sanitize-recover=undefined -I"$root/include")

# fuzz_read_part: io::read_part against io::read_points (the vector file reader: lib/io/vectors.cpp).
"$cxx" "${flags[@]}" "$root/fuzz/fuzz_read_part.cpp" "$root/lib/io/vectors.cpp" -o "$out/fuzz_read_part"
# Seeds: a small file of each format (first byte: format, then parts; see the target).
printf '\000x,y\n1,2\n3,4\n\n' >"$out/corpus-read-part/csv"
printf '\006\002\000\000\000\000\000\200\077\000\000\000\100\002\000\000\000\000\000\100\100\000\000\200\100' \
  >"$out/corpus-read-part/fvecs"
"$out/fuzz_read_part" -max_total_time="$seconds" -max_len=4096 -artifact_prefix="$out/" "$out/corpus-read-part"

# fuzz_read_pairs: io::read_pairs (the .pairs reader: lib/io/pairs.cpp, lib/io/record_file.cpp).
mkdir -p "$out/corpus-read-pairs"
"$cxx" "${flags[@]}" "$root/fuzz/fuzz_read_pairs.cpp" "$root/lib/io/pairs.cpp" "$root/lib/io/record_file.cpp" \
  -o "$out/fuzz_read_pairs"
# Seeds: no pairs; two pairs in order.
printf '\000\000\000\000\000\000\000\000' >"$out/corpus-read-pairs/empty"
printf '\002\000\000\000\000\000\000\000\000\000\000\000\001\000\000\000\001\000\000\000\002\000\000\000' \
  >"$out/corpus-read-pairs/two"
"$out/fuzz_read_pairs" -max_total_time="$seconds" -max_len=4096 -artifact_prefix="$out/" "$out/corpus-read-pairs"
