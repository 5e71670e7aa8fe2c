#!/usr/bin/env bash
# The ldimesh command line as a user meets it: bad input gives one line on stderr and a
# non-zero exit (never a crash); --json prints a summary with the figures; files get written.
set -u
ldimesh=$1
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
failures=0

fail() { echo "FAIL: $*"; failures=$((failures + 1)); }

# expect_error DESCRIPTION ARGS...: exit status 1 or 2, exactly one line on stderr, no stdout.
expect_error() {
  local what=$1; shift
  "$ldimesh" "$@" >"$tmp/out" 2>"$tmp/err"
  local status=$?
  if [ "$status" -ne 1 ] && [ "$status" -ne 2 ]; then fail "$what: exit status $status"; fi
  if [ "$(wc -l <"$tmp/err")" -ne 1 ]; then fail "$what: stderr is not one line:"; cat "$tmp/err"; fi
  if ! grep -q '^ldimesh: error: ' "$tmp/err"; then fail "$what: no 'ldimesh: error:' line"; fi
  if [ -s "$tmp/out" ]; then fail "$what: printed to stdout"; fi
}

expect_error "unknown surface" mesh --surface teapot --res 16
expect_error "resolution 0" mesh --surface sphere --res 0
expect_error "r above 1" mesh --surface sphere --res 16 --r 1.5
expect_error "r below 0" mesh --surface sphere --res 16 --r -0.1
expect_error "unwritable output" mesh --surface sphere --res 16 --out /proc/version/x.ply
expect_error "unknown format" mesh --surface sphere --res 16 --out "$tmp/x.stl"
mkdir -p "$tmp/folder.ply"
expect_error "output is a folder" mesh --surface sphere --res 16 --out "$tmp/folder.ply"

# A run that fails leaves the file system as it found it: no empty output file, no folder made
# for it, and an existing file keeps its bytes.
expect_error "unknown surface, new output" mesh --surface teapot --res 16 --out "$tmp/new/sub/t.ply"
[ ! -e "$tmp/new" ] || fail "a failed run made '$tmp/new'"
echo "kept" >"$tmp/kept.glb"
expect_error "unknown surface, existing output" mesh --surface teapot --res 16 --out "$tmp/kept.glb"
[ "$(cat "$tmp/kept.glb")" = kept ] || fail "a failed run changed an existing output"
expect_error "missing VTU" mesh --vtu "$tmp/none.vtu" --field u --iso 1 --out "$tmp/none.glb"
[ ! -e "$tmp/none.glb" ] || fail "a failed run left '$tmp/none.glb'"
# A step folder that cannot be written is refused before any work, and --out is not touched.
echo "a file" >"$tmp/not-a-folder"
expect_error "steps-dir is a file" mesh --surface sphere --res 16 --out "$tmp/kept.glb" \
  --steps-dir "$tmp/not-a-folder/steps"
[ "$(cat "$tmp/kept.glb")" = kept ] || fail "a refused --steps-dir changed --out"
# Through a symbolic link the output is written to the link's target, and the link stays.
echo old >"$tmp/target.ply"
ln -s target.ply "$tmp/link.ply"
"$ldimesh" mesh --surface sphere --res 16 --out "$tmp/link.ply" >/dev/null 2>&1 || fail "via a link"
[ -L "$tmp/link.ply" ] && [ "$(head -c 3 "$tmp/target.ply")" = ply ] ||
  fail "the link was replaced, or its target not written"
# A run that succeeds makes the missing folders and leaves no temporary file beside its output.
"$ldimesh" mesh --surface sphere --res 16 --out "$tmp/made/sub/s.glb" >/dev/null 2>&1 ||
  fail "writing into new folders"
[ "$(ls -A "$tmp/made/sub")" = s.glb ] || fail "beside the output: $(ls -A "$tmp/made/sub")"
# A new output gets the permissions of any new file (0666 less the umask), not the temporary's.
(umask 022 && "$ldimesh" mesh --surface sphere --res 16 --out "$tmp/made/perm.ply" >/dev/null 2>&1)
[ "$(stat -c %a "$tmp/made/perm.ply")" = 644 ] ||
  fail "a new output has mode $(stat -c %a "$tmp/made/perm.ply"), not 644"
expect_error "bad views" mesh --surface sphere --res 16 --views xq
expect_error "no subcommand"
expect_error "tri and quad" mesh --surface sphere --res 16 --tri --quad
expect_error "refine below 0" mesh --surface sphere --res 16 --refine -1
expect_error "refine above 16" mesh --surface sphere --res 16 --refine 17
expect_error "refine not a number" mesh --surface sphere --res 16 --refine two
expect_error "refine-dot above 1" mesh --surface sphere --res 16 --refine 1 --refine-dot 2
expect_error "refine-dot below -1" mesh --surface sphere --res 16 --refine-dot -1.5

# --merge (§5): the sphere becomes one closed triangle mesh; the summary says how.
"$ldimesh" mesh --surface sphere --res 48 --merge --json --out "$tmp/merged.ply" >"$tmp/merged.json" \
  || fail "merge run failed"
python3 - "$tmp/merged.json" <<'PY' || fail "merge: implausible summary"
import json, sys
j = json.load(open(sys.argv[1]))
m = j["merging"]
# The sphere's trimmed views are six caps laid out like the faces of a cube (one per view and
# side: ±x, ±y, ±z); each cap borders the four that are not opposite it, and merging bridges
# every pair of close patches once (docs/method.md, §5 (i)): the cube's 12 edges.
assert m["enabled"] and m["patches"] == 6 and m["bridges"] == 6 * 4 // 2, m
assert j["r"] == 1, j["r"]  # merging trims with r = 1
assert m["unfilled_holes"] == 0 and m["components"] == 1, m
assert j["triangles"] == 2 * (j["vertices"] - 2), (j["triangles"], j["vertices"])  # closed, genus 0
assert j["seconds"]["bridge"] > 0 and j["seconds"]["sew"] > 0, j["seconds"]
PY
[ -s "$tmp/merged.ply" ] || fail "merge run wrote no PLY"
# --merge --quad (§5 (iv)): the torus becomes one closed mesh of quads only (V − E + F = 0, so
# with E = 2F for quads: F = V).
"$ldimesh" mesh --surface torus --res 48 --merge --quad --json >"$tmp/mq.json" ||
  fail "merge --quad run failed"
python3 - "$tmp/mq.json" <<'PY' || fail "merge --quad: implausible summary"
import json, sys
j = json.load(open(sys.argv[1]))
m, q = j["merging"], j["merging"]["quads"]
assert j["face_type"] == "quads" and j["faces"] == q["output_quads"] > 0 and j["triangles"] == 0, j
assert q["leftover_triangles"] == 0 and q["input_triangles"] > 0, q
assert m["unfilled_holes"] == 0 and m["components"] == 1, m
assert j["faces"] == j["vertices"], (j["faces"], j["vertices"])  # closed, genus 1
PY

# ldimesh surfaces lists every built-in surface.
"$ldimesh" surfaces >"$tmp/surfaces" || fail "surfaces: non-zero exit"
for s in sphere torus barth klein marschner-lobb slices; do
  grep -q "^$s " "$tmp/surfaces" || fail "surfaces: $s missing"
done

# --json: a parseable summary with the figures; the file is written and non-empty.
"$ldimesh" mesh --surface klein --res 64 --json --out "$tmp/k.ply" >"$tmp/summary.json" || fail "json run failed"
for key in '"samples"' '"quads"' '"triangles"' '"raycast"' '"match"' '"trim"'; do
  grep -q "$key" "$tmp/summary.json" || fail "json: $key missing"
done
triangles=$(sed -n 's/^ *"triangles": \([0-9]*\),*$/\1/p' "$tmp/summary.json")
[ "${triangles:-0}" -gt 1000 ] || fail "json: implausible triangle count '$triangles'"
[ -s "$tmp/k.ply" ] || fail "json run wrote no PLY"
grep -aq "element face $((triangles))" "$tmp/k.ply" || fail "PLY face count differs from the summary"

# --quad writes quads only, into an OBJ.
"$ldimesh" mesh --surface torus --res 32 --quad --out "$tmp/t.obj" >/dev/null || fail "quad obj run failed"
grep -q '^f ' "$tmp/t.obj" || fail "obj has no faces"
if grep '^f ' "$tmp/t.obj" | awk 'NF != 5 { bad = 1 } END { exit !bad }'; then fail "obj has non-quad faces"; fi

# --grid: a raw float32 volume (f = x + y + z on 12³ points) is meshed; size mismatches are errors.
python3 - "$tmp/v.raw" <<'PY'
import array, sys
n = 12
a = array.array('f', [float(i + j + k) for k in range(n) for j in range(n) for i in range(n)])
open(sys.argv[1], 'wb').write(a.tobytes())
PY
"$ldimesh" mesh --grid "$tmp/v.raw" --dims 12,12,12 --iso 16.5 --res 32 --json --out "$tmp/g.ply" >"$tmp/grid.json" \
  || fail "grid run failed"
grid_tris=$(sed -n 's/^ *"triangles": \([0-9]*\),*$/\1/p' "$tmp/grid.json")
[ "${grid_tris:-0}" -gt 100 ] || fail "grid: implausible triangle count '$grid_tris'"
expect_error "grid size mismatch" mesh --grid "$tmp/v.raw" --dims 12,12,13
# --colour-by FILE: a second raw volume of the same layout (c = x - 2z, linear: its interpolant
# is exact) colours the isosurface: every PLY vertex carries c at its position, the JSON summary
# its range; a missing colour file is a one-line error.
python3 - "$tmp/c.raw" <<'PY'
import array, sys
n = 12
a = array.array('f', [float(i - 2 * k) for k in range(n) for j in range(n) for i in range(n)])
open(sys.argv[1], 'wb').write(a.tobytes())
PY
"$ldimesh" mesh --grid "$tmp/v.raw" --dims 12,12,12 --iso 16.5 --res 32 --colour-by "$tmp/c.raw" \
  --json --out "$tmp/gc.ply" >"$tmp/gc.json" || fail "grid --colour-by run failed"
python3 - "$tmp/gc.ply" "$tmp/gc.json" <<'PY' || fail "grid --colour-by: colours are not x - 2z"
import json, struct, sys
data = open(sys.argv[1], "rb").read()
header, body = data.split(b"end_header\n", 1)
n = int(next(l for l in header.decode().splitlines() if l.startswith("element vertex")).split()[2])
worst = max(abs(v[6] - (v[0] - 2 * v[2])) for v in struct.iter_unpack("<7f", body[:28 * n]))
c = json.load(open(sys.argv[2]))["colour"]
# half a step of the fragments' 12 scalar bits over the range, and float rounding
print(f"grid --colour-by: {n} vertices, largest |value - (x - 2z)| {worst:.1e}, range [{c['min']}, {c['max']}]")
sys.exit(0 if n > 100 and worst < (c["max"] - c["min"]) / (2 * 4094) + 1e-4 and c["min"] < c["max"] else 1)
PY
expect_error "missing colour volume" mesh --grid "$tmp/v.raw" --dims 12,12,12 --colour-by "$tmp/w.missing"
expect_error "grid without dims" mesh --grid "$tmp/v.raw"
expect_error "grid and surface" mesh --grid "$tmp/v.raw" --dims 12,12,12 --surface sphere
expect_error "neither grid nor surface" mesh --res 16
expect_error "unknown caster" mesh --surface sphere --res 16 --caster fast

# The coherent axis caster (default) and Embree on every ray (--caster embree) give the same
# mesh, byte for byte: a wavy field on a 24³ float32 grid, plain, with §5
# merging (its projection rays) and with §4 refinement (its extension samples).
python3 - "$tmp/w.raw" <<'PY'
import array, math, sys
n = 24
h = 2.0 / (n - 1)
a = array.array('f', [math.sin(3.1 * (-1 + i * h) + 0.4) * math.cos(2.3 * (-1 + j * h) - 0.2)
                      + 0.6 * math.sin(2.7 * (-1 + k * h) + 1.9 * (-1 + i * h)) - 0.1
                      for k in range(n) for j in range(n) for i in range(n)])
open(sys.argv[1], 'wb').write(a.tobytes())
PY
for extra in "" "--merge" "--refine 2"; do
  for caster in auto embree; do
    # shellcheck disable=SC2086
    "$ldimesh" mesh --grid "$tmp/w.raw" --dims 24,24,24 --iso 0 --res 48 $extra --caster "$caster" \
      --out "$tmp/w_$caster.ply" >/dev/null || fail "wavy grid ($extra, $caster) failed"
  done
  [ "$(stat -c %s "$tmp/w_auto.ply")" -gt 10000 ] || fail "wavy grid ($extra): implausibly small mesh"
  cmp -s "$tmp/w_auto.ply" "$tmp/w_embree.ply" || fail "wavy grid ($extra): the casters' meshes differ"
done

# --repeat runs the step again on the same data (benchmarks' warm figures): the same mesh as one
# run, and one "repeats" entry per run with every stage's seconds.
"$ldimesh" mesh --grid "$tmp/w.raw" --dims 24,24,24 --iso 0 --res 48 --merge --repeat 3 --json \
  --out "$tmp/w_repeat.ply" >"$tmp/w_repeat.json" || fail "wavy grid --repeat 3 failed"
"$ldimesh" mesh --grid "$tmp/w.raw" --dims 24,24,24 --iso 0 --res 48 --merge \
  --out "$tmp/w_once.ply" >/dev/null || fail "wavy grid once failed"
cmp -s "$tmp/w_repeat.ply" "$tmp/w_once.ply" || fail "--repeat 3 changed the mesh"
python3 - "$tmp/w_repeat.json" <<'PY' || fail "--repeat 3: implausible repeats"
import json, sys
j = json.load(open(sys.argv[1]))
runs = j["repeats"]
assert len(runs) == 3, runs
for r in runs:
    assert set(r) == {"scene", "raycast", "reduce"} and all(v > 0 for v in r.values()), r
assert runs[-1]["raycast"] == j["seconds"]["raycast"], (runs[-1], j["seconds"])
PY
expect_error "repeat 0" mesh --surface sphere --res 16 --repeat 0

# ldimesh distance: the sphere meshed at two resolutions is close to itself and to the implicit
# sphere (within a small fraction of the coarser pixel, 2.5/32); a mesh is at distance 0 from itself.
"$ldimesh" mesh --surface sphere --res 32 --out "$tmp/s32.ply" >/dev/null || fail "sphere 32 failed"
"$ldimesh" mesh --surface sphere --res 64 --json --out "$tmp/s64.ply" >"$tmp/s64.json" || fail "sphere 64 failed"
"$ldimesh" distance "$tmp/s32.ply" "$tmp/s64.ply" --json >"$tmp/d.json" || fail "distance failed"
"$ldimesh" distance "$tmp/s32.ply" --surface sphere --isovalue 1 --json >"$tmp/ds.json" || fail "distance to surface failed"
python3 - "$tmp/d.json" "$tmp/ds.json" "$tmp/s64.json" <<'PY' || fail "distance: implausible figures"
import json, sys
d, ds, s64 = (json.load(open(f)) for f in sys.argv[1:])
for s in (d["forward"], d["backward"], ds["forward"]):
    assert 0 < s["mean"] <= s["rms"] <= s["max"] < 0.01, s
assert d["max"] == max(d["forward"]["max"], d["backward"]["max"])
assert d["forward"]["samples"] == 10 * s64["triangles"], (d["forward"]["samples"], s64["triangles"])
assert ds["not_converged"] == 0 and ds["outside_clip"] == 0
PY
"$ldimesh" distance "$tmp/s32.ply" "$tmp/s32.ply" >"$tmp/d.txt" || fail "distance to itself failed"
grep -q 'symmetric *max  0.0000e+00' "$tmp/d.txt" || { fail "distance to itself is not 0"; cat "$tmp/d.txt"; }
head -c 300 "$tmp/s32.ply" >"$tmp/cut.ply"
expect_error "distance: missing file" distance "$tmp/none.ply" "$tmp/s32.ply"
expect_error "distance: truncated PLY" distance "$tmp/s32.ply" "$tmp/cut.ply"
expect_error "distance: one mesh only" distance "$tmp/s32.ply"
expect_error "distance: unknown surface" distance "$tmp/s32.ply" --surface teapot
# A GLB (as published) reads like the PLY of the same mesh; a truncated one, or a format it
# does not know, is a one-line error.
"$ldimesh" mesh --surface sphere --res 32 --out "$tmp/s32.glb" >/dev/null || fail "mesh --out GLB"
"$ldimesh" distance "$tmp/s32.glb" "$tmp/s32.ply" --json >"$tmp/dg.json" || fail "distance GLB PLY"
python3 - "$tmp/dg.json" <<'PY' || fail "distance: the GLB is not the PLY's mesh"
import json, sys
d = json.load(open(sys.argv[1]))
# Draco quantizes positions to a tenth of a pixel (2.5/32 here): far below 1e-3 of the diagonal.
assert d["max"] < 1e-3 * d["diagonal"], d
PY
# --glb-normal-bits reaches the encoder: 4 bits give a smaller file of the same positions.
"$ldimesh" mesh --surface sphere --res 32 --glb-normal-bits 4 --glb-scalar-bits 3 \
  --out "$tmp/s32n4.glb" >/dev/null || fail "mesh --out GLB --glb-normal-bits 4"
[ "$(stat -c %s "$tmp/s32n4.glb")" -lt "$(stat -c %s "$tmp/s32.glb")" ] ||
  fail "--glb-normal-bits 4 did not shrink the GLB"
"$ldimesh" distance "$tmp/s32n4.glb" "$tmp/s32.glb" --json >"$tmp/dn.json" || fail "distance n4"
python3 - "$tmp/dn.json" <<'PY' || fail "distance: 4 normal bits moved the positions"
import json, sys
d = json.load(open(sys.argv[1]))
assert d["max"] < 1e-3 * d["diagonal"], d
PY
expect_error "--glb-normal-bits 1" mesh --surface sphere --res 16 --glb-normal-bits 1
expect_error "--glb-scalar-bits 17" mesh --surface sphere --res 16 --glb-scalar-bits 17
head -c 200 "$tmp/s32.glb" >"$tmp/cut.glb"
expect_error "distance: truncated GLB" distance "$tmp/cut.glb" --surface sphere
# A GLB on which Draco's decoder spends seconds (tests/transport/glb_test.cpp says how it was
# made) is refused once the decoding process has used its CPU limit.
expect_error "distance: a GLB Draco decodes slowly" distance \
  "$(dirname "$0")/../transport/data/slow_texcoord_predictor.glb" --surface sphere
grep -q "took more than 2 s of CPU" "$tmp/err" || { fail "distance: no CPU limit"; cat "$tmp/err"; }
expect_error "distance: unknown format" distance "$tmp/s32.obj" --surface sphere

if [ "$failures" -ne 0 ]; then echo "$failures check(s) failed"; exit 1; fi
echo "all CLI checks passed"
