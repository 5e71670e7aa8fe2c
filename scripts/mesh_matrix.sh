#!/usr/bin/env bash
# Writes the CLI's meshes on a matrix of cases into a folder, one binary PLY per case, and a
# SHA-256 list of them (SHA256SUMS), so that two builds can be compared byte for byte:
#
#   scripts/mesh_matrix.sh build /tmp/before        # with the old build
#   scripts/mesh_matrix.sh build /tmp/after         # with the new one
#   diff /tmp/before/SHA256SUMS /tmp/after/SHA256SUMS && echo identical
#
# Cases: analytic surfaces (sphere, torus, Barth, Marschner–Lobb) and a sampled 48³ grid
# (Marschner–Lobb, the coherent grid caster) × resolutions 64 and 96 × triangles, quads,
# §4 refinement (2 levels), §5 merging (triangles and quads) × 1–4 ranks (mpiexec; 96 and the
# grid on 1 and 3 ranks only, to keep the run near two minutes on two cores).
#
# tests/cli/mesh_matrix.sha256 is this list as the code gives it today. --quick writes the
# subset CTest compares with it (tests/cli/golden_meshes.sh): the polynomial surfaces (sphere,
# torus, Barth) at 64 on 1 and 3 ranks, every mode. Not Marschner–Lobb and the grid sampled from
# it: their cos() comes from glibc's libm, which picks its FMA variants by processor, so their
# last bits may differ between machines. A change that alters meshes on purpose updates that
# file in the same commit, with the reason:
#
#   scripts/mesh_matrix.sh build /tmp/m && cp /tmp/m/SHA256SUMS tests/cli/mesh_matrix.sha256
set -euo pipefail
quick=0
if [ "${1:-}" = --quick ]; then
  quick=1
  shift
fi
build=${1:?usage: mesh_matrix.sh [--quick] BUILD_DIR OUT_DIR}
out=${2:?usage: mesh_matrix.sh [--quick] BUILD_DIR OUT_DIR}
bin="$build/bin/ldimesh"
[ -x "$bin" ] || { echo "mesh_matrix.sh: no $bin (build first)" >&2; exit 1; }
mkdir -p "$out"
mpi=(mpiexec --oversubscribe)
[ "$(id -u)" = 0 ] && mpi+=(--allow-run-as-root)

grid_args=()
if [ "$quick" = 0 ] && [ -x "$build/bin/ldimesh_sample_field" ]; then
  info=$("$build/bin/ldimesh_sample_field" --surface marschner-lobb --n 48 --out "$out/ml48.raw")
  grid_args=(--grid "$out/ml48.raw" --dims 48,48,48 --type float32 --iso 0.5
             --origin -1,-1,-1 --spacing "$(python3 -c "import json,sys; s=json.loads(sys.argv[1])['spacing']; print(','.join(repr(x) for x in s))" "$info")")
fi

modes=("tri:" "quad:--quad" "refine:--refine 2" "merge:--merge" "mergequad:--merge --quad")
count=0
run() {  # name ranks args...
  local name=$1 ranks=$2
  shift 2
  "${mpi[@]}" -n "$ranks" "$bin" mesh "$@" --threads 1 --out "$out/$name.ply" > /dev/null
  count=$((count + 1))
}
all_ranks=(1 2 3 4) surfaces=(sphere torus barth marschner-lobb) resolutions=(64 96)
[ "$quick" = 1 ] && all_ranks=(1 3) surfaces=(sphere torus barth) resolutions=(64)
for ranks in "${all_ranks[@]}"; do
  for surface in "${surfaces[@]}"; do
    for res in "${resolutions[@]}"; do
      [ "$res" = 96 ] && [ "$ranks" != 1 ] && [ "$ranks" != 3 ] && continue
      for mode in "${modes[@]}"; do
        # shellcheck disable=SC2086
        run "${surface}_${res}_${mode%%:*}_n${ranks}" "$ranks" --surface "$surface" --res "$res" \
          ${mode#*:}
      done
    done
  done
  if [ ${#grid_args[@]} -gt 0 ] && { [ "$ranks" = 1 ] || [ "$ranks" = 3 ]; }; then
    for mode in "${modes[@]}"; do
      # shellcheck disable=SC2086
      run "grid48_64_${mode%%:*}_n${ranks}" "$ranks" "${grid_args[@]}" --res 64 ${mode#*:}
    done
  fi
done
rm -f "$out/ml48.raw"
(cd "$out" && sha256sum ./*.ply > SHA256SUMS)
echo "mesh_matrix.sh: $count meshes in $out (SHA256SUMS)"
