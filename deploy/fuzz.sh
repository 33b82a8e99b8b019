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
# One target; its output goes to its log and its exit status to <log>.status.
fuzz_one() {
  local t=$1 corpus="$dir/corpus/$1" log="$dir/artifacts/$1.log" status=0
  local dict=()
  mkdir -p "$corpus"
  if [ "$t" = fuzz_frame_decoder ]; then dict=(-dict=tests/fuzz/frame.dict); fi
  "$dir/tests/fuzz/$t" "$corpus" "${dict[@]}" -max_total_time="$seconds" -max_len=4096 \
    -rss_limit_mb=2048 -timeout=10 -print_final_stats=1 -artifact_prefix="$dir/artifacts/$t-" \
    >"$log" 2>&1 || status=$?
  echo "$status" >"$log.status"
}
# The targets run side by side, one per core (each libFuzzer process uses one): the same time
# for each target, in three rounds instead of five on CI's two cores (measured: 242 -> 175 s for
# the whole step, build included).
jobs_max=$(nproc)
for t in "${targets[@]}"; do
  while [ "$(jobs -rp | wc -l)" -ge "$jobs_max" ]; do wait -n || true; done
  echo "fuzz: $t for ${seconds}s"
  fuzz_one "$t" &
done
wait
failed=0
for t in "${targets[@]}"; do
  log="$dir/artifacts/$t.log"
  status=$(cat "$log.status" 2>/dev/null || echo missing)
  echo "fuzz: $t"
  # The summary without libFuzzer's progress lines; the whole output stays in the log.
  grep -v -E '^#[0-9]+' "$log" | tail -n 60 || true
  grep -E '^#[0-9]+.*DONE' "$log" || true
  if [ "$status" != 0 ]; then
    echo "fuzz: $t FAILED (exit $status); full log: $log"
    failed=1
  fi
done
[ "$failed" = 0 ] || exit 1
echo "fuzz: all targets ran clean"
