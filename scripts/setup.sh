#!/usr/bin/env bash
# Installs every Debian package ldimesh needs to build and test. Idempotent: when everything is
# installed already it only asks dpkg and returns at once (no apt-get update).
set -euo pipefail

packages=(
  cmake make g++ git            # build
  libembree-dev                 # ray casting (Embree 3)
  libglm-dev                    # vector math
  libtbb-dev                    # threads
  libcli11-dev                  # command line
  nlohmann-json3-dev            # JSON summaries
  libzstd-dev                   # fragment compression
  libopenmpi-dev openmpi-bin    # the distributed pipeline
  libgtest-dev                  # tests
  clang libclang-rt-14-dev      # libFuzzer target for the fragment decoder
  clang-format                  # formatting (.clang-format)
  python3                       # test data generation in tests/cli
)

missing=()
for p in "${packages[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done
if [ ${#missing[@]} -eq 0 ]; then
  exit 0
fi

echo "setup: installing ${missing[*]}"
sudo=()
if [ "$(id -u)" -ne 0 ]; then
  if command -v sudo >/dev/null 2>&1; then sudo=(sudo); else
    echo "setup: need root (or sudo) to install: ${missing[*]}" >&2
    exit 1
  fi
fi
export DEBIAN_FRONTEND=noninteractive
"${sudo[@]}" apt-get update -qq
"${sudo[@]}" apt-get install -y -qq --no-install-recommends "${missing[@]}"
