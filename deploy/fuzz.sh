#!/usr/bin/env bash
# Builds the libFuzzer targets with clang (build-fuzz/) and runs each one briefly: the CI step for
# the wire protocol's decoders. Exits non-zero if a fuzzer finds a crash, leak, UB or a broken
# property (the reproducer is left in build-fuzz/artifacts/).
#   deploy/fuzz.sh            every target for FUZZ_SECONDS (default 30) each
#   FUZZ_SECONDS=300 deploy/fuzz.sh
# Corpora persist in build-fuzz/corpus/<target>/ between runs.
set -euo pipefail
cd "$(dirname "$0")/.."
seconds=${FUZZ_SECONDS:-30}
dir=build-fuzz
generator=()
if command -v ninja >/dev/null 2>&1; then generator=(-G Ninja); fi
if [ ! -f "$dir/CMakeCache.txt" ]; then
  # Coverage instrumentation and the sanitizers on every library the fuzzers link, so that
  # libFuzzer sees the decoder's branches and ASan sees its memory accesses.
  CC=clang CXX=clang++ cmake -S . -B "$dir" "${generator[@]}" -DCMAKE_BUILD_TYPE=RelWithDebInfo \
    -DIRRADCAST_FUZZ=ON -DIRRADCAST_BUILD_TESTS=OFF -DIRRADCAST_BUILD_BENCH=OFF \
    -DCMAKE_C_FLAGS="-fsanitize=fuzzer-no-link,address,undefined -fno-omit-frame-pointer" \
    -DCMAKE_CXX_FLAGS="-fsanitize=fuzzer-no-link,address,undefined -fno-omit-frame-pointer"
fi
targets=(fuzz_frame_decoder fuzz_tile_decoder fuzz_probe_volume fuzz_websocket fuzz_client_address)
cmake --build "$dir" --parallel "$(nproc)" --target "${targets[@]}"
echo "fuzz.sh: build done at ${SECONDS} s; CPU (user system) of the shell, then of its commands:"; times

export ASAN_OPTIONS=detect_leaks=1:abort_on_error=1
export UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1
mkdir -p "$dir/artifacts"
for t in "${targets[@]}"; do
  corpus="$dir/corpus/$t"
  mkdir -p "$corpus"
  dict=()
  if [ "$t" = fuzz_frame_decoder ]; then dict=(-dict=tests/fuzz/frame.dict); fi
  echo "fuzz: $t for ${seconds}s"
  log="$dir/artifacts/$t.log"
  status=0
  "$dir/tests/fuzz/$t" "$corpus" "${dict[@]}" -max_total_time="$seconds" -max_len=4096 \
    -rss_limit_mb=2048 -timeout=10 -print_final_stats=1 -artifact_prefix="$dir/artifacts/$t-" \
    >"$log" 2>&1 || status=$?
  # The summary without libFuzzer's progress lines; the whole output stays in the log.
  grep -v -E '^#[0-9]+' "$log" | tail -n 60 || true
  grep -E '^#[0-9]+.*DONE' "$log" || true
  if [ "$status" -ne 0 ]; then
    echo "fuzz: $t FAILED (exit $status); full log: $log"
    exit 1
  fi
done
echo "fuzz: all targets ran clean"
