#!/usr/bin/env bash
# Configures and builds irradcast. Usage: deploy/build.sh [BUILD_DIR] [extra cmake args...]
set -euo pipefail
cd "$(dirname "$0")/.."
dir=${1:-build}
shift || true
generator=()
if command -v ninja >/dev/null 2>&1; then generator=(-G Ninja); fi
# ccache where the machine has one (not installed by install-deps.sh): rebuilds of the same
# sources in another tree (CI's clean clone, the sanitizer and Release trees) come from the cache.
if command -v ccache >/dev/null 2>&1; then
  generator+=(-DCMAKE_C_COMPILER_LAUNCHER=ccache -DCMAKE_CXX_COMPILER_LAUNCHER=ccache)
fi
if [ ! -f "$dir/CMakeCache.txt" ]; then
  # IRRADCAST_BUILD_TYPE picks a fresh tree's build type (CI builds its test tree as Release,
  # so that one tree is both what the tests run and the -O3 build that is bundled).
  cmake -S . -B "$dir" "${generator[@]}" -DCMAKE_BUILD_TYPE="${IRRADCAST_BUILD_TYPE:-RelWithDebInfo}" "$@"
else
  cmake -S . -B "$dir" "$@" >/dev/null
fi
cmake --build "$dir" --parallel "$(nproc)"
