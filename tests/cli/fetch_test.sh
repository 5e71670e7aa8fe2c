#!/usr/bin/env bash
# ldimesh-serve and ldimesh-fetch as a user meets them: a folder of step files is served,
# fetched (latest, by number, as PLY, following new steps), and every error is one
# "ldimesh-fetch: error: …" line with a non-zero exit. The server is always killed at the end.
#   fetch_test.sh LDIMESH_FETCH LDIMESH_SERVE LDIMESH_MAKE_STEPS LDIMESH_GRAYSCOTT
set -u
fetch=$1
serve=$2
make_steps=$3
grayscott=$4
tmp=$(mktemp -d)
server_pid=
follower_pid=
cleanup() {
  for pid in $follower_pid $server_pid; do
    kill "$pid" 2>/dev/null
    wait "$pid" 2>/dev/null
  done
  rm -rf "$tmp"
}
trap cleanup EXIT
failures=0

fail() { echo "FAIL: $*"; failures=$((failures + 1)); }

# expect_error DESCRIPTION MESSAGE ARGS...: non-zero exit, exactly one stderr line
# "ldimesh-fetch: error: …" containing MESSAGE, no stdout.
expect_error() {
  local what=$1 message=$2
  shift 2
  timeout 20 "$fetch" "$@" >"$tmp/out" 2>"$tmp/err"
  local status=$?
  if [ "$status" -eq 0 ] || [ "$status" -eq 124 ]; then fail "$what: exit status $status"; fi
  if [ "$(wc -l <"$tmp/err")" -ne 1 ]; then fail "$what: stderr is not one line:"; cat "$tmp/err"; fi
  if ! grep -q '^ldimesh-fetch: error: ' "$tmp/err"; then fail "$what: no 'ldimesh-fetch: error:' line"; fi
  if ! grep -qF -- "$message" "$tmp/err"; then fail "$what: no '$message' in: $(cat "$tmp/err")"; fi
  if [ -s "$tmp/out" ]; then fail "$what: printed to stdout"; fi
}

# wait_for PID SECONDS: waits for PID to exit, at most SECONDS; returns its status, 124 if it
# had to be killed.
wait_for() {
  local pid=$1 limit=$(($2 * 10))
  for _ in $(seq "$limit"); do
    if ! kill -0 "$pid" 2>/dev/null; then
      wait "$pid"
      return $?
    fi
    sleep 0.1
  done
  kill -9 "$pid" 2>/dev/null
  wait "$pid" 2>/dev/null
  return 124
}

"$make_steps" "$tmp/run" 2 || { echo "FAIL: ldimesh_make_steps"; exit 1; }

# The server on a free port; the URL (with the token) is its first line.
"$serve" --dir "$tmp/run" --port 0 --token test-token >"$tmp/serve.out" 2>"$tmp/serve.err" &
server_pid=$!
url=
for _ in $(seq 100); do
  url=$(grep -o 'http://[^ ]*' "$tmp/serve.out" | head -n 1)
  [ -n "$url" ] && break
  sleep 0.1
done
if [ -z "$url" ]; then
  echo "FAIL: ldimesh-serve printed no URL"
  cat "$tmp/serve.err"
  exit 1
fi
base=$(echo "$url" | sed 's|/?token=.*||')
case "$url" in *'?token=test-token') ;; *) fail "the URL carries no token: $url" ;; esac

# --latest with the printed URL: step 2, byte-identical to what the run wrote, one line.
timeout 20 "$fetch" --url "$url" --latest -o "$tmp/a" >"$tmp/out" 2>"$tmp/err" || fail "--latest: exit status $?: $(cat "$tmp/err")"
grep -q '^step 2  time 0.02  triangles 1002  bytes [0-9]*  seconds 0.390  ' "$tmp/out" || fail "--latest: line: $(cat "$tmp/out")"
[ "$(wc -l <"$tmp/out")" -eq 1 ] || fail "--latest: not one line"
cmp -s "$tmp/run/step_000002.glb" "$tmp/a/step_000002.glb" || fail "--latest: GLB differs"
cmp -s "$tmp/run/step_000002.json" "$tmp/a/step_000002.json" || fail "--latest: JSON differs"
[ -s "$tmp/err" ] && fail "--latest: printed to stderr: $(cat "$tmp/err")"

# --step with the token given apart, and --ply.
timeout 20 "$fetch" --url "$base" --token test-token --step 1 --ply -o "$tmp/b" >"$tmp/out" 2>"$tmp/err" || fail "--step 1: exit status $?: $(cat "$tmp/err")"
cmp -s "$tmp/run/step_000001.glb" "$tmp/b/step_000001.glb" || fail "--step 1: GLB differs"
[ -f "$tmp/b/step_000001.json" ] || fail "--step 1: no JSON"
head -c 3 "$tmp/b/step_000001.ply" 2>/dev/null | grep -q ply || fail "--ply: no PLY written"

# The viewer's page needs no token; the API does.
if command -v curl >/dev/null; then
  [ "$(curl -s -o /dev/null -w '%{http_code}' "$base/api/v1/steps")" = 401 ] || fail "API without token is not 401"
  [ "$(curl -s -o /dev/null -w '%{http_code}' "$base/")" = 200 ] || fail "the viewer page is not served"
fi

expect_error "wrong token" "the server refused the token" --url "$base" --token wrong --latest -o "$tmp/c"
expect_error "no token" "the server wants a token" --url "$base" --latest -o "$tmp/c"
expect_error "unknown step" "step 42 is not on the server (it keeps steps 1 to 2)" --url "$url" --step 42 -o "$tmp/c"
expect_error "closed port" "cannot connect to http://127.0.0.1:1: connection refused" --url http://127.0.0.1:1 --token t --latest -o "$tmp/c"
expect_error "unwritable output" "cannot create folder" --url "$url" --latest -o /proc/version/x
expect_error "https" "https is not served" --url https://127.0.0.1:1 --latest -o "$tmp/c"
expect_error "step and latest" "excludes" --url "$url" --step 1 --latest -o "$tmp/c"

# --follow: the newest step, then the next one the run writes, then stop at --max-steps.
timeout 20 "$fetch" --url "$url" --follow --max-steps 2 --wait 5 -o "$tmp/f" >"$tmp/follow.out" 2>"$tmp/follow.err" &
follower_pid=$!
for _ in $(seq 50); do grep -q '^step 2 ' "$tmp/follow.out" && break; sleep 0.1; done
"$make_steps" "$tmp/run" 3 || fail "ldimesh_make_steps 3"
wait_for "$follower_pid" 15
status=$?
follower_pid=
[ "$status" -eq 0 ] || fail "--follow: exit status $status: $(cat "$tmp/follow.err")"
[ "$(grep -c '^step ' "$tmp/follow.out")" -eq 2 ] || fail "--follow: lines: $(cat "$tmp/follow.out")"
cmp -s "$tmp/run/step_000003.glb" "$tmp/f/step_000003.glb" || fail "--follow: step 3 GLB differs"

# SIGINT ends --follow cleanly (exit 0) while it waits in a long poll.
"$fetch" --url "$url" --follow --wait 30 -o "$tmp/g" >"$tmp/g.out" 2>"$tmp/g.err" &
follower_pid=$!
for _ in $(seq 50); do grep -q '^step 3 ' "$tmp/g.out" && break; sleep 0.1; done
sleep 0.2
kill -INT "$follower_pid"
wait_for "$follower_pid" 5
status=$?
follower_pid=
[ "$status" -eq 0 ] || fail "--follow after SIGINT: exit status $status: $(cat "$tmp/g.err")"
[ -s "$tmp/g.err" ] && fail "--follow after SIGINT: printed to stderr: $(cat "$tmp/g.err")"

# A served GLB on which Draco's decoder spends seconds (tests/transport/glb_test.cpp says how it
# was made): --ply decodes it in a process with a CPU limit, and fetch ends with one line.
cp "$(dirname "$0")/../transport/data/slow_texcoord_predictor.glb" "$tmp/run/step_000007.glb"
printf '{"step":7,"time":0.07,"isovalues":[1.0],"triangles":204,"vertices":168,"bytes":2064}\n' \
  >"$tmp/run/step_000007.json"
for _ in $(seq 50); do  # until the server lists it (without --ply the GLB is only saved)
  timeout 20 "$fetch" --url "$url" --step 7 -o "$tmp/s0" >/dev/null 2>&1 && break
  sleep 0.1
done
cmp -s "$tmp/run/step_000007.glb" "$tmp/s0/step_000007.glb" || fail "the slow GLB was not served"
expect_error "a GLB Draco decodes slowly" "took more than 2 s of CPU" --url "$url" --step 7 --ply -o "$tmp/s"

# A step whose isovalues are coloured one by U, one by nothing ("colour_by": ["U", null]): the PLY
# has no "value" column (it would mix a field with NaN), the GLB and its metadata come as served.
printf '{"isovalues": [0.25, 0.1], "colour_by": ["U", null], "server": {"enabled": false}, "output_dir": "%s", "resolution": 48, "log": false}\n' \
  "$tmp/mixed" >"$tmp/mixed.json"
OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 \
  "$grayscott" --size 32 --steps 1 --substeps 40 --options "$tmp/mixed.json" >/dev/null ||
  fail "Gray–Scott coloured per isovalue"
cp "$tmp/mixed/step_000001.glb" "$tmp/run/step_000008.glb"
sed 's/^{"step":1,/{"step":8,/' "$tmp/mixed/step_000001.json" >"$tmp/run/step_000008.json"
grep -q '"surface_scalars":\[{"name":"U",' "$tmp/run/step_000008.json" || fail "the mixed step has no surface_scalars"
for _ in $(seq 50); do  # until the server lists it
  timeout 20 "$fetch" --url "$url" --step 8 --ply -o "$tmp/m" >/dev/null 2>"$tmp/m.err" && break
  sleep 0.1
done
cmp -s "$tmp/run/step_000008.glb" "$tmp/m/step_000008.glb" || fail "the mixed step's GLB: $(cat "$tmp/m.err")"
head -c 400 "$tmp/m/step_000008.ply" 2>/dev/null | grep -qa 'element vertex [1-9]' ||
  fail "the mixed step's PLY has no vertices"
head -c 400 "$tmp/m/step_000008.ply" 2>/dev/null | grep -qa 'property float value' &&
  fail "the mixed step's PLY has a value column"

# SIGTERM stops the server cleanly.
kill -TERM "$server_pid"
wait_for "$server_pid" 5
status=$?
server_pid=
[ "$status" -eq 0 ] || fail "ldimesh-serve after SIGTERM: exit status $status"

# A non-loopback address only when asked for (--allow-remote), and then with a warning.
timeout 10 "$serve" --dir "$tmp/run" --port 0 --bind 0.0.0.0 >"$tmp/remote.out" 2>"$tmp/remote.err"
status=$?
[ "$status" -eq 1 ] || fail "--bind 0.0.0.0 without --allow-remote: exit status $status"
grep -q 'not a loopback address.*--allow-remote' "$tmp/remote.err" ||
  fail "--bind 0.0.0.0 without --allow-remote: $(cat "$tmp/remote.err")"
"$serve" --dir "$tmp/run" --port 0 --bind 0.0.0.0 --allow-remote >"$tmp/remote.out" 2>"$tmp/remote.err" &
server_pid=$!
for _ in $(seq 100); do grep -q 'http://' "$tmp/remote.out" && break; sleep 0.1; done
grep -q '^http://0\.0\.0\.0:[0-9]*/?token=\|serving .* at http://0\.0\.0\.0:' "$tmp/remote.out" ||
  fail "--allow-remote: no URL: $(cat "$tmp/remote.out")"
grep -q 'warning: the HTTP server listens on 0\.0\.0\.0, reachable from the network' "$tmp/remote.err" ||
  fail "--allow-remote: no warning: $(cat "$tmp/remote.err")"
kill -TERM "$server_pid"
wait_for "$server_pid" 5
server_pid=

if [ "$failures" -ne 0 ]; then
  echo "$failures failure(s)"
  exit 1
fi
echo "ok"
