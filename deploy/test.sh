#!/usr/bin/env bash
# Installs what is missing, builds, and runs every test.
#   deploy/test.sh             the normal build (build/)
#   deploy/test.sh --sanitize  the same tests under AddressSanitizer + UBSan (build-asan/)
set -euo pipefail
cd "$(dirname "$0")/.."
bash deploy/install-deps.sh
# The sample data (glTF files) some tests read: ../shared/testdata unless IRRADCAST_TESTDATA
# says otherwise. Where it is absent those tests skip, naming the path (tests/testdata.h).
export IRRADCAST_TESTDATA=${IRRADCAST_TESTDATA:-$(cd .. && pwd)/shared/testdata}
[ -d "$IRRADCAST_TESTDATA" ] || echo "test.sh: no sample data at $IRRADCAST_TESTDATA: the tests that read it will skip"
# After each step: wall seconds so far, then `times`: the CPU time (user system) of this shell,
# then of everything it ran so far (the compilers and tests).
step() { echo "test.sh: $1 done at ${SECONDS} s; CPU (user system) of the shell, then of its commands:"; times; }
if [ "${1:-}" = "--sanitize" ]; then
  # Built with clang (install-deps.sh installs it for the fuzzers): a file of the instrumented
  # tree compiles in 50-75 % of GCC's time, the tests run in 70 % of theirs, and clang's
  # warnings join those of the GCC tree above. A tree already configured keeps its compiler.
  CC=clang CXX=clang++ bash deploy/build.sh build-asan -DIRRADCAST_SANITIZE=ON -DIRRADCAST_BUILD_BENCH=OFF
  step "build-asan"
  export ASAN_OPTIONS=detect_leaks=1:abort_on_error=1
  export UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1
  ctest --test-dir build-asan --output-on-failure -j "$(nproc)"
  step "ctest build-asan"
else
  bash deploy/build.sh build
  step "build"
  ctest --test-dir build --output-on-failure -j "$(nproc)"
  step "ctest build"
fi
