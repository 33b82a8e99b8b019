#!/usr/bin/env bash
# Installs every Debian 12 package irradcast needs to build, run and test. Idempotent and
# non-interactive: when everything is present it changes nothing and does not touch the network.
set -euo pipefail

PACKAGES=(
  # toolchain
  build-essential cmake ninja-build pkg-config git
  # libraries
  libembree-dev libtbb-dev libopenexr-dev libtinygltf-dev libstb-dev nlohmann-json3-dev
  libglm-dev libasio-dev libssl-dev libprotobuf-dev protobuf-compiler libzstd-dev libcli11-dev
  # Vulkan compute backend: loader, lavapipe, shader compiler, validation layers
  libvulkan-dev mesa-vulkan-drivers glslang-tools glslang-dev spirv-tools vulkan-validationlayers
  # distribution over machines (NATS with JetStream), HTTP/WebSocket for the browser viewer
  # (websocketpp, docs/PROTOCOL.md#websocket; node builds the page: web/build.mjs)
  nats-server libnats-dev libwebsocketpp-dev
  # relocatable bundle (deploy/bundle.sh)
  patchelf
  # the deployment files' offline check (deploy/check-manifests.sh): `docker-compose config`
  docker-compose
  # tests and benchmarks (Chromium: the browser viewer's tests)
  chromium
  libgtest-dev libgmock-dev libbenchmark-dev
  # a real reverse proxy in front of the server (tests/scenario/test_trusted_proxy.cpp)
  haproxy
  # libFuzzer targets (deploy/fuzz.sh)
  clang libclang-rt-14-dev
)

missing=()
for p in "${PACKAGES[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done

# node and npm (Debian 12: node 18) for the browser viewer's build (web/build.mjs) and the
# manifests' check (deploy/k8s-check), unless a node is installed already.
command -v node >/dev/null 2>&1 || missing+=(nodejs)
command -v npm >/dev/null 2>&1 || missing+=(npm)

if [ ${#missing[@]} -eq 0 ]; then
  echo "install-deps: all ${#PACKAGES[@]} packages present"
else
  echo "install-deps: installing ${missing[*]}"
  SUDO=""
  if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
  export DEBIAN_FRONTEND=noninteractive
  $SUDO apt-get update -qq
  $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
  echo "install-deps: done"
fi

# npm packages, exactly as each folder's package-lock.json pins them; `npm ci` only when its
# node_modules is missing or older than the lock file. web/: the browser viewer (three.js,
# protobufjs, fzstd, esbuild, puppeteer-core for its tests; nothing is fetched when the page
# loads). deploy/k8s-check/: the manifests' schema check (kubernetes-models' JSON schemas for
# ajv, yaml). (The container image's dependency layer has this script alone, without the lock
# files: then there is nothing to install.)
root="$(cd "$(dirname "$0")/.." && pwd)"
for dir in "$root/web" "$root/deploy/k8s-check"; do
  stamp="$dir/node_modules/.package-lock.json"
  [ -f "$dir/package-lock.json" ] || continue
  if [ ! -f "$stamp" ] || [ "$dir/package-lock.json" -nt "$stamp" ]; then
    echo "install-deps: npm ci in ${dir#"$root"/}"
    (cd "$dir" && npm ci --no-audit --no-fund --loglevel=error)
  else
    echo "install-deps: ${dir#"$root"/}/node_modules is current"
  fi
done
