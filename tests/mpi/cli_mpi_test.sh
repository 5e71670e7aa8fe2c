#!/usr/bin/env bash
# The command line over MPI: 2, 3 and 4 ranks write the same mesh (byte for byte) as one process,
# for an analytic surface, for a raw volume split into grid blocks, coloured by a second volume
# or not, refined (§4) or not, and for a VTU file of mixed cells.
set -u
ldimesh=$1
mpiexec=$2
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
failures=0
fail() { echo "FAIL: $*"; failures=$((failures + 1)); }

"$ldimesh" mesh --surface barth --res 128 --out "$tmp/one.ply" >/dev/null || fail "one process"
for n in 2 3 4; do
  "$mpiexec" -n "$n" --oversubscribe "$ldimesh" mesh --surface barth --res 128 --out "$tmp/n$n.ply" \
    >"$tmp/n$n.log" || fail "$n ranks: exit status $?"
  cmp -s "$tmp/one.ply" "$tmp/n$n.ply" || fail "barth: $n ranks wrote a different mesh"
done
grep -q "4 ranks" "$tmp/n4.log" || fail "the 4-rank run did not report 4 ranks"

python3 - "$tmp/v.raw" <<'PY'
import array, math, sys
n = 40
a = array.array('f')
for k in range(n):
    for j in range(n):
        for i in range(n):
            x, y, z = (2.0 * i / (n - 1) - 1, 2.0 * j / (n - 1) - 1, 2.0 * k / (n - 1) - 1)
            a.append(x * x + 1.3 * y * y + z * z + 0.4 * math.sin(4 * x))
open(sys.argv[1], 'wb').write(a.tobytes())
PY
"$ldimesh" mesh --grid "$tmp/v.raw" --dims 40,40,40 --iso 0.7 --res 96 --out "$tmp/g1.ply" >/dev/null || fail "grid, one process"
"$mpiexec" -n 3 --oversubscribe "$ldimesh" mesh --grid "$tmp/v.raw" --dims 40,40,40 --iso 0.7 --res 96 \
  --out "$tmp/g3.ply" >/dev/null || fail "grid, 3 ranks"
cmp -s "$tmp/g1.ply" "$tmp/g3.ply" || fail "grid: 3 ranks wrote a different mesh"
# Coloured by a second volume (--colour-by): the ranks agree on each view's scalar range before
# quantizing, so 1, 3 and 4 ranks (4: an intermediate rank re-encodes a merge) write the same
# mesh and the same colours (the PLY's value property), byte for byte.
python3 - "$tmp/c.raw" <<'PY'
import array, math, sys
n = 40
a = array.array('f', [math.sin(0.3 * i) + 0.05 * j * k for k in range(n) for j in range(n) for i in range(n)])
open(sys.argv[1], 'wb').write(a.tobytes())
PY
"$ldimesh" mesh --grid "$tmp/v.raw" --dims 40,40,40 --iso 0.7 --res 96 --colour-by "$tmp/c.raw" \
  --out "$tmp/c1.ply" >/dev/null || fail "coloured grid, one process"
grep -aq "property float value" "$tmp/c1.ply" || fail "coloured grid: no value property"
for n in 3 4; do
  "$mpiexec" -n "$n" --oversubscribe "$ldimesh" mesh --grid "$tmp/v.raw" --dims 40,40,40 --iso 0.7 \
    --res 96 --colour-by "$tmp/c.raw" --out "$tmp/c$n.ply" >/dev/null || fail "coloured grid, $n ranks"
  cmp -s "$tmp/c1.ply" "$tmp/c$n.ply" || fail "coloured grid: $n ranks wrote a different mesh"
done
# --repeat over ranks: every run's binds and collectives on all ranks, the same mesh, one
# "repeats" entry per run.
"$mpiexec" -n 3 --oversubscribe "$ldimesh" mesh --grid "$tmp/v.raw" --dims 40,40,40 --iso 0.7 --res 96 \
  --repeat 3 --json --out "$tmp/g3r.ply" >"$tmp/g3r.json" || fail "grid, 3 ranks, --repeat 3"
cmp -s "$tmp/g1.ply" "$tmp/g3r.ply" || fail "grid: 3 ranks with --repeat 3 wrote a different mesh"
python3 -c "import json, sys; j = json.load(open(sys.argv[1])); assert len(j['repeats']) == 3 and j['ranks'] == 3, j['repeats']" \
  "$tmp/g3r.json" || fail "grid, 3 ranks, --repeat 3: not three runs reported"

# §4 refinement: the root's sample requests are answered by all ranks, and 3 ranks write the
# same mesh as one process, triangles and quads; the summary counts one round trip per pass.
for faces in tri quad; do
  "$ldimesh" mesh --surface marschner-lobb --res 32 --refine 2 --"$faces" --json \
    --out "$tmp/r1_$faces.ply" >"$tmp/r1_$faces.json" || fail "refine $faces: one process"
  "$mpiexec" -n 3 --oversubscribe "$ldimesh" mesh --surface marschner-lobb --res 32 --refine 2 \
    --"$faces" --json --out "$tmp/r3_$faces.ply" >"$tmp/r3_$faces.json" || fail "refine $faces: 3 ranks"
  cmp -s "$tmp/r1_$faces.ply" "$tmp/r3_$faces.ply" || fail "refine $faces: 3 ranks wrote a different mesh"
  python3 - "$tmp/r1_$faces.json" "$tmp/r3_$faces.json" <<'PY' || fail "refine $faces: implausible summary"
import json, sys
one, three = (json.load(open(f)) for f in sys.argv[1:])
for j in (one, three):
    r = j["refinement"]
    assert r["levels"] == 2 and 1 <= r["passes"] <= 2, r
    assert r["round_trips"] == r["passes"] == len(r["rays_per_pass"]) == len(r["seconds_per_pass"]), r
    assert r["rays"] == sum(r["rays_per_pass"]) > 0, r
    assert j["seconds"]["refine"] >= r["sample_seconds"] >= 0, j["seconds"]
assert three["ranks"] == 3
for key in ("passes", "rays_per_pass", "grown_cells", "subdivided_cells", "removed_faces"):
    assert one["refinement"][key] == three["refinement"][key], key
assert one["faces"] == three["faces"]
PY
done
# §5 merging: the sewing region's new vertices are projected with samples from all ranks, and
# 3 ranks write the same merged mesh as one process.
"$ldimesh" mesh --surface torus --res 32 --merge --json --out "$tmp/m1.ply" >"$tmp/m1.json" ||
  fail "merge: one process"
"$mpiexec" -n 3 --oversubscribe "$ldimesh" mesh --surface torus --res 32 --merge --json \
  --out "$tmp/m3.ply" >"$tmp/m3.json" || fail "merge: 3 ranks"
cmp -s "$tmp/m1.ply" "$tmp/m3.ply" || fail "merge: 3 ranks wrote a different mesh"
python3 - "$tmp/m1.json" "$tmp/m3.json" <<'PY' || fail "merge: implausible summary"
import json, sys
one, three = (json.load(open(f)) for f in sys.argv[1:])
assert one["merging"] == three["merging"], (one["merging"], three["merging"])
m = one["merging"]
assert m["split_edges"] > 0 and 0 < m["projected"] <= m["split_edges"], m
assert m["split_passes"] >= 1 and m["components"] == 1 and m["unfilled_holes"] == 0, m
PY
"$mpiexec" -n 3 --oversubscribe "$ldimesh" mesh --surface marschner-lobb --res 32 --refine 1 --no-grow \
  --out "$tmp/ng.ply" >"$tmp/ng.log" || fail "refine --no-grow: 3 ranks"
grep -q '^  refine ' "$tmp/ng.log" || fail "refine: no 'refine' line in the summary"

# Cells of every shape from a VTK-written file (tests/cli/make_vtu.py cells: quadratic hexahedra,
# tetrahedra, wedges, pyramids): 1 to 4 ranks, and 1 or 2 threads, write the same mesh, merged or
# not (VTK's Python module writes the file, as for cli.vtu).
if "$ldimesh" mesh --help | grep -q -- "--vtu" &&
  /usr/bin/python3 "$(dirname "$0")/../cli/make_vtu.py" cells "$tmp/cells.vtu"; then
  for merge in "" --merge; do
    "$ldimesh" mesh --vtu "$tmp/cells.vtu" --field r --iso 0.49 --res 64 $merge --threads 1 \
      --out "$tmp/cells1.ply" >/dev/null || fail "cells $merge: one process, one thread"
    "$ldimesh" mesh --vtu "$tmp/cells.vtu" --field r --iso 0.49 --res 64 $merge --threads 2 \
      --out "$tmp/cells1t2.ply" >/dev/null || fail "cells $merge: one process, two threads"
    cmp -s "$tmp/cells1.ply" "$tmp/cells1t2.ply" || fail "cells $merge: two threads wrote a different mesh"
    for n in 2 3 4; do
      "$mpiexec" -n "$n" --oversubscribe "$ldimesh" mesh --vtu "$tmp/cells.vtu" --field r --iso 0.49 \
        --res 64 $merge --out "$tmp/cells$n.ply" >/dev/null || fail "cells $merge: $n ranks"
      cmp -s "$tmp/cells1.ply" "$tmp/cells$n.ply" || fail "cells $merge: $n ranks wrote a different mesh"
    done
  done
else
  fail "cells: no VTU support or make_vtu.py failed"
fi

# An error on every rank is reported once, with a non-zero exit.
"$mpiexec" -n 2 --oversubscribe "$ldimesh" mesh --surface teapot >"$tmp/out" 2>"$tmp/err"
[ $? -ne 0 ] || fail "unknown surface under mpiexec: exit status 0"
[ "$(grep -c 'ldimesh: error' "$tmp/err")" -eq 1 ] || fail "unknown surface under mpiexec: not exactly one error line"

if [ "$failures" -ne 0 ]; then echo "$failures check(s) failed"; exit 1; fi
echo "all MPI command-line checks passed"
