#!/usr/bin/env bash
# The whole delivery path with real meshes: `ldimesh mesh --steps-dir` writes a step (Draco GLB +
# metadata), `ldimesh serve` serves the folder, `ldimesh-fetch` downloads it (and decodes it
# to PLY): the GLB arrives byte for byte and the PLY has the published triangle count.
#   serve_test.sh LDIMESH LDIMESH_FETCH
set -u
ldimesh=$1
fetch=$2
. "$(dirname "$0")/../lib.sh"
test_setup

"$ldimesh" mesh --surface torus --res 48 --steps-dir "$tmp/steps" --step 7 --time 0.5 >/dev/null \
  || fail "ldimesh mesh --steps-dir"
[ -s "$tmp/steps/step_000007.glb" ] && [ -s "$tmp/steps/step_000007.json" ] || fail "no step files written"
triangles=$(sed -n 's/.*"triangles": *\([0-9]*\).*/\1/p' "$tmp/steps/step_000007.json")
[ "${triangles:-0}" -gt 1000 ] || fail "implausible triangle count '$triangles' in the metadata"

"$ldimesh" serve --dir "$tmp/steps" --port 0 >"$tmp/serve.out" 2>"$tmp/serve.err" &
server_pid=$!
url=$(wait_for_url "$tmp/serve.out")
[ -n "$url" ] || { fail "ldimesh serve printed no URL"; cat "$tmp/serve.err"; exit 1; }

timeout 30 "$fetch" --url "$url" --latest --ply -o "$tmp/got" >"$tmp/fetch.out" || fail "ldimesh-fetch --latest --ply"
cmp -s "$tmp/steps/step_000007.glb" "$tmp/got/step_000007.glb" || fail "the fetched GLB differs from the served one"
grep -aqx "element face $triangles" "$tmp/got/step_000007.ply" || fail "the decoded PLY does not have $triangles faces"
grep -Eq "^step 7 +time 0\.5 +triangles $triangles " "$tmp/fetch.out" \
  || fail "ldimesh-fetch printed no line for step 7 at time 0.5 with $triangles triangles"

# The viewer's page is served without a token; the API is not.
if command -v curl >/dev/null 2>&1; then
  base=${url%%\?*}
  [ "$(curl -s -o /dev/null -w '%{http_code}' "${base}")" = 200 ] || fail "the viewer page is not served"
  [ "$(curl -s -o /dev/null -w '%{http_code}' "${base}api/v1/steps")" = 401 ] || fail "the API answered without a token"
fi

if [ "$failures" -ne 0 ]; then echo "$failures check(s) failed"; exit 1; fi
echo "all delivery checks passed"
