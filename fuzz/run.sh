#!/usr/bin/env bash
# Runs every reader's fuzz target for a while, under libFuzzer with ASan + UBSan, starting from the
# seed corpus the build writes (kdspace-fuzz-seeds) and from what earlier runs kept.
#
#   usage: fuzz/run.sh BUILD_DIR SECONDS_PER_TARGET [TARGET...]      (targets: fvecs ivecs bvecs csv
#                                                          npy boxes rays hits pairs index read_part)
#   e.g.   cmake --preset fuzz && cmake --build --preset fuzz -j2 --target kdspace_fuzz &&
#          fuzz/run.sh build/fuzz 25                     (CI: 25 s each)
#          fuzz/run.sh build/fuzz 3600 index             (a long run of one target)
#
# The corpus grows in BUILD_DIR/fuzz/corpus/TARGET; a finding is written to
# BUILD_DIR/fuzz/findings/TARGET-crash-... (replay it: BUILD_DIR/fuzz/fuzz_TARGET FILE). Prints one
# line per target (executions, coverage, corpus size) and exits 1 if any target found anything.
set -u
if [ $# -lt 2 ]; then
  sed -n '2,14p' "$0" >&2
  exit 2
fi
build=$(cd "$1" && pwd)/fuzz
seconds=$2
shift 2
targets=("$@")
[ ${#targets[@]} -eq 0 ] && targets=(fvecs ivecs bvecs csv npy boxes rays hits pairs index read_part)

"$build/kdspace-fuzz-seeds" "$build/seeds" || { echo "fuzz: could not write the seeds" >&2; exit 1; }
mkdir -p "$build/findings"
export ASAN_OPTIONS=${ASAN_OPTIONS:-detect_leaks=1:abort_on_error=1}
export UBSAN_OPTIONS=${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}

status=0
for t in "${targets[@]}"; do
  mkdir -p "$build/corpus/$t"
  max_len=4096
  [ "$t" = index ] && max_len=65536
  log="$build/findings/$t.log"
  "$build/fuzz_$t" "$build/corpus/$t" "$build/seeds/$t" -max_total_time="$seconds" -max_len=$max_len \
    -timeout=10 -rss_limit_mb=2048 -print_final_stats=1 -artifact_prefix="$build/findings/$t-" >"$log" 2>&1
  rc=$?
  execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -n 1)
  cov=$(grep -oE 'cov: [0-9]+ ft: [0-9]+' "$log" | tail -n 1)
  corpus=$(find "$build/corpus/$t" -type f | wc -l)
  if [ $rc -eq 0 ]; then
    echo "fuzz $t: ${execs:-?} executions in ${seconds} s, ${cov:-cov: ?}, corpus $corpus files: no finding"
  else
    echo "FAIL fuzz $t: exit $rc after ${execs:-?} executions; see $log and $build/findings/"
    tail -n 40 "$log"
    status=1
  fi
done
exit $status
