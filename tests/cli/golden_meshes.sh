#!/usr/bin/env bash
# Golden meshes: the CLI's meshes on the quick subset of scripts/mesh_matrix.sh (the polynomial
# surfaces at 64 on 1 and 3 ranks, triangles, quads, §4 refinement, §5 merging) are byte for byte
# the ones tests/cli/mesh_matrix.sha256 lists. A change that alters meshes on purpose updates
# that file in the same commit, with the reason (scripts/mesh_matrix.sh says how).
# Usage: golden_meshes.sh SOURCE_DIR BUILD_DIR
set -euo pipefail
src=${1:?usage: golden_meshes.sh SOURCE_DIR BUILD_DIR}
build=${2:?usage: golden_meshes.sh SOURCE_DIR BUILD_DIR}
golden="$src/tests/cli/mesh_matrix.sha256"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
fail() { echo "FAIL: $*" >&2; exit 1; }

[ -s "$golden" ] || fail "no $golden"
"$src/scripts/mesh_matrix.sh" --quick "$build" "$tmp" || fail "scripts/mesh_matrix.sh --quick"
made=$(wc -l < "$tmp/SHA256SUMS")
[ "$made" -ge 30 ] || fail "the quick matrix wrote $made meshes, 30 expected"
differ=0 same=0
while read -r hash name; do
  want=$(awk -v n="$name" '$2 == n { print $1 }' "$golden")
  if [ -z "$want" ]; then
    echo "  $name: not in tests/cli/mesh_matrix.sha256"
    differ=$((differ + 1))
  elif [ "$want" != "$hash" ]; then
    echo "  $name: $hash, golden $want"
    differ=$((differ + 1))
  else
    same=$((same + 1))
  fi
done < "$tmp/SHA256SUMS"
echo "golden meshes: $same of $made byte for byte as tests/cli/mesh_matrix.sha256"
[ "$differ" = 0 ] || fail "$differ meshes differ from the golden ones (an intended change updates tests/cli/mesh_matrix.sha256 with its reason: scripts/mesh_matrix.sh)"
echo "PASS"
