#!/usr/bin/env bash
# 1,000 random corruptions of index files, each searched with `kdspace knn --index`: every one must
# exit 1 with one clear line on stderr naming the file ("kdspace: error: bad.kdx: ..."), print
# nothing on stdout, write no output, and finish (no crash, no hang).
#
#   usage: index_corruption_tests.sh KDSPACE_BINARY SCRATCH_DIR [TRIALS]
#
# The corruptions: a flipped bit, a changed byte, a run of random or zero bytes, a truncation, bytes
# appended, inserted or deleted, two words swapped, a block copied over another; on a point tree, an
# updated (dynamic) tree and a forest. Prints a summary; exits 1 on the first failure.
set -u
if [ $# -lt 2 ]; then
  echo "usage: $0 KDSPACE_BINARY SCRATCH_DIR [TRIALS]" >&2
  exit 2
fi
KDSPACE=$(cd "$(dirname "$1")" && pwd)/$(basename "$1")
mkdir -p "$2" && cd "$2" || exit 2
exec python3 - "$KDSPACE" "${3:-1000}" <<'EOF'
import os, random, struct, subprocess, sys

kdspace, trials = sys.argv[1], int(sys.argv[2])
rng = random.Random(20261124)

def write_fvecs(path, rows):
    with open(path, "wb") as f:
        for r in rows:
            f.write(struct.pack("<i%df" % len(r), len(r), *r))

def run(*args):
    p = subprocess.run([kdspace, *args], capture_output=True, text=True, timeout=60)
    return p.returncode, p.stdout, p.stderr

def must(*args):
    rc, out, err = run(*args)
    if rc != 0:
        sys.exit("setup failed: kdspace %s: exit %d: %s" % (" ".join(args), rc, err))

write_fvecs("base.fvecs", [[rng.uniform(-1, 1) for _ in range(3)] for _ in range(3000)])
write_fvecs("wide.fvecs", [[rng.randint(0, 255) for _ in range(16)] for _ in range(1500)])
write_fvecs("query.fvecs", [[rng.uniform(-1, 1) for _ in range(3)] for _ in range(20)])
write_fvecs("wide_query.fvecs", [[rng.randint(0, 255) for _ in range(16)] for _ in range(20)])
write_fvecs("add.fvecs", [[rng.uniform(-1, 1) for _ in range(3)] for _ in range(500)])
with open("remove.ivecs", "wb") as f:
    ids = list(range(0, 3000, 4))
    f.write(struct.pack("<i%di" % len(ids), len(ids), *ids))
must("index", "--base", "base.fvecs", "--out", "tree.kdx")
must("index", "--update", "tree.kdx", "--add", "add.fvecs", "--remove", "remove.ivecs", "--out", "dynamic.kdx")
must("index", "--base", "wide.fvecs", "--out", "forest.kdx", "--forest", "3", "--checks", "64")
goods = [("tree.kdx", "query.fvecs"), ("dynamic.kdx", "query.fvecs"), ("forest.kdx", "wide_query.fvecs")]
originals = {name: open(name, "rb").read() for name, _ in goods}
for name, query in goods:  # the good files answer
    must("knn", "--index", name, "--query", query, "-k", "3", "--out", "out.ivecs")

def corrupt(data):
    d = bytearray(data)
    n = len(d)
    kind = rng.randrange(10)
    at = rng.randrange(n)
    if kind == 0:
        d[at] ^= 1 << rng.randrange(8)
    elif kind == 1:
        d[at] = rng.randrange(256)
    elif kind == 2:
        for i in range(at, min(n, at + rng.randint(2, 64))):
            d[i] = rng.randrange(256)
    elif kind == 3:
        size = rng.randint(1, 200)
        d[at:at + size] = bytes(len(d[at:at + size]))
    elif kind == 4:
        del d[rng.randrange(n):]
    elif kind == 5:
        d += bytes(rng.randrange(256) for _ in range(rng.randint(1, 100)))
    elif kind == 6:
        d[at:at] = bytes(rng.randrange(256) for _ in range(rng.randint(1, 16)))
    elif kind == 7:
        del d[at:at + rng.randint(1, 16)]
    elif kind == 8:
        a, b = rng.randrange(n - 4), rng.randrange(n - 4)
        d[a:a + 4], d[b:b + 4] = d[b:b + 4], d[a:a + 4]
    else:
        a, b, size = rng.randrange(n), rng.randrange(n), rng.randint(8, 512)
        d[b:b + size] = d[a:a + size][: len(d[b:b + size])]
    return bytes(d), kind

kinds = [0] * 10
for trial in range(trials):
    name, query = goods[trial % len(goods)]
    while True:
        bad, kind = corrupt(originals[name])
        if bad != originals[name]:
            break
    kinds[kind] += 1
    with open("bad.kdx", "wb") as f:
        f.write(bad)
    if os.path.exists("out.ivecs"):
        os.remove("out.ivecs")
    try:
        rc, out, err = run("knn", "--index", "bad.kdx", "--query", query, "-k", "3", "--out", "out.ivecs")
    except subprocess.TimeoutExpired:
        sys.exit("trial %d (%s, corruption %d): no answer within 60 s" % (trial, name, kind))
    lines = err.splitlines()
    problem = None
    if rc != 1:
        problem = "exit code %d" % rc
    elif len(lines) != 1 or not lines[0].startswith("kdspace: error: bad.kdx: "):
        problem = "stderr is not one line 'kdspace: error: bad.kdx: ...'"
    elif out:
        problem = "something on stdout"
    elif os.path.exists("out.ivecs"):
        problem = "an output file was written"
    if problem:
        open("failed.kdx", "wb").write(bad)
        sys.exit("FAIL trial %d (%s, corruption %d): %s\n  stderr: %s\n  the file: %s/failed.kdx"
                 % (trial, name, kind, problem, err[:500], os.getcwd()))
print("PASS %d corruptions of %s: each exit 1 with one clear line (corruptions by kind: %s)"
      % (trials, ", ".join(n for n, _ in goods), kinds))
EOF
