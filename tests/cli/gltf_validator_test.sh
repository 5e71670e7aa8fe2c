#!/usr/bin/env bash
# Every kind of GLB ldimesh writes passes Khronos' glTF validator (npm gltf-validator) with no
# error and no warning: a small mesh (one Draco primitive), a mesh of more than 200 000
# triangles (encoded in slabs: several primitives of one mesh), a mesh coloured by a second
# field (_SCALAR), small and large, an in situ step of two isovalues (a mesh and node each, the
# node's extras naming the surface), and one whose first isovalue is coloured and the second not
# ("colour_by": ["U", null]: primitives with and without _SCALAR).
#   gltf_validator_test.sh LDIMESH SOURCE_DIR LDIMESH_ANALYTIC LDIMESH_GRAYSCOTT
set -u
ldimesh=$1
src=$2
analytic=$3
grayscott=$4
. "$(dirname "$0")/../lib.sh"
test_setup
"$ldimesh" mesh --surface torus --res 64 --out "$tmp/small.glb" >/dev/null || fail "small mesh"
"$ldimesh" mesh --surface torus --res 256 --out "$tmp/large.glb" >/dev/null || fail "large mesh"
python3 - "$tmp" <<'PY'
import array, math, sys
n = 96
v, c = array.array('f'), array.array('f')
for k in range(n):
    for j in range(n):
        for i in range(n):
            x, y, z = (2.0 * i / (n - 1) - 1, 2.0 * j / (n - 1) - 1, 2.0 * k / (n - 1) - 1)
            v.append(x * x + y * y + z * z + 0.3 * math.sin(6 * x) * math.sin(5 * y))
            c.append(x - 0.5 * z)
open(sys.argv[1] + "/v.raw", "wb").write(v.tobytes())
open(sys.argv[1] + "/c.raw", "wb").write(c.tobytes())
PY
for res in 64 512; do
  "$ldimesh" mesh --grid "$tmp/v.raw" --dims 96,96,96 --iso 0.5 --res "$res" --colour-by "$tmp/c.raw" \
    --out "$tmp/coloured$res.glb" >/dev/null || fail "coloured mesh at $res"
done
# A step of two isovalues of the sphere's field, as the adaptor publishes it (the analytic
# mini-app, one process).
printf '{"isovalues": [1, 0.36], "server": {"enabled": false}, "output_dir": "%s", "resolution": 64, "log": false}\n' \
  "$tmp/steps" >"$tmp/two.json"
OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 \
  "$analytic" --surface sphere --steps 1 --options "$tmp/two.json" \
  >/dev/null || fail "two isovalues in situ"
python3 - "$tmp/steps/step_000001.glb" <<'PY' || fail "the two isovalues are not a node each"
import json, struct, sys
data = open(sys.argv[1], "rb").read()
length = struct.unpack_from("<I", data, 12)[0]
doc = json.loads(data[20:20 + length])
surfaces = sorted(n["extras"]["ldimesh_surface"] for n in doc["nodes"])
assert surfaces == [0, 1] and len(doc["meshes"]) == 2, (surfaces, len(doc["meshes"]))
PY
# Gray–Scott's V at two isovalues, the first coloured by U, the second not (one process).
printf '{"isovalues": [0.25, 0.1], "colour_by": ["U", null], "server": {"enabled": false}, "output_dir": "%s", "resolution": 64, "log": false}\n' \
  "$tmp/mixed" >"$tmp/mixed.json"
OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 \
  "$grayscott" --size 32 --steps 1 --substeps 40 --options "$tmp/mixed.json" \
  >/dev/null || fail "Gray–Scott coloured per isovalue"
python3 - "$tmp/mixed/step_000001.glb" <<'PY' || fail "the mixed step lacks a surface with or without _SCALAR"
import json, struct, sys
data = open(sys.argv[1], "rb").read()
length = struct.unpack_from("<I", data, 12)[0]
doc = json.loads(data[20:20 + length])
scalar = [any("_SCALAR" in p["attributes"] for p in m["primitives"]) for m in doc["meshes"]]
assert scalar == [True, False], scalar
assert doc["meshes"][0]["extras"]["ldimesh"]["surface_scalar_ranges"][1] is None
PY
cd "$src" || fail "no source folder"
node tests/cli/validate_glb.mjs --primitives 2 "$tmp/large.glb" "$tmp/small.glb" "$tmp/coloured64.glb" \
  "$tmp/steps/step_000001.glb" "$tmp/mixed/step_000001.glb" ||
  fail "a GLB is not valid glTF"
node tests/cli/validate_glb.mjs --primitives 2 "$tmp/coloured512.glb" ||
  fail "the large coloured GLB is not valid glTF"
finish
