#!/usr/bin/env bash
# A job killed with SIGKILL while it writes its steps leaves no step that reads as valid but
# wrong (issue 26). Round after round, ldimesh-analytic on 2 ranks writes every published step
# into a fresh output_dir, with fwrite slowed down by an LD_PRELOAD shim (SHIM: 4 KiB pieces,
# 20 ms apart) so that a step's GLB takes a few hundred milliseconds to write; after a pseudo-random
# delay (seeded per round) every process of the job gets SIGKILL. Then, in that folder:
#   - every step_N.json has its step_N.glb, whose size is the metadata's "bytes" and which
#     decodes (decode_glb, through `ldimesh distance`) to the metadata's vertex and face counts;
#   - a step_N.glb without its .json (the writer renames the .json last) is at most one, the
#     newest step, and decodes too;
#   - what else is there is only the writer's hidden temporary files (".step_N.….tmp.…",
#     which readers ignore): a kill in the middle of a write.
# The rounds go on until two kills have landed in the middle of a write (a temporary file
# left, or a GLB without its .json), at most MAX_ROUNDS; none in all of them fails the test,
# which would then not have tested what it is for.
# Usage: kill_test.sh MPIEXEC BIN_DIR SHIM [MAX_ROUNDS (default 20)]
set -euo pipefail
shopt -s nullglob
mpiexec=$1
bin=$2
shim=$3
max_rounds=${4:-20}
tmp=$(mktemp -d)
trap 'pkill -9 -f -- "$tmp/" 2>/dev/null || true; rm -rf "$tmp"' EXIT
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_rmaps_base_oversubscribe=1

fail() {
  echo "FAIL: $*" >&2
  exit 1
}

field() {  # field NAME FILE: an integer field of a step's metadata
  grep -o "\"$1\":[0-9]*" "$2" | head -n 1 | cut -d: -f2
}

# decoded FILE: "V F" as decode_glb reads the GLB (fails the test if it does not decode).
decoded() {
  local line
  line=$("$bin/ldimesh" distance "$1" "$1" 2>&1 | head -n 1) || fail "$1 does not decode: $line"
  sed -n 's/.*A = [^ ]* (\([0-9]*\) vertices, \([0-9]*\) faces).*/\1 \2/p' <<<"$line"
}

total_steps=0 torn=0 temporaries=0 mid_write=0 round=0
while ((mid_write < 2 && round < max_rounds)); do
  round=$((round + 1))
  dir=$tmp/round$round
  opts=$tmp/round$round.json
  printf '{"server": {"enabled": false}, "output_dir": "%s", "resolution": 128}\n' "$dir" >"$opts"
  # In a subshell that outlives the kill (it is not matched below): no job notice of it.
  (setsid "$mpiexec" -n 2 --oversubscribe -x LD_PRELOAD="$shim" "$bin/ldimesh-analytic" \
    --options "$opts" --surface torus --period 8 --steps 1000000 >"$dir.log" 2>&1 ||
    true) 2>/dev/null &
  job=$!
  # Once the first step is out, kill after 0–1.5 s: mostly while a later step is on its way.
  for ((wait = 0; wait < 300; wait++)); do
    compgen -G "$dir/step_*.json" >/dev/null && break
    kill -0 "$job" 2>/dev/null || { cat "$dir.log" >&2; fail "round $round: the job ended"; }
    sleep 0.1
  done
  RANDOM=$((4242 + round))
  sleep "$((RANDOM % 16))e-1"
  pkill -9 -f -- "$opts" || true
  wait "$job" 2>/dev/null || true

  newest_json=-1 newest_glb=-1 orphans=0
  for json in "$dir"/step_*.json; do
    step=$(basename "$json" .json)
    glb=$dir/$step.glb
    [ -f "$glb" ] || fail "round $round: $step.json without its .glb"
    bytes=$(stat -c %s "$glb")
    [ "$bytes" = "$(field bytes "$json")" ] ||
      fail "round $round: $step.glb has $bytes bytes, its metadata says $(field bytes "$json")"
    [ "$(decoded "$glb")" = "$(field vertices "$json") $(field triangles "$json")" ] ||
      fail "round $round: $step.glb decodes to $(decoded "$glb") (vertices faces), not the metadata's"
    n=$((10#${step#step_}))
    ((n > newest_json)) && newest_json=$n
    total_steps=$((total_steps + 1))
  done
  for glb in "$dir"/step_*.glb; do
    step=$(basename "$glb" .glb)
    [ -f "$dir/$step.json" ] && continue
    orphans=$((orphans + 1))
    n=$((10#${step#step_}))
    newest_glb=$n
    [ -n "$(decoded "$glb")" ] || fail "round $round: $step.glb (no .json yet) does not decode"
  done
  ((orphans <= 1)) || fail "round $round: $orphans GLBs without metadata (at most the newest)"
  ((orphans == 0 || newest_glb > newest_json)) ||
    fail "round $round: a GLB without metadata older than the newest complete step"
  torn=$((torn + orphans))
  left=0
  for f in "$dir"/.* "$dir"/*; do
    name=$(basename "$f")
    case $name in
      . | .. | step_*.json | step_*.glb) ;;
      .step_*.tmp.*) left=$((left + 1)) ;;
      *) fail "round $round: unexpected file $name in the output folder" ;;
    esac
  done
  temporaries=$((temporaries + left))
  ((left + orphans > 0)) && mid_write=$((mid_write + 1))
done
echo "kill test: $round jobs killed with SIGKILL, $mid_write of them while writing a step;" \
  "$total_steps complete steps, all valid; $torn GLBs whose .json was not yet written (the" \
  "newest step each); $temporaries temporary files left"
((mid_write > 0)) || fail "no kill in $round rounds landed while a step was being written"
