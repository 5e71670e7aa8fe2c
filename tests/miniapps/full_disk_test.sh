#!/usr/bin/env bash
# A disk that fills while a step is written (issue 26): the job goes on, the step is published
# from memory, the folder holds no torn or temporary file, and writing resumes when there is room
# again. ldimesh-grayscott on one rank (48³ points: a solver that computes for about 60 ms per
# step, so that the root keeps up) writes every published step into output_dir, with the
# LD_PRELOAD shim SHIM (tests/support/full_disk.c) failing the 2nd and 3rd step GLBs it starts
# writing as a full disk does: half of the bytes reach the file, then ENOSPC. Then:
#   - the job ends normally (steps the root was too busy for are skipped, as always: the test
#     counts the published ones);
#   - stderr says once that a step was not written, with the system's reason ("No space left
#     on device"), and once that writing works again, with the number of steps not written (2);
#   - the folder holds exactly the other published steps: every .json with its .glb, which
#     decodes to the metadata's counts, and no hidden temporary file (the half-written ones are
#     removed).
# Usage: full_disk_test.sh MPIEXEC BIN_DIR SHIM
set -euo pipefail
shopt -s nullglob
mpiexec=$1
bin=$2
shim=$3
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1

fail() {
  echo "FAIL: $*" >&2
  [ -f "$tmp/log" ] && tail -n 20 "$tmp/log" >&2
  exit 1
}

field() {  # field NAME FILE: an integer field of a step's metadata
  grep -o "\"$1\":[0-9]*" "$2" | head -n 1 | cut -d: -f2
}

dir=$tmp/steps
printf '{"server": {"enabled": false}, "output_dir": "%s", "resolution": 64, "keep": 100}\n' \
  "$dir" >"$tmp/options.json"
# Preloaded after what the caller preloads (the sanitizer run's dlclose shim).
"$mpiexec" -n 1 -x LD_PRELOAD="${LD_PRELOAD:+$LD_PRELOAD:}$shim" -x LDIMESH_TEST_FULL_DISK=2,3 \
  "$bin/ldimesh-grayscott" --options "$tmp/options.json" --size 48 --substeps 50 --steps 16 \
  >"$tmp/log" 2>&1 ||
  fail "the job failed"

published=$(sed -n 's/.*done, [0-9]* steps, \([0-9]*\) published.*/\1/p' "$tmp/log")
[ -n "$published" ] || fail "no summary line"
[ "$published" -ge 4 ] || fail "only $published steps published: too few to test"
[ "$(grep -c 'not written: .*No space left on device' "$tmp/log")" -eq 1 ] ||
  fail "the log does not say once that a step was not written for lack of space"
grep -q 'again from step [0-9]* (2 steps were not written)' "$tmp/log" ||
  fail "the log does not say that writing works again after 2 steps"

hidden=("$dir"/.step_*)
[ "${#hidden[@]}" -eq 0 ] || fail "temporary files left: ${hidden[*]}"
jsons=("$dir"/step_*.json)
[ "${#jsons[@]}" -eq $((published - 2)) ] ||
  fail "${#jsons[@]} steps on disk, $published published, 2 not written"
for json in "${jsons[@]}"; do
  glb=${json%.json}.glb
  [ -f "$glb" ] || fail "$json has no GLB"
  [ "$(stat -c %s "$glb")" -eq "$(field bytes "$json")" ] || fail "$glb has the wrong size"
  line=$("$bin/ldimesh" distance "$glb" "$glb" 2>&1 | head -n 1) || fail "$glb does not decode: $line"
  counts=$(sed -n 's/.*A = [^ ]* (\([0-9]*\) vertices, \([0-9]*\) faces).*/\1 \2/p' <<<"$line")
  [ "$counts" = "$(field vertices "$json") $(field triangles "$json")" ] ||
    fail "$glb decodes to $counts, its metadata says otherwise"
done
globs=("$dir"/step_*.glb)
[ "${#globs[@]}" -eq "${#jsons[@]}" ] || fail "a GLB without its metadata"
echo "full disk: $published steps published, ${#jsons[@]} on disk, 2 not written (ENOSPC" \
  "half-way), no temporary file left"
