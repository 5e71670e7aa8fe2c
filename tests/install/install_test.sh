#!/usr/bin/env bash
# `cmake --install` and find_package(ldimesh) as a user meets them: the build is installed into
# a fresh prefix; a separate project (tests/install/consumer) finds the package there and
# builds a C++ program and the C and Fortran heat mini-apps' sources against ldimesh::adaptor and
# ldimesh::fortran, with nothing of the build or source tree on its include paths; each
# program runs on 2 ranks and writes steps. The installed ldimesh-serve finds the installed
# viewer and serves the page and three.js. With WITH_DEALII=1 the deal.II mini-app is built on
# its own against the package too, as miniapps/dealii/README.md says.
#   install_test.sh SOURCE_DIR BUILD_DIR MPIEXEC
set -u
src=$1
build=$2
. "$(dirname "$0")/../lib.sh"
test_setup "$3"

prefix=$tmp/prefix
cmake --install "$build" --prefix "$prefix" >"$tmp/install.log" 2>&1 ||
  { cat "$tmp/install.log"; echo "FAIL: cmake --install"; exit 1; }
for f in include/ldimesh.h include/ldimesh/adaptor.hpp include/ldimesh/fortran/ldimesh_mod.mod \
  lib/cmake/ldimesh/ldimeshConfig.cmake lib/cmake/ldimesh/ldimeshConfigVersion.cmake \
  share/ldimesh/viewer/web/index.html share/ldimesh/viewer/web/viewer.js \
  share/ldimesh/node_modules/three/build/three.module.js \
  share/ldimesh/node_modules/three/examples/jsm/loaders/GLTFLoader.js \
  share/ldimesh/node_modules/three/examples/jsm/libs/draco/draco_decoder.js \
  bin/ldimesh bin/ldimesh-serve bin/ldimesh-fetch; do
  [ -e "$prefix/$f" ] || fail "not installed: $f"
done
echo "installed into a fresh prefix"

# The consumer project, configured and built against the installed package only.
if ! cmake -S "$src/tests/install/consumer" -B "$tmp/consumer" -DCMAKE_BUILD_TYPE=Release \
  -DCMAKE_PREFIX_PATH="$prefix" -DLDIMESH_MINIAPPS="$src/miniapps" \
  -DCMAKE_EXPORT_COMPILE_COMMANDS=ON >"$tmp/configure.log" 2>&1; then
  cat "$tmp/configure.log"
  echo "FAIL: the consumer project does not configure with find_package(ldimesh)"
  exit 1
fi
if ! cmake --build "$tmp/consumer" -j 2 >"$tmp/build.log" 2>&1; then
  tail -n 40 "$tmp/build.log"
  echo "FAIL: the consumer project does not build"
  exit 1
fi
# Its compile and link lines name the installed prefix, never the ldimesh build or source tree
# (the mini-apps' source files themselves excepted).
if grep -o -e "-I[^ ]*" -e "-isystem [^ ]*" "$tmp/consumer/compile_commands.json" |
  grep -q -e "$build" -e "$src"; then
  fail "the consumer's include paths reach into the ldimesh tree"
fi
if grep -rhoq -e "$build" "$tmp"/consumer/CMakeFiles/*.dir/link.txt; then
  fail "the consumer links from the ldimesh build tree"
fi
grep -q "$prefix" "$tmp"/consumer/CMakeFiles/consumer-cxx.dir/link.txt ||
  fail "consumer-cxx does not link the installed libraries"
echo "consumer project built against find_package(ldimesh)"

# Each program on 2 ranks, steps written to a folder (server off).
options() { RESOLUTION=64 writing_options "$@"; }
steps_in() { find "$1" -name 'step_*.glb' -size +0 2>/dev/null | wc -l; }
opts=$(options "$tmp/cxx" ', "isovalues": [0]')
timeout 120 "${mpirun[@]}" -n 2 "$tmp/consumer/consumer-cxx" "$(cat "$opts")" 3 >"$tmp/cxx.log" 2>&1 ||
  { cat "$tmp/cxx.log"; fail "consumer-cxx on 2 ranks"; }
[ "$(steps_in "$tmp/cxx")" -ge 1 ] || fail "consumer-cxx wrote no step"
for lang in c fortran; do
  opts=$(options "$tmp/$lang")
  timeout 120 "${mpirun[@]}" -n 2 "$tmp/consumer/consumer-$lang" --size 24 --steps 3 --substeps 2 \
    --options "$opts" >"$tmp/$lang.log" 2>&1 || { cat "$tmp/$lang.log"; fail "consumer-$lang on 2 ranks"; }
  [ "$(steps_in "$tmp/$lang")" -ge 1 ] || fail "consumer-$lang wrote no step"
done
echo "C++, C and Fortran consumers ran on 2 ranks and wrote steps"

# The deal.II mini-app as its README builds it: on its own, find_package(deal.II) and
# find_package(ldimesh) from the prefix (where deal.II is installed).
if [ "${WITH_DEALII:-0}" = 1 ]; then
  if cmake -S "$src/miniapps/dealii" -B "$tmp/dealii" -DCMAKE_BUILD_TYPE=Release \
    -DCMAKE_PREFIX_PATH="$prefix" >"$tmp/dealii-configure.log" 2>&1 &&
    cmake --build "$tmp/dealii" -j 2 >"$tmp/dealii-build.log" 2>&1; then
    grep -q "$prefix" "$tmp"/dealii/CMakeFiles/ldimesh-dealii.dir/link.txt ||
      fail "the stand-alone deal.II mini-app does not link the installed libraries"
    opts=$(options "$tmp/dealii-steps")
    timeout 300 "${mpirun[@]}" -n 2 "$tmp/dealii/ldimesh-dealii" --refinements 0 --steps 2 \
      --output-every 2 --options "$opts" >"$tmp/dealii.log" 2>&1 ||
      { cat "$tmp/dealii.log"; fail "the stand-alone deal.II mini-app on 2 ranks"; }
    [ "$(steps_in "$tmp/dealii-steps")" -ge 1 ] || fail "the stand-alone deal.II mini-app wrote no step"
    echo "the deal.II mini-app built on its own against the installed package, and ran"
  else
    tail -n 30 "$tmp/dealii-configure.log" "$tmp/dealii-build.log"
    fail "the deal.II mini-app does not build on its own against the installed package"
  fi
fi

# The installed server finds the installed viewer files itself (beside its bin/).
"$prefix/bin/ldimesh-serve" --dir "$tmp/cxx" --port 0 >"$tmp/serve.out" 2>"$tmp/serve.err" &
server_pid=$!
url=$(wait_for_url "$tmp/serve.out")
if [ -z "$url" ]; then
  cat "$tmp/serve.err"
  fail "the installed ldimesh-serve printed no URL"
else
  base=${url%%\?*}
  for path in "" vendor/three/build/three.module.js vendor/three/examples/jsm/loaders/GLTFLoader.js; do
    code=$(python3 -c 'import sys, urllib.request
try: print(urllib.request.urlopen(sys.argv[1], timeout=10).status)
except Exception as e: print(getattr(e, "code", e))' "$base$path")
    [ "$code" = 200 ] || fail "the installed server answers $code for /$path"
  done
  grep -q "warning" "$tmp/serve.err" && { cat "$tmp/serve.err"; fail "the installed server warned"; }
  echo "the installed ldimesh-serve serves the installed viewer and three.js"
fi

finish
