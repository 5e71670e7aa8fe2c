#!/usr/bin/env bash
# Configures (Release) and builds ldimesh into build/, binaries in build/bin/.
# Usage: scripts/build.sh [cmake --build arguments, e.g. --target ldimesh]
set -euo pipefail
cd "$(dirname "$0")/.."
cmake -S . -B build -DCMAKE_BUILD_TYPE=Release -DLDIMESH_BUILD_TESTS=ON -DLDIMESH_BUILD_BENCH=ON >/dev/null
cmake --build build -j"$(nproc)" "$@"
