#!/usr/bin/env bash
# Clean layers, as a user meets them:
# 1. a C++ program that includes only the adaptor's header (ldimesh/adaptor.hpp), as C++20 and
#    as C++17, and a C one that includes ldimesh.h, compile without Embree's or TBB's headers
#    (none is even read);
# 2. a client-only configuration (LDIMESH_CLIENT_ONLY, with MPI, Embree, TBB and OpenMesh
#    unfindable) builds ldimesh-fetch, whose link line names none of them, and it runs;
# 3. the folders' #include graph (core's stages, transport, adaptor, cli, viewer, miniapps) has no
#    cycle (folder_layers.py).
# Usage: layers_test.sh SOURCE_DIR CXX CC "MPI_INCLUDE_DIRS" [BUILD_DIR]
set -euo pipefail
src=$1 cxx=$2 cc=$3 mpi_includes=$4
work=${5:-$(mktemp -d)}
mkdir -p "$work"
fail() { echo "FAIL: $*" >&2; exit 1; }

includes=(-I"$src/adaptor/include" -I"$src/core/include")
for d in $mpi_includes; do includes+=(-I"$d"); done

cat >"$work/solver.cpp" <<'CPP'
#include "ldimesh/adaptor.hpp"
int main(int argc, char** argv) {
  MPI_Init(&argc, &argv);
  std::unique_ptr<ldimesh::Adaptor> adaptor;
  ldimesh::Status s = ldimesh::Adaptor::create(MPI_COMM_WORLD, R"({"log": false})", adaptor);
  ldimesh::GridBlock block;
  if (s && adaptor) s = adaptor->add_grid_block(block);
  MPI_Finalize();
  return s ? 0 : 1;
}
CPP
cat >"$work/solver.c" <<'C'
#include "ldimesh.h"
int main(void) { ldimesh_grid_block b; ldimesh_grid_block_init(&b); return 0; }
C
"$cxx" -std=c++20 -fsyntax-only "${includes[@]}" "$work/solver.cpp" || fail "adaptor.hpp does not compile alone"
# Solvers' codes are often C++17 (deal.II 9.4 compiles its users as C++17).
"$cxx" -std=c++17 -pedantic -fsyntax-only "${includes[@]}" "$work/solver.cpp" ||
  fail "adaptor.hpp does not compile as C++17"
"$cc" -fsyntax-only "${includes[@]}" "$work/solver.c" || fail "ldimesh.h does not compile alone"
for f in solver.cpp solver.c; do
  comp=$cxx; flags=(-std=c++20)
  [ "$f" = solver.c ] && comp=$cc && flags=()
  deps=$("$comp" "${flags[@]}" -M "${includes[@]}" "$work/$f")
  if grep -Eo '[^ ]*(embree|/tbb/|oneapi)[^ ]*' <<<"$deps"; then
    fail "$f reads the headers above"
  fi
done
echo "headers: adaptor.hpp and ldimesh.h read no Embree or TBB header"

cmake -S "$src" -B "$work/client" -DLDIMESH_CLIENT_ONLY=ON -DCMAKE_DISABLE_FIND_PACKAGE_MPI=ON \
  -DCMAKE_DISABLE_FIND_PACKAGE_embree=ON -DCMAKE_DISABLE_FIND_PACKAGE_TBB=ON \
  -DCMAKE_DISABLE_FIND_PACKAGE_OpenMesh=ON >"$work/configure.log" 2>&1 ||
  { tail -20 "$work/configure.log"; fail "the client-only configuration fails"; }
cmake --build "$work/client" --target ldimesh-fetch -j2 >"$work/build.log" 2>&1 ||
  { tail -20 "$work/build.log"; fail "ldimesh-fetch does not build client-only"; }
link=$(cat "$work/client/viewer/CMakeFiles/ldimesh-fetch.dir/link.txt")
# Library names only (-lNAME, libNAME…): a path may hold "mpi" (as in "compile") by chance.
if grep -Eio '(-l|lib)(mpi|embree|tbb|openmesh)[^ ]*' <<<"$link"; then
  fail "ldimesh-fetch's link line: $link"
fi
"$work/client/bin/ldimesh-fetch" --help >/dev/null || fail "the client-only ldimesh-fetch does not run"
echo "client only: ldimesh-fetch built and linked without MPI, Embree, TBB, OpenMesh"
python3 "$(dirname "$0")/folder_layers.py" "$src" || fail "an include cycle between folders"
