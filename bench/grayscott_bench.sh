#!/usr/bin/env bash
# In situ cost on a real solver loop: ldimesh-grayscott on 2 ranks at a size where one output
# step (--substeps solver steps) computes in about a second, every step due, "busy": "skip".
# Runs the same simulation three times, one after the other: without in situ (no step due: the
# solver's own time), with the synchronous path ("background": false: the solver waits for the
# cast and the reduction) and with the background path (the default with MPI_THREAD_MULTIPLE:
# the solver waits for a copy of its block). Per executed step of the last run: the slowest
# rank's compute time, the time the solver was blocked inside execute()
# (StepReport::max_blocked_seconds, from --report), and the root's background stages (the
# published step's JSON "seconds"); then the three runs side by side, headed by the whole run's
# wall time (mpiexec's start to its end: start-up, every step, finalize draining the root's
# work) against the run without in situ, the figure the solver's user pays. Prints Markdown
# for docs/performance.md ("In situ cost on Gray–Scott").
# Usage: bench/grayscott_bench.sh [SIZE=192] [SUBSTEPS=60] [STEPS=20] [RESOLUTION=256]
# (binaries from build/bin, or from $LDIMESH_BIN; COLOUR_BY=U colours the V isosurface by U,
# option "colour_by"; MERGING=false|true|auto sets option "merging", default the adaptor's;
# EVERY=N makes every Nth step due instead of every step)
set -euo pipefail
cd "$(dirname "$0")/.."
size=${1:-192}
substeps=${2:-60}
steps=${3:-20}
resolution=${4:-256}
bin=${LDIMESH_BIN:-build/bin}
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
for mode in none sync background; do
  mkdir -p "$tmp/$mode"
  extra='"background": true'
  [ "$mode" = sync ] && extra='"background": false'
  [ "$mode" != none ] && [ -n "${EVERY:-}" ] && extra="$extra, \"cadence\": {\"every_steps\": $EVERY}"
  [ "$mode" = none ] && extra='"cadence": {"every_steps": 1000000000}'
  [ -n "${COLOUR_BY:-}" ] && extra="$extra, \"colour_by\": \"$COLOUR_BY\""
  case "${MERGING:-}" in
    true | false) extra="$extra, \"merging\": $MERGING" ;;
    auto) extra="$extra, \"merging\": \"auto\"" ;;
  esac
  printf '{"server": {"enabled": false}, "output_dir": "%s/%s/steps", "resolution": %d, "keep": 4, %s}\n' \
    "$tmp" "$mode" "$resolution" "$extra" >"$tmp/$mode/options.json"
  # --bind-to none: the ray caster runs threads on every rank.
  start=$(date +%s.%N)
  mpiexec -n 2 --bind-to none "$bin/ldimesh-grayscott" --size "$size" --substeps "$substeps" \
    --steps "$steps" --options "$tmp/$mode/options.json" --report >"$tmp/$mode/run.log"
  awk -v a="$start" -v b="$(date +%s.%N)" 'BEGIN { printf "%.3f\n", b - a }' >"$tmp/$mode/wall"
done
python3 - "$tmp" "$size" "$substeps" "$steps" "$resolution" <<'PY'
import json, os, statistics, sys
root, size, substeps, steps, res = sys.argv[1:]

def read_reports(mode):
    reports = {}
    for line in open(os.path.join(root, mode, "run.log")):
        if line.startswith("report "):
            r = dict(kv.split("=") for kv in line.split()[1:])
            reports[int(r["step"])] = r
    return reports

tmp = os.path.join(root, "background")
reports = read_reports("background")
stages = ["cast", "encode", "reduce", "decode", "mesh", "glb"]
colour = os.environ.get("COLOUR_BY")
print(f"2 ranks, {size}³ points, {substeps} substeps per step, {steps} steps, {res}² views, "
      f"every {os.environ.get('EVERY', '1')} step(s) due, busy = skip; background path"
      + (f"; coloured by {colour}" if colour else "") + "\n")
executed = [s for s, r in sorted(reports.items()) if r["executed"] == "1"]
every = max(1, -(-len(executed) // 20))  # at most about 20 rows; the median covers them all
if every > 1:
    print(f"Every {every}th executed step:\n")
print("| step | compute s | blocked s | blocked / compute | snapshot MB | triangles | "
      "bytes / triangle | " + " | ".join(f"{s} s" for s in stages) + " |")
print("|---" * (7 + len(stages)) + "|")
rows = []
for i, s in enumerate(executed):
    r = reports[s]
    path = os.path.join(tmp, "steps", f"step_{s:06d}.json")
    meta = json.load(open(path)) if os.path.exists(path) else None
    compute, blocked = float(r["compute_s"]), float(r["blocked_s"])
    rows.append((compute, blocked))
    if i % every and i != len(executed) - 1:
        continue
    cells = [str(s), f"{compute:.3f}", f"{blocked:.3f}", f"{100 * blocked / compute:.1f} %",
             r.get("snapshot_mb", "?"), str(meta["triangles"]) if meta else "(replaced)",
             f"{meta['bytes'] / max(meta['triangles'], 1):.2f}" if meta else ""]
    cells += [f"{meta['seconds'].get(st, 0):.3f}" if meta else "" for st in stages]
    print("| " + " | ".join(cells) + " |")
skipped = sum(1 for r in reports.values() if r["skipped_busy"] == "1")
mc = statistics.median(c for c, _ in rows)
mb = statistics.median(b for _, b in rows)
print(f"\nMedian over the {len(rows)} executed steps: compute {mc:.3f} s, blocked {mb:.3f} s "
      f"({100 * mb / mc:.1f} %); {skipped} of {len(reports)} steps skipped (root busy).")
print("\n| run | whole run s | vs. no in situ | compute s (median) | blocked s (median) | "
      "blocked / compute | compute + blocked s (median) | vs. no in situ | steps skipped |")
print("|---|---|---|---|---|---|---|---|---|")
base = None
base_wall = None
for mode, name in (("none", "no in situ (nothing due)"), ("sync", "synchronous path"),
                   ("background", "background path")):
    rs = read_reports(mode)
    ex = [r for r in rs.values() if mode == "none" or r["executed"] == "1"]
    c = statistics.median(float(r["compute_s"]) for r in ex)
    b = statistics.median(float(r["blocked_s"]) for r in ex)
    total = statistics.median(float(r["compute_s"]) + float(r["blocked_s"]) for r in ex)
    base = base or total
    wall = float(open(os.path.join(root, mode, "wall")).read())
    base_wall = base_wall or wall
    skipped = sum(1 for r in rs.values() if r["skipped_busy"] == "1")
    print(f"| {name} | {wall:.2f} | {100 * (wall / base_wall - 1):+.1f} % | {c:.3f} | {b:.4f} | "
          f"{100 * b / c:.1f} % | {total:.3f} | {100 * (total / base - 1):+.1f} % | {skipped} |")
PY
