#!/usr/bin/env bash
# The distributed pipeline for 1, 2, 4 and 8 (oversubscribed) ranks; Markdown rows for
# docs/performance.md ("Fragment codec and the MPI reduction").
# Usage: bench/mpi_bench.sh [--surface barth] [--res 512] [...]
set -euo pipefail
cd "$(dirname "$0")/.."
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
bin=build/bin/ldimesh_bench_mpi
first=--header
for n in 1 2 4 8; do
  # --bind-to none: each rank runs threads; OpenMPI would otherwise pin it to one core.
  mpiexec -n "$n" --oversubscribe --bind-to none "$bin" $first "$@"
  first=
done
