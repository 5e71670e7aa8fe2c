#!/usr/bin/env bash
# Installs every Debian package ldimesh needs to build and test. Idempotent: when everything is
# installed already it only asks dpkg and returns at once (no apt-get update).
set -euo pipefail

packages=(
  cmake make g++ gfortran git   # build (gfortran: the Fortran module and mini-app)
  libembree-dev                 # ray casting (Embree 3)
  libglm-dev                    # vector math
  libtbb-dev                    # threads
  libcli11-dev                  # command line
  nlohmann-json3-dev            # JSON summaries
  libcpp-httplib-dev pkg-config # the job's HTTP server (found through pkg-config)
  libzstd-dev                   # fragment compression
  libopenmesh-dev               # half-edge meshes for §5 merging
  libdraco-dev libeigen3-dev draco  # GLB meshes (Draco glTF encoder; draco_decoder CLI)
  libopenmpi-dev openmpi-bin    # the distributed pipeline
  libgtest-dev                  # tests
  libdeal.ii-dev                # the deal.II mini-app (miniapps/dealii: a real FEM library)
  libgmsh-dev                   # gmsh's library: the tests' oracle for gmsh's node orders
  libvtk9-dev                   # ldimesh mesh --vtu: VTK's XML readers
  python3-vtk9 python3-numpy    # VTK writes and reads the tests' high-order VTU files
  clang libclang-rt-14-dev      # libFuzzer target for the fragment decoder
  clang-format                  # formatting (.clang-format)
  python3 curl                  # test data generation and HTTP checks in tests/cli
  chromium                      # browser test of the viewer (driven by playwright-core)
)
# Node.js and npm for the viewer's three.js and the browser test driver, unless a node is there.
if ! command -v node >/dev/null 2>&1 || ! command -v npm >/dev/null 2>&1; then
  packages+=(nodejs npm)
fi

# The viewer's JavaScript dependencies (npm registry), whenever the lock file changed.
install_node_modules() {
  cd "$(dirname "$0")/.."
  if [ ! -f node_modules/.package-lock.json ] || [ package-lock.json -nt node_modules/.package-lock.json ]; then
    echo "setup: npm ci (three, playwright-core, gltf-validator)"
    npm ci --no-audit --no-fund --loglevel=error
  fi
}

missing=()
for p in "${packages[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done
if [ ${#missing[@]} -eq 0 ]; then
  install_node_modules
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
install_node_modules
