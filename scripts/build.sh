#!/usr/bin/env bash
# Configures (Release) and builds ldimesh into build/, binaries in build/bin/.
# Usage: scripts/build.sh [cmake --build arguments, e.g. --target ldimesh]
# LDIMESH_REQUIRE_ALL=ON (scripts/test sets it): a missing VTK or deal.II fails the configure
# instead of leaving their parts and tests out.
set -euo pipefail
cd "$(dirname "$0")/.."
cmake -S . -B build -DCMAKE_BUILD_TYPE=Release -DLDIMESH_BUILD_TESTS=ON -DLDIMESH_BUILD_BENCH=ON \
  -DLDIMESH_REQUIRE_ALL="${LDIMESH_REQUIRE_ALL:-OFF}" >/dev/null
cmake --build build -j"$(nproc)" "$@"
