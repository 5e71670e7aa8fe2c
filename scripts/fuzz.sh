#!/usr/bin/env bash
# Fuzzes the LDI fragment decoder (decode_fragment) with libFuzzer, AddressSanitizer and
# UndefinedBehaviorSanitizer for a bounded time. Builds with clang++ straight from the sources
# into build-fuzz/ (no CMake), writes a seed corpus of valid fragments into build-fuzz/corpus
# (which keeps what the fuzzer finds between runs), and exits non-zero on any finding; the
# input that triggered it is left in build-fuzz/artifacts/. The fuzzing build skips the
# checksum comparisons (FUZZING_BUILD_MODE_UNSAFE_FOR_PRODUCTION) so that mutations reach the
# zstd frame and the streams; the unit tests cover the checksums.
#
# Usage: scripts/fuzz.sh [SECONDS (default 30)] [more libFuzzer flags...]
set -euo pipefail
cd "$(dirname "$0")/.."

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

out=build-fuzz
bin=$out/fragment_decoder_fuzz
sources=(core/src/raycast/fragment.cpp core/src/raycast/ldi.cpp transport/src/fragment_codec.cpp
         tests/fuzz/fragment_decoder_fuzz.cpp)
headers=(core/include/ldimesh/core/*.hpp transport/include/ldimesh/transport/*.hpp)
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
  # FUZZING_BUILD_MODE_UNSAFE_FOR_PRODUCTION: the decoder skips its checksum comparisons here.
  "$cxx" -std=c++20 -O1 -g -fsanitize=fuzzer,address,undefined -fno-sanitize-recover=all \
    -DFUZZING_BUILD_MODE_UNSAFE_FOR_PRODUCTION -Wall -Wextra -Icore/include -Itransport/include "${sources[@]}" -lzstd -o "$bin"
fi

LDIMESH_FUZZ_WRITE_SEEDS=$out/corpus "$bin"

echo "fuzz: decode_fragment for $seconds s, corpus $out/corpus ($(ls "$out/corpus" | wc -l) inputs)"
status=0
"$bin" -max_total_time="$seconds" -timeout=10 -print_final_stats=1 \
  -artifact_prefix="$out/artifacts/" "$@" "$out/corpus" >"$out/fuzz.log" 2>&1 || status=$?
runs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$out/fuzz.log" | tail -n 1)
if [ "$status" -ne 0 ]; then
  tail -n 40 "$out/fuzz.log"
  echo "fuzz: FAILED (exit status $status) after ${runs:-?} executions; the input is in" \
       "$out/artifacts/, the whole log in $out/fuzz.log" >&2
  exit 1
fi
echo "fuzz: OK, ${runs:-?} executions in $seconds s, no crash, leak or undefined behaviour" \
     "(log: $out/fuzz.log)"
