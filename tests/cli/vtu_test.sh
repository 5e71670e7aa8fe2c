#!/usr/bin/env bash
# `ldimesh mesh --vtu` on files written by VTK itself (tests/cli/make_vtu.py): order-2 Lagrange
# hexahedra carrying |x|² beside linear hexahedra, meshed at |x|² = 0.49 — the mesh lies on the
# sphere of radius 0.7 (`ldimesh distance` to the sphere, and the same figures to the file's own
# isosurface with `distance --vtu`), also from a .pvtu over two pieces, with and without ghost
# layers; one-line errors naming the field or
# the cell for a missing field, a vector field, an unsupported cell type, orders that differ
# along the axes, a cell naming a point the file does not have, more points or values declared
# than the file can hold, a component count that is not one, two arrays of one name, a missing
# piece, a compression header that crashes VTK's reader (read in a child process: one line,
# exit 1).
#   vtu_test.sh LDIMESH SOURCE_DIR
set -u
ldimesh=$1
src=$2
. "$(dirname "$0")/../lib.sh"
test_setup
for kind in sphere cells ascii raw timesteps triangle tet15 degrees badpoint zeroblock; do
  /usr/bin/python3 "$src/tests/cli/make_vtu.py" $kind "$tmp/$kind.vtu" || fail "make_vtu.py $kind"
done
/usr/bin/python3 "$src/tests/cli/make_vtu.py" pieces "$tmp/pieces.pvtu" || fail "make_vtu.py pieces"
/usr/bin/python3 "$src/tests/cli/make_vtu.py" ghosts "$tmp/ghosts.pvtu" || fail "make_vtu.py ghosts"

"$ldimesh" mesh --vtu "$tmp/sphere.vtu" --field r --iso 0.49 --res 128 --out "$tmp/sphere.ply" \
  --json >"$tmp/sphere.json" 2>"$tmp/sphere.err" || { cat "$tmp/sphere.err"; fail "--vtu sphere.vtu"; }
"$ldimesh" distance "$tmp/sphere.ply" --surface sphere --iso 0.49 --json >"$tmp/distance.json" ||
  fail "ldimesh distance"
/usr/bin/python3 - "$tmp/distance.json" "$tmp/sphere.json" <<'PY' || fail "the mesh of the VTK-written file is not on the sphere r = 0.7"
import json, sys
d = json.load(open(sys.argv[1]))["forward"]
summary = json.load(open(sys.argv[2]))
triangles = summary.get("triangles", summary.get("mesh", {}).get("triangles", 0))
print(f"sphere.vtu at r² = 0.49: {triangles} triangles, mean {d['mean']:.1e}, max {d['max']:.1e}")
# the hits are exact (|x|² is degree 2 per axis); the rest is the triangles between them
sys.exit(0 if d["mean"] < 3e-4 and d["max"] < 2e-3 and triangles > 10000 else 1)
PY

# Mixed quadratic cells (hexahedra of 27 and 20 nodes, tetrahedra, wedges, pyramids) written by
# VTK, merged (§5): every vertex on the sphere to float rounding (lossless fragments; the hits are
# exact: |x|² lies in each cell's space), one closed surface across the types' boundaries.
"$ldimesh" mesh --vtu "$tmp/cells.vtu" --field r --iso 0.49 --res 128 --merge --lossless \
  --out "$tmp/cells.ply" 2>"$tmp/cells.err" || { cat "$tmp/cells.err"; fail "--vtu cells.vtu"; }
/usr/bin/python3 "$src/tests/cli/sphere_vertices.py" "$tmp/cells.ply" 2e-7 closed ||
  fail "the merged mesh of mixed cells is not the closed sphere r = 0.7"

# --colour-by: the isosurface of r coloured by the file's array h = x + 2y, which every cell
# represents exactly: each vertex of the PLY (float value property) carries x + 2y of its
# position, within half a step of the fragments' 12 scalar bits over the range and the float
# depths' rounding; the summary names the field and its range.
"$ldimesh" mesh --vtu "$tmp/sphere.vtu" --field r --iso 0.49 --colour-by h --res 96 \
  --out "$tmp/coloured.ply" --json >"$tmp/coloured.json" 2>"$tmp/coloured.err" ||
  { cat "$tmp/coloured.err"; fail "--vtu --colour-by h"; }
/usr/bin/python3 - "$tmp/coloured.ply" "$tmp/coloured.json" <<'PY' || fail "the colours are not x + 2y"
import json, struct, sys
data = open(sys.argv[1], "rb").read()
header, body = data.split(b"end_header\n", 1)
lines = header.decode().splitlines()
assert "property float value" in lines, "no value property"
n = int(next(l for l in lines if l.startswith("element vertex")).split()[2])
worst, lo, hi = 0.0, float("inf"), -float("inf")
for v in range(n):
    x, y, z, nx, ny, nz, value = struct.unpack_from("<7f", body, 28 * v)
    worst = max(worst, abs(value - (x + 2 * y)))
    lo, hi = min(lo, value), max(hi, value)
colour = json.load(open(sys.argv[2]))["colour"]
print(f"{n} vertices coloured by h: largest |value - (x + 2y)| {worst:.1e}, range [{lo:.4f}, {hi:.4f}]; "
      f"summary {colour}")
sys.exit(0 if n > 5000 and worst < (hi - lo) / (2 * 4094) + 2e-5 and colour["field"] == "h" and colour["min"] == lo and
         colour["max"] == hi and colour["uncoloured_vertices"] == 0 and hi - lo > 2.5 else 1)
PY

# `ldimesh distance --vtu`: the same mesh measured against the file's own isosurface (the cells'
# polynomials, looked up point by point) — here the sphere itself, so the same figures.
"$ldimesh" distance "$tmp/sphere.ply" --vtu "$tmp/sphere.vtu" --field r --iso 0.49 --json \
  >"$tmp/distance_vtu.json" 2>"$tmp/distance_vtu.err" ||
  { cat "$tmp/distance_vtu.err"; fail "ldimesh distance --vtu"; }
/usr/bin/python3 - "$tmp/distance.json" "$tmp/distance_vtu.json" <<'PY' || fail "distance --vtu differs from the sphere's"
import json, sys
a, b = (json.load(open(f)) for f in sys.argv[1:3])
print(f"to the sphere: mean {a['forward']['mean']:.6e}; to the file's isosurface: "
      f"mean {b['forward']['mean']:.6e}, {b['not_converged']} not converged")
same = all(abs(a["forward"][k] - b["forward"][k]) <= 1e-9 for k in ("mean", "rms", "max"))
sys.exit(0 if same and b["not_converged"] == 0 and
         a["forward"]["samples"] == b["forward"]["samples"] else 1)
PY
expect_distance_error() {  # expect_distance_error PATTERN ARGS...
  local pattern=$1
  shift
  if "$ldimesh" distance "$@" >/dev/null 2>"$tmp/err" || ! grep -q -- "$pattern" "$tmp/err"; then
    cat "$tmp/err"
    fail "ldimesh distance $*: no error with '$pattern'"
  fi
}
expect_distance_error "no point array 'u'" "$tmp/sphere.ply" --vtu "$tmp/sphere.vtu" --field u
expect_distance_error "needs --field" "$tmp/sphere.ply" --vtu "$tmp/sphere.vtu"
expect_distance_error "not both" "$tmp/sphere.ply" --vtu "$tmp/sphere.vtu" --field r --surface sphere
expect_distance_error "isovalue of --surface or --vtu" "$tmp/sphere.ply" "$tmp/sphere.ply" --iso 0.5
expect_distance_error "requires --vtu" "$tmp/sphere.ply" --surface sphere --field r

# The same cells as a .pvtu over two pieces: the same mesh.
"$ldimesh" mesh --vtu "$tmp/pieces.pvtu" --field r --iso 0.49 --res 128 --out "$tmp/pieces.ply" \
  >/dev/null 2>"$tmp/pieces.err" || { cat "$tmp/pieces.err"; fail "--vtu pieces.pvtu"; }
cmp -s "$tmp/sphere.ply" "$tmp/pieces.ply" || fail "the .pvtu's mesh differs from the .vtu's"
# Two pieces that each carry the other's layer of cells beside z = 0 as ghosts (DUPLICATECELL in
# vtkGhostType, as dolfinx writes in parallel): 34 ghost cells skipped, the sphere's 66 cells
# each meshed once, the same mesh.
"$ldimesh" mesh --vtu "$tmp/ghosts.pvtu" --field r --iso 0.49 --res 128 --out "$tmp/ghosts.ply" \
  >"$tmp/ghosts.out" 2>"$tmp/ghosts.err" || { cat "$tmp/ghosts.err"; fail "--vtu ghosts.pvtu"; }
grep -q "66 cells in 2 blocks, 34 ghost cells skipped" "$tmp/ghosts.out" ||
  { cat "$tmp/ghosts.out"; fail "ghost cells of the .pvtu's pieces not skipped"; }
cmp -s "$tmp/sphere.ply" "$tmp/ghosts.ply" || fail "the ghost-layered .pvtu's mesh differs from the .vtu's"
# The same cells uncompressed, as VTK writes them: ASCII, raw appended data in two pieces, and
# two time steps (each array once per step under its name; step 0 is read): the same mesh. The
# checks before VTK reads the data (a byte a value, one array per name and step) pass them.
for kind in ascii raw timesteps; do
  "$ldimesh" mesh --vtu "$tmp/$kind.vtu" --field r --iso 0.49 --res 128 --out "$tmp/$kind.ply" \
    >/dev/null 2>"$tmp/$kind.err" || { cat "$tmp/$kind.err"; fail "--vtu $kind.vtu"; }
  cmp -s "$tmp/sphere.ply" "$tmp/$kind.ply" || fail "the mesh of $kind.vtu differs from sphere.vtu's"
done

# Errors: one line on stderr, naming what is wrong, and a non-zero exit.
expect_error() {  # expect_error PATTERN ARGS...
  local pattern=$1
  shift
  if "$ldimesh" mesh "$@" --out "$tmp/x.ply" >"$tmp/out" 2>"$tmp/err"; then
    fail "ldimesh mesh $* succeeded"
  elif [ "$(wc -l <"$tmp/err")" -ne 1 ] || ! grep -q -- "$pattern" "$tmp/err"; then
    cat "$tmp/err"
    fail "ldimesh mesh $*: not one line with '$pattern'"
  fi
}
expect_error "no point array 'u' (point arrays: " --vtu "$tmp/sphere.vtu" --field u
expect_error "'vec' has 3 components" --vtu "$tmp/sphere.vtu" --field vec
expect_error "no point array 'nope'" --vtu "$tmp/sphere.vtu" --field r --colour-by nope
expect_error "'vec' has 3 components" --vtu "$tmp/sphere.vtu" --field r --colour-by vec
expect_error "--colour-by needs --grid or --vtu" --surface sphere --colour-by h
expect_error "cell 1 is VTK_TRIANGLE (VTK type 5): hexahedra, tetrahedra, wedges and pyramids" \
  --vtu "$tmp/triangle.vtu" --field r
expect_error "cell 0: VTK's 15-node tetrahedron" --vtu "$tmp/tet15.vtu" --field r
expect_error "cell 0: orders 2, 2, 3 differ" --vtu "$tmp/degrees.vtu" --field r
expect_error "cell 1 names point 1000 of 54" --vtu "$tmp/badpoint.vtu" --field r
# Damaged XML, each refused before VTK reads the data (write_damaged FROM TO OLD NEW: the
# first occurrence of OLD replaced by NEW, which must be there).
write_damaged() {
  /usr/bin/python3 - "$@" <<'PY' || fail "cannot write $2"
import sys
data = open(sys.argv[1], "rb").read()
old, new = sys.argv[3].encode(), sys.argv[4].encode()
assert old in data, old
open(sys.argv[2], "wb").write(data.replace(old, new, 1))
PY
}
# A damaged count: NumberOfPoints with digits put in front (VTK would allocate what it says).
write_damaged "$tmp/sphere.vtu" "$tmp/huge.vtu" 'NumberOfPoints="' 'NumberOfPoints="90000000000'
expect_error "declares 900000000001744 points and 66 cells, more than its" --vtu "$tmp/huge.vtu" --field r
# A component count of 43 digits makes VTK 9.1's CreateArray loop over 2³¹ component names.
write_damaged "$tmp/sphere.vtu" "$tmp/components.vtu" 'NumberOfComponents="3"' \
  'NumberOfComponents="3333333333333333333333333333333333333333333"'
expect_error "array 'vec' has NumberOfComponents \"3333333333333333333333333333333333333333333\", not a count of 1 to 1048576" \
  --vtu "$tmp/components.vtu" --field r
# One VTK reads into an int but still loops over: on the connectivity, whose size is not
# declared.
write_damaged "$tmp/ascii.vtu" "$tmp/components2.vtu" 'Name="connectivity"' \
  'Name="connectivity" NumberOfComponents="2147483647"'
expect_error "array 'connectivity' has NumberOfComponents \"2147483647\", not a count of 1 to" \
  --vtu "$tmp/components2.vtu" --field r
# Uncompressed, a value takes at least a byte: 100 000 components of 66 cells cannot be in a file
# of some 100 KB (compressed, they could: 10 000 : 1).
cells66=$(printf ' 1%.0s' $(seq 66))
write_damaged "$tmp/ascii.vtu" "$tmp/wide.vtu" '<CellData>' \
  "<CellData><DataArray type=\"Float64\" Name=\"q\" NumberOfComponents=\"100000\" format=\"ascii\">$cells66</DataArray>"
expect_error "array 'q' declares 6600000 values, more than its" --vtu "$tmp/wide.vtu" --field r
# Two cell data arrays of one name: VTK 9.1's reader crashes on it (a segmentation fault), even
# where both are whole; refused first. Two point data arrays named as the field: ambiguous.
q="<DataArray type=\"Float64\" Name=\"q\" format=\"ascii\">$cells66</DataArray>"
write_damaged "$tmp/sphere.vtu" "$tmp/twice.vtu" '<CellData>' "<CellData>$q$q"
expect_error "two cell data arrays named 'q'" --vtu "$tmp/twice.vtu" --field r
write_damaged "$tmp/sphere.vtu" "$tmp/twice-array.vtu" '<CellData>' \
  "<CellData>$q<Array type=\"String\" Name=\"q\" format=\"ascii\">$cells66</Array>"
expect_error "two cell data arrays named 'q'" --vtu "$tmp/twice-array.vtu" --field r
write_damaged "$tmp/sphere.vtu" "$tmp/twice-points.vtu" 'Name="h"' 'Name="r"'
expect_error "two point data arrays named 'r'" --vtu "$tmp/twice-points.vtu" --field r
# A compression header whose block size is 0: VTK 9.1's reader divides by it (SIGFPE on x86-64);
# it runs in a child process, so the tool prints one line and exits 1 instead of crashing (a
# crash in the tool itself prints no such line). A VTK that checks the size, or a machine whose
# division does not trap, refuses the file in one line of its own.
crash="zeroblock.vtu': \(VTK's reader process died of signal 8\|VTK cannot read it\)"
expect_error "$crash" --vtu "$tmp/zeroblock.vtu" --field r
expect_distance_error "$crash" "$tmp/sphere.ply" --vtu "$tmp/zeroblock.vtu" --field r
expect_error "no such file" --vtu "$tmp/none.vtu" --field r
expect_error "VTK cannot read it" --vtu "$src/README.md" --field r
rm -f "$tmp"/pieces_1.vtu "$tmp"/pieces/pieces_1.vtu
expect_error "piece 1 cannot be read" --vtu "$tmp/pieces.pvtu" --field r

finish
