#!/usr/bin/env bash
# Installs what is missing, builds, and runs every test.
#   deploy/test.sh             the normal build (build/)
#   deploy/test.sh --sanitize  the same tests under AddressSanitizer + UBSan (build-asan/)
set -euo pipefail
cd "$(dirname "$0")/.."
bash deploy/install-deps.sh
if [ "${1:-}" = "--sanitize" ]; then
  bash deploy/build.sh build-asan -DIRRADCAST_SANITIZE=ON -DIRRADCAST_BUILD_BENCH=OFF
  export ASAN_OPTIONS=detect_leaks=1:abort_on_error=1
  export UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1
  ctest --test-dir build-asan --output-on-failure -j "$(nproc)"
else
  bash deploy/build.sh build
  ctest --test-dir build --output-on-failure -j "$(nproc)"
fi
