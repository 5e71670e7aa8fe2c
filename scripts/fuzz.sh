#!/usr/bin/env bash
# Fuzzes one decoder of untrusted input with libFuzzer, AddressSanitizer and
# UndefinedBehaviorSanitizer for a bounded time. Targets (tests/fuzz/*_fuzz.cpp):
#   fragment  decode_fragment: LDI fragments between ranks
#   ply       parse_ply: meshes given to `ldimesh distance`
#   glb       decode_glb: what ldimesh-fetch and `ldimesh distance` read from a server or disk
#   options   parse_adaptor_options: the adaptor's JSON options document
#   http      the job's HTTP server: raw requests over a loopback connection
#   raw       read_raw_volume: the volume files `ldimesh mesh --grid` reads
#   vtu       read_vtu: the VTK XML files `ldimesh mesh --vtu` reads (VTK's own parser)
# Builds with clang++ straight from the sources into build-fuzz/TARGET/ (no CMake), writes a
# seed corpus of valid inputs (the target's own encoder's output and hand-written files) into
# build-fuzz/TARGET/corpus (which keeps what the fuzzer finds between runs), and exits non-zero
# on any finding; the input that triggered it is left in build-fuzz/TARGET/artifacts/. The
# fragment build skips the checksum comparisons (FUZZING_BUILD_MODE_UNSAFE_FOR_PRODUCTION) so
# that mutations reach the zstd frame and the streams; the unit tests cover the checksums.
#
# Usage: scripts/fuzz.sh TARGET [SECONDS (default 30)] [more libFuzzer flags...]
set -euo pipefail
cd "$(dirname "$0")/.."

target=${1:-}
shift || true
case $target in
  fragment)
    name=fragment_decoder_fuzz
    sources=(core/src/raycast/fragment.cpp core/src/raycast/ldi.cpp transport/reduction/src/fragment_codec.cpp)
    libs=(-lzstd) ;;
  ply)
    name=ply_reader_fuzz
    sources=(core/src/io/mesh_io.cpp core/src/base/mesh.cpp core/src/base/status.cpp)
    libs=() ;;
  glb)
    name=glb_decoder_fuzz
    # Debian's Draco 1.5.5 can spend up to ≈ 15 s on a hostile 1.3 KB stream (an unbounded
    # count in its texture-coordinate predictor: docs/reliability.md, an open finding). That is
    # bounded (2^31 steps), not a hang: the per-input limit sits above it, so that the target
    # goes on finding crashes, leaks and undefined behaviour; the OK line reports the slowest
    # input, and a real hang still stops the run.
    timeout=30
    sources=(transport/delivery/src/glb.cpp transport/delivery/src/glb_decode.cpp
             transport/delivery/src/glb_format.cpp
             core/src/base/mesh.cpp core/src/base/status.cpp)
    libs=(-I/usr/include/eigen3 -ldraco) ;;
  http)
    name=http_request_fuzz
    sources=(transport/delivery/src/http_server.cpp transport/delivery/src/snapshot_store.cpp
             core/src/base/status.cpp)
    # Debian's cpp-httplib is a library built with these definitions (class layouts follow them).
    pkg-config --exists cpp-httplib || { echo "fuzz: cpp-httplib not found (scripts/setup.sh)" >&2; exit 1; }
    libs=($(pkg-config --cflags --libs cpp-httplib) -DLDIMESH_SOURCE_DIR=\"/nonexistent\"
          -DLDIMESH_BINARY_DIR=\"/nonexistent\" -DLDIMESH_INSTALL_DATA_DIR=\"/nonexistent\") ;;
  raw)
    name=raw_volume_fuzz
    sources=(core/src/io/raw_volume.cpp core/src/base/status.cpp)
    libs=() ;;
  vtu)
    name=vtu_reader_fuzz
    # VTK 9 from Debian (libvtk9-dev: 9.1 on Debian 12): its XML reader is the parser; not
    # instrumented.
    vtk_include=$(ls -d /usr/include/vtk-9.* 2>/dev/null | sort -V | tail -n 1 || true)
    [ -n "$vtk_include" ] || { echo "fuzz: VTK 9 headers not found (scripts/setup.sh)" >&2; exit 1; }
    sources=(core/src/io/vtu.cpp core/src/base/status.cpp)
    libs=(-I"$vtk_include")
    for m in IOXML IOXMLParser IOCore CommonExecutionModel CommonDataModel CommonCore \
             CommonMisc CommonSystem CommonMath CommonTransforms sys; do
      libs+=(-lvtk$m-"${vtk_include##*/vtk-}")
    done
    export LSAN_OPTIONS="suppressions=$PWD/scripts/sanitize.supp.d/vtk-lsan.supp${LSAN_OPTIONS:+:$LSAN_OPTIONS}"
    # VTK allocates, and fills, arrays at sizes the file gives before it reads them, some from
    # values inside the data (the connectivity's size from the offsets): a mutated byte asks for
    # gigabytes (docs/reliability.md, an open finding in VTK). A real run's malloc refuses what
    # the machine cannot give and VTK reports it (read_vtu turns VTK's std::bad_alloc into an
    # error too): here too (no libFuzzer malloc limit; ASan returns null above its 1 TiB
    # maximum). What VTK touches still counts against the RSS limit: libFuzzer's fork mode goes
    # on past inputs over the memory or time limit (kept in artifacts/, counted in the OK line,
    # not triaged: they may be VTK's or ours). It goes on past crashes too: VTK 9.1 crashes on
    # some damaged files read_vtu cannot check from outside (the connectivity's size from the
    # offsets' last value: a failed allocation it then frees wrongly), which our tools survive
    # by reading in a child process (read_vtu_isolated). Each crash input is run again alone,
    # with the same limits, and triaged by its report below: VTK's own crash is a memory error
    # or a deadly signal whose stack is in VTK called from one of read_vtu's two VTK passes
    # (vtk_information_pass, vtk_data_pass in core/src/io/vtu.cpp); it is counted and kept as
    # vtk-crash-*. Anything else is a finding: a crash in our code or in VTK called from
    # anywhere else, one that does not happen again alone, a memory or time limit on the rerun,
    # a leak (VTK's are suppressed) or a failed check.
    # -detect_leaks=0 turns off libFuzzer's leak check after each input whose mallocs exceed
    # its frees (every input here, in VTK's reader: two thirds of the run's time); LeakSanitizer
    # still checks each job at its exit, and a leak there fails the run.
    # FUZZ_JOBS: fork jobs at once (default 1).
    jobs=${FUZZ_JOBS:-1}
    [[ $jobs =~ ^[1-9][0-9]*$ ]] || { echo "fuzz: FUZZ_JOBS must be a positive whole number, not '$jobs'" >&2; exit 2; }
    export ASAN_OPTIONS="allocator_may_return_null=1${ASAN_OPTIONS:+:$ASAN_OPTIONS}"
    flags=(-malloc_limit_mb=100000000 -fork="$jobs" -ignore_ooms=1 -ignore_crashes=1 -detect_leaks=0)
    triage_vtk=1 ;;
  options)
    name=options_fuzz
    sources=(adaptor/src/options.cpp core/src/base/status.cpp)
    libs=() ;;
  *)
    echo "fuzz: unknown target '$target' (one of: fragment, ply, glb, options, http, raw, vtu)" >&2
    exit 2 ;;
esac
seconds=${1:-30}
shift || true
if ! [[ $seconds =~ ^[0-9]+$ ]] || [ "$seconds" -lt 1 ]; then
  echo "fuzz: the run time must be a whole number of seconds, not '$seconds'" >&2
  exit 2
fi
cxx=${FUZZ_CXX:-clang++}
if ! command -v "$cxx" >/dev/null 2>&1; then
  echo "fuzz: $cxx not found (scripts/setup.sh installs clang and libclang-rt-14-dev)" >&2
  exit 1
fi

out=build-fuzz/$target
bin=$out/$name
sources+=(tests/fuzz/$name.cpp)
headers=(core/include/ldimesh/core/*.hpp core/include/ldimesh/core/*/*.hpp
         transport/*/include/ldimesh/transport/*.hpp adaptor/src/*.hpp)
mkdir -p "$out/corpus" "$out/artifacts"

# Rebuild when the binary is missing or older than any source or header.
stale=0
if [ ! -x "$bin" ]; then stale=1; else
  for f in "${sources[@]}" "${headers[@]}" "$0"; do
    if [ "$f" -nt "$bin" ]; then stale=1; break; fi
  done
fi
if [ "$stale" -eq 1 ]; then
  echo "fuzz: building $bin with $cxx (ASan, UBSan, libFuzzer)"
  # FUZZING_BUILD_MODE_UNSAFE_FOR_PRODUCTION: the fragment decoder skips its checksums here.
  "$cxx" -std=c++20 -O1 -g -fsanitize=fuzzer,address,undefined -fno-sanitize-recover=all \
    -DFUZZING_BUILD_MODE_UNSAFE_FOR_PRODUCTION -Wall -Wextra -Icore/include \
    -Itransport/reduction/include -Itransport/delivery/include \
    "${sources[@]}" "${libs[@]}" -o "$bin"
fi

LDIMESH_FUZZ_WRITE_SEEDS=$out/corpus "$bin"

echo "fuzz: $target for $seconds s, corpus $out/corpus ($(ls "$out/corpus" | wc -l) inputs)"
status=0
marker=$(mktemp "$out/.started.XXXXXX")
"$bin" -max_total_time="$seconds" -timeout="${timeout:-10}" -print_final_stats=1 \
  -artifact_prefix="$out/artifacts/" ${flags[@]+"${flags[@]}"} "$@" "$out/corpus" >"$out/fuzz.log" 2>&1 ||
  status=$?
runs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$out/fuzz.log" | tail -n 1)
# Fork mode (vtu) prints no final stats: its last status line counts the executions and the
# inputs over the memory and time limits and the crashes. It exits with the last job's status,
# which is a limit's (70 time, 71 memory) when it went on past one: only a crash (a leak,
# undefined behaviour, a failed check) or another status is a finding there.
limits=""
if [[ " ${flags[*]-} " == *" -fork="* ]]; then
  last=$(grep -E '^#[0-9]+: cov:.* oom/timeout/crash: [0-9]+/[0-9]+/[0-9]+' "$out/fuzz.log" |
    tail -n 1 || true)
  runs=$(sed -n 's/^#\([0-9]*\): cov:.*/\1/p' <<<"$last")
  counts=$(sed -n 's/.* oom\/timeout\/crash: \([0-9]*\)\/\([0-9]*\)\/\([0-9]*\).*/\1 \2 \3/p' <<<"$last")
  read -r ooms timeouts crashes <<<"${counts:-0 0 0}"
  [ "$ooms" = 0 ] && [ "$timeouts" = 0 ] ||
    limits="$ooms over the memory limit, $timeouts over the time limit (not triaged)"
  if [ "${crashes:-0}" = 0 ] && { [ "$status" -eq 70 ] || [ "$status" -eq 71 ]; }; then status=0; fi
  # Its jobs' crashes are not always counted there (one on a seed was not): a crash or leak
  # input written during this run is a finding whatever the status says, unless (vtu) it is
  # VTK's own crash, run again alone.
  vtk_crashes=0
  findings=0
  rerun=$(mktemp -d)
  while IFS= read -r input; do
    file=${input##*/}
    if [ "${triage_vtk:-0}" = 1 ] && [[ $file == crash-* ]]; then
      if report=$("$bin" -malloc_limit_mb=100000000 -timeout="${timeout:-10}" \
          -artifact_prefix="$rerun/" "$input" 2>&1); then
        echo "fuzz: $file does not crash when run alone" >&2
        findings=1
        continue
      fi
      # The crash's stack: VTK's frames, then the first of ours (a source file of this
      # repository), which must be one of read_vtu's VTK passes.
      verdict=ours
      if grep -q -E 'ERROR: AddressSanitizer|deadly signal' <<<"$report" &&
         ! grep -q -E 'out-of-memory|LeakSanitizer|ERROR: libFuzzer: timeout' <<<"$report"; then
        in_vtk=0
        while IFS= read -r frame; do
          [[ $frame =~ ^\ +#[0-9]+\  ]] || continue
          if [[ $frame == *libvtk* ]]; then in_vtk=1; continue; fi
          if [[ $frame == *" $PWD/"* ]]; then
            if [ "$in_vtk" = 1 ] && [[ $frame == *vtk_information_pass* || $frame == *vtk_data_pass* ]]; then
              verdict=vtk
            fi
            break
          fi
        done <<<"$report"
      fi
      if [ "$verdict" = vtk ]; then
        mv "$input" "$out/artifacts/vtk-$file"
        vtk_crashes=$((vtk_crashes + 1))
        continue
      fi
      grep -E -m 6 'ERROR|runtime error|^ +#[0-9]+ ' <<<"$report" >&2 || true
    fi
    echo "fuzz: finding: $input" >&2
    findings=1
  done < <(find "$out/artifacts" -newer "$marker" \( -name 'crash-*' -o -name 'leak-*' \))
  rm -rf "$rerun"
  # A job's leak found at its exit is reported in the log (with -ignore_crashes, maybe nowhere
  # else).
  if grep -q 'ERROR: LeakSanitizer' "$out/fuzz.log"; then
    echo "fuzz: LeakSanitizer reported a leak (in $out/fuzz.log)" >&2
    findings=1
  fi
  if [ "$findings" = 1 ]; then
    status=1
  elif [ "$status" -ne 0 ] && [ "$vtk_crashes" -gt 0 ] && [ "${crashes:-0}" -le "$vtk_crashes" ]; then
    status=0  # the last job's status was one of VTK's crashes, each triaged above
  fi
  [ "$vtk_crashes" = 0 ] ||
    limits="${limits:+$limits, }$vtk_crashes crashing inside VTK (kept as $out/artifacts/vtk-crash-*)"
fi
rm -f "$marker"
if [ "$status" -ne 0 ]; then
  tail -n 40 "$out/fuzz.log"
  echo "fuzz: FAILED (exit status $status) after ${runs:-?} executions; the input is in" \
       "$out/artifacts/, the whole log in $out/fuzz.log" >&2
  exit 1
fi
slowest=$(sed -n 's/^stat::slowest_unit_time_sec: *//p' "$out/fuzz.log" | tail -n 1)
[ -z "$limits" ] ||
  echo "fuzz: went on past inputs: $limits; in $out/artifacts/ (docs/reliability.md)"
echo "fuzz: OK, ${runs:-?} executions in $seconds s, no crash, leak or undefined behaviour${triage_vtk:+ in our code}" \
     "(slowest input ${slowest:-?} s; log: $out/fuzz.log)"
