#!/usr/bin/env bash
# Tests of the `kdspace-mpi` command under mpirun.
#
#   usage: mpi_cli_tests.sh same|faults NP SCRATCH KDSPACE KDSPACE_MPI TEST_FILES REFUSE_NEW_LIB
#
# same:   on every data shape and file format (written by TEST_FILES), `mpirun -np NP kdspace-mpi
#         knn|radius` writes the same bytes as `kdspace knn|radius` (ids and distances).
# faults: a rank that fails (bad data in its part of a file, a truncated file, running out of memory,
#         an output it cannot write) makes every rank exit, with one message naming the rank and the
#         file row, and the exit code of kdspace; nothing hangs (each run has a time limit) and no
#         output file is left half written.
# Prints PASS/FAIL for each check and, last, "N passed, M failed"; exits 1 if any check failed.
set -u

if [ $# -ne 7 ]; then
  echo "usage: $0 same|faults NP SCRATCH KDSPACE KDSPACE_MPI TEST_FILES REFUSE_NEW_LIB" >&2
  exit 2
fi
mode=$1
np=$2
SCRATCH=$3
abs() { echo "$(cd "$(dirname "$1")" && pwd)/$(basename "$1")"; }
KDSPACE=$(abs "$4")
KDSPACE_MPI=$(abs "$5")
TEST_FILES=$(abs "$6")
REFUSE_NEW=$(abs "$7")
MPIRUN=(mpirun --oversubscribe --allow-run-as-root)
# A run that takes longer than this has hung: the fault tests would otherwise wait forever.
LIMIT=120

rm -rf "$SCRATCH" && mkdir -p "$SCRATCH" && cd "$SCRATCH" || exit 2
"$TEST_FILES" . || exit 2

passed=0
failed=0
pass() { echo "PASS $1"; passed=$((passed + 1)); }
fail() {
  echo "FAIL $1: $2"
  echo "  stderr: $(grep -v '^\s*$' err.txt 2>/dev/null | head -c 800)"
  failed=$((failed + 1))
}

# mpi P ARGS...: runs kdspace-mpi on P ranks; stdout in out.txt, stderr in err.txt, code in $rc.
mpi() {
  local p=$1
  shift
  timeout $LIMIT "${MPIRUN[@]}" -np "$p" "$KDSPACE_MPI" "$@" >out.txt 2>err.txt </dev/null
  rc=$?
}

# same NAME ARGS...: kdspace and kdspace-mpi on NP ranks write the same ids and distances.
same() {
  local name=$1
  shift
  if ! "$KDSPACE" "$@" --out want.ivecs --distances want.fvecs --threads 1 >/dev/null 2>err.txt; then
    fail "$name" "kdspace failed"
    return
  fi
  rm -f got.ivecs got.fvecs
  mpi "$np" "$@" --out got.ivecs --distances got.fvecs
  if [ "$rc" -ne 0 ]; then fail "$name" "kdspace-mpi exit code $rc"; return; fi
  if ! cmp -s want.ivecs got.ivecs; then fail "$name" "ids differ from kdspace's"; return; fi
  if ! cmp -s want.fvecs got.fvecs; then fail "$name" "distances differ from kdspace's"; return; fi
  pass "$name (np $np)"
}

# ---- the same bytes as kdspace ---------------------------------------------------------------------
if [ "$mode" = same ]; then
  same "knn k=1, uniform 3-D" knn --base uniform.fvecs --query uniform-q.fvecs -k 1
  same "knn k=10, uniform 3-D" knn --base uniform.fvecs --query uniform-q.fvecs -k 10
  same "knn, the base as its own queries" knn --base uniform.fvecs --query uniform.fvecs -k 4
  same "knn k=25, clustered 8-D" knn --base clustered.fvecs --query clustered-q.fvecs -k 25
  same "knn k=1, duplicate-heavy" knn --base duplicates.fvecs --query duplicates-q.fvecs -k 1
  same "knn k=300, duplicate-heavy (ties across regions)" knn --base duplicates.fvecs --query duplicates-q.fvecs -k 300
  same "knn l1, integer grid (.ivecs; points on region boundaries)" knn --base grid.ivecs --query grid-q.fvecs -k 17 --metric l1
  same "knn k=n, all identical" knn --base identical.fvecs --query identical-q.fvecs -k 400
  same "knn double, flat axes (.csv)" knn --base flat.csv --query flat-q.csv -k 5
  same "knn linf double, sorted along x (.npy)" knn --base sorted.npy --query sorted-q.npy -k 9 --metric linf
  same "knn, a single point" knn --base one.fvecs --query one-q.fvecs -k 1
  same "knn, byte values (.bvecs)" knn --base bytes.bvecs --query bytes-q.fvecs -k 12
  same "knn, other build options" knn --base clustered.fvecs --query clustered-q.fvecs -k 6 --leaf 1 --axis cycle --position sliding
  same "radius, uniform" radius --base uniform.fvecs --query uniform-q.fvecs -r 0.2
  same "radius --max-results, duplicate-heavy" radius --base duplicates.fvecs --query duplicates-q.fvecs -r 0.5 --max-results 20
  same "radius linf, integer grid" radius --base grid.ivecs --query grid-q.fvecs -r 1.5 --metric linf
  same "radius double (.csv)" radius --base flat.csv --query flat-q.csv -r 1.0
fi

# ---- faults --------------------------------------------------------------------------------------
# expect_failure NAME CODE WANT P ARGS...: kdspace-mpi on P ranks exits with CODE within the time
# limit, prints exactly one error line, and that line contains WANT (a fixed string).
expect_failure() {
  local name=$1 code=$2 want=$3 p=$4
  shift 4
  mpi "$p" "$@"
  if [ "$rc" -eq 124 ]; then fail "$name" "no exit after ${LIMIT}s: a hang"; return; fi
  if [ "$rc" -ne "$code" ]; then fail "$name" "exit code $rc, expected $code"; return; fi
  local lines
  lines=$(grep -c '^kdspace: error: ' err.txt)
  if [ "$lines" -ne 1 ]; then fail "$name" "$lines error lines, expected 1 (from rank 0 only)"; return; fi
  if ! grep -qF -- "$want" err.txt; then fail "$name" "message lacks: $want"; return; fi
  pass "$name"
}

# The message of kdspace itself for the same input, after "kdspace: error: ".
kdspace_message() {
  "$KDSPACE" "$@" --out want.ivecs >/dev/null 2>kerr.txt
  sed -n 's/^kdspace: error: //p' kerr.txt | head -n 1
}

if [ "$mode" = faults ]; then
  # Rows 1500..2249 of 3000 are rank 2's of 4: a NaN in row 2001.
  python3 - <<'EOF'
import struct
rows = open("uniform.fvecs", "rb").read()
row_bytes = 4 + 3 * 4
b = bytearray(rows)
struct.pack_into("<f", b, 2000 * row_bytes + 4 + 4, float("nan"))  # row 2001, column 2
open("nan-rank2.fvecs", "wb").write(b)
open("truncated.fvecs", "wb").write(rows[:-5])
lines = open("flat.csv").read().split("\n")
bad = list(lines); bad[900] = bad[900].replace(",", ",x", 1)  # line 901: a field that is no number
open("badfield.csv", "w").write("\n".join(bad))
blank = list(lines); blank[300] = "  "  # a blank line before more data
open("blank.csv", "w").write("\n".join(blank))
EOF
  q=(--query uniform-q.fvecs -k 3)
  want=$(kdspace_message knn --base nan-rank2.fvecs "${q[@]}")
  expect_failure "NaN in rank 2's part: every rank exits, rank 2 and the row named" 1 "rank 2 of 4: $want" 4 \
    knn --base nan-rank2.fvecs "${q[@]}" --out ids.ivecs
  want=$(kdspace_message knn --base truncated.fvecs "${q[@]}")
  expect_failure "truncated file: the last rank names the cut row" 1 "rank 3 of 4: $want" 4 \
    knn --base truncated.fvecs "${q[@]}" --out ids.ivecs
  want=$(kdspace_message knn --base badfield.csv --query flat-q.csv -k 3)
  expect_failure "csv field that is no number, found by the rank that holds it" 1 "$want" 3 \
    knn --base badfield.csv --query flat-q.csv -k 3 --out ids.ivecs
  grep -qF "rank " err.txt && pass "csv error names a rank" || fail "csv error names a rank" "no rank in the message"
  want=$(kdspace_message knn --base blank.csv --query flat-q.csv -k 3)
  expect_failure "csv blank line before more data" 1 "$want" 4 \
    knn --base blank.csv --query flat-q.csv -k 3 --out ids.ivecs
  expect_failure "NaN in the queries of one rank" 1 "rank 2 of 4: nan-rank2.fvecs: row 2001" 4 \
    knn --base uniform.fvecs --query nan-rank2.fvecs -k 3 --out ids.ivecs
  expect_failure "missing base file" 1 "missing.fvecs: cannot open" 2 \
    knn --base missing.fvecs "${q[@]}" --out ids.ivecs
  want=$(kdspace_message knn --base uniform.fvecs --query clustered-q.fvecs -k 3)
  expect_failure "queries of another dimension" 1 "$want" 3 knn --base uniform.fvecs --query clustered-q.fvecs -k 3 --out ids.ivecs
  want=$(kdspace_message knn --base one.fvecs "${q[@]:0:2}" -k 2)
  expect_failure "k above the number of points" 1 "$want" 4 knn --base one.fvecs "${q[@]:0:2}" -k 2 --out ids.ivecs
  expect_failure "an output folder that does not exist" 1 "no-such-folder/ids.ivecs" 2 \
    knn --base uniform.fvecs "${q[@]}" --out no-such-folder/ids.ivecs

  # Out of memory on rank 1 of 2 only: its operator new refuses more than 8000 bytes at a time
  # (rank 1 reads 1500 rows of 12 bytes). Not under AddressSanitizer, whose runtime must be loaded
  # first and replaces operator new itself.
  if ldd "$KDSPACE_MPI" | grep -q libasan; then
    echo "SKIP out of memory on one rank (AddressSanitizer build)"
  else
    args=(knn --base uniform.fvecs "${q[@]}" --out ids.ivecs)
    timeout $LIMIT "${MPIRUN[@]}" -np 1 "$KDSPACE_MPI" "${args[@]}" : \
      -np 1 -x LD_PRELOAD="$REFUSE_NEW" -x KDSPACE_TEST_NEW_LIMIT=8000 "$KDSPACE_MPI" "${args[@]}" \
      >out.txt 2>err.txt </dev/null
    rc=$?
    if [ "$rc" -eq 1 ] && grep -q '^kdspace: error: rank 1 of 2: out of memory' err.txt; then
      pass "out of memory on rank 1: every rank exits, rank 1 named"
    else fail "out of memory on rank 1: every rank exits, rank 1 named" "exit code $rc"; fi
  fi

  # A failed run leaves an existing output as it was, and no temporary beside it.
  mpi 2 knn --base uniform.fvecs "${q[@]}" --out kept.ivecs --distances kept.fvecs
  cp kept.ivecs before.ivecs
  mpi 4 knn --base nan-rank2.fvecs "${q[@]}" --out kept.ivecs --distances kept.fvecs
  if [ "$rc" -eq 1 ] && cmp -s kept.ivecs before.ivecs && [ -z "$(ls ./*.tmp 2>/dev/null)" ]; then
    pass "a failed run leaves the old output and no temporary file"
  else fail "a failed run leaves the old output and no temporary file" "exit code $rc, files: $(ls)"; fi

  # Usage errors: exit 2 on every rank, the hint names kdspace-mpi.
  expect_failure "approximate options are refused" 2 "option --eps is not available in kdspace-mpi" 2 \
    knn --base uniform.fvecs "${q[@]}" --out ids.ivecs --eps 0.5
  expect_failure "joins are refused" 2 "option --self is not available in kdspace-mpi" 2 \
    knn --base uniform.fvecs --self -k 3 --out ids.ivecs
  grep -qF "run 'kdspace-mpi knn --help'" err.txt && pass "usage error hint" || fail "usage error hint" "no hint"
  expect_failure "-k 0 is a usage error" 2 "option -k expects a whole number >= 1, got 0" 2 \
    knn --base uniform.fvecs --query uniform-q.fvecs -k 0 --out ids.ivecs
  expect_failure "unknown command" 2 "unknown command 'pairs'" 2 pairs --base uniform.fvecs
  mpi 2 knn --help
  if [ "$rc" -eq 0 ] && [ "$(grep -c '^usage: kdspace-mpi knn' out.txt)" -eq 1 ]; then pass "knn --help (printed once)"
  else fail "knn --help (printed once)" "exit code $rc"; fi
fi

echo "$passed passed, $failed failed"
[ "$failed" -eq 0 ]
