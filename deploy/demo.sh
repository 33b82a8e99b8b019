#!/usr/bin/env bash
# Installs what is missing, builds, and runs the main job: the built-in Cornell box baked into
# lightmaps, a view composed from them, and the same view from the reference path tracer.
# Images land in out/cornell/ (view.png, reference.png, lightmaps/*.exr, report.json).
set -euo pipefail
cd "$(dirname "$0")/.."
bash deploy/install-deps.sh
bash deploy/build.sh build
out=out/cornell
./build/server/irradcast-bake --scene cornell --out "$out" --updates 8 --reference 64 "$@"
echo
echo "demo: wrote $out/view.png (composed from the lightmaps), $out/reference.png (path traced),"
echo "      $out/view.exr, $out/reference.exr, $out/lightmaps/*.exr and $out/report.json"
