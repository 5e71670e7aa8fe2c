#!/usr/bin/env bash
# Runs every command of docs/performance.md, one after the other, each one's output into
# OUT_DIR/NAME.log and a line per command (start, exit status, end) into OUT_DIR/index: what to
# run, on an otherwise idle machine, before the figures there are replaced. About 10 minutes on
# two cores. Needs a Release build in BUILD_DIR (default build) and VTK for the Python peers.
# Usage: bench/measure_all.sh OUT_DIR [BUILD_DIR]
set -uo pipefail
out=${1:?usage: bench/measure_all.sh OUT_DIR [BUILD_DIR]}
bin=${2:-build}/bin
cd "$(dirname "$0")/.."
mkdir -p "$out"
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
run() {
  local name=$1
  shift
  echo "=== $name $(date +%T): $*" | tee -a "$out/index"
  "$@" >"$out/$name.log" 2>&1
  echo "    exit $? $(date +%T)" | tee -a "$out/index"
}
echo "=== commit $(git rev-parse --short HEAD) $(date -u +%F)" | tee -a "$out/index"
run flying_edges /usr/bin/python3 bench/flying_edges.py --repeats 3
run tet_contour /usr/bin/python3 bench/tet_contour.py --repeats 3 --steps 3
run mesh_1core "$bin/ldimesh_bench_mesh" --repeat 7 --threads 1
run mesh_2cores "$bin/ldimesh_bench_mesh" --repeat 7
run refine "$bin/ldimesh_bench_refine" --repeat 11 --threads 1
for i in 1 2 3; do
  for case in "quad 2" "quad 1" "tri 1"; do
    set -- $case
    run "merge_${1}_${2}threads_$i" "$bin/ldimesh" mesh --surface marschner-lobb --res 512 \
      --merge $([ "$1" = quad ] && echo --quad) --threads "$2" --lossless --json
  done
done
run codec "$bin/ldimesh_bench_codec"
run codec_small "$bin/ldimesh_bench_codec" --depth-bits 16 --normal-bits 10
run mpi bash bench/mpi_bench.sh --res 512
run glb_512 "$bin/ldimesh_bench_glb" --res 512 --repeat 3
run glb_448 "$bin/ldimesh_bench_glb" --res 448 --repeat 5
run cell_cost /usr/bin/python3 bench/cell_cost.py
run highorder /usr/bin/python3 bench/highorder_cells_contour.py
run colour /usr/bin/python3 bench/colour_cost.py --repeats 5
run curved_shell "$bin/ldimesh_bench_sources" --only elements --elements 8 --order 4 --curved 4 \
  --shell 8 --res 256
run grayscott env COLOUR_BY=U MERGING=false bash bench/grayscott_bench.sh 192 60 20 256
echo "=== done $(date +%T)" | tee -a "$out/index"
