#!/usr/bin/env bash
# Everything issue 19 measures on a machine with a GPU, from a bundle (deploy/bundle.sh), in one
# command that needs nothing installed there but glibc and the GPU's Vulkan driver:
#   deploy/gpu-run.sh [--quick] BUNDLE SPONZA OUT_DIR
# BUNDLE   the bundle's tarball (.tar.gz, unpacked into a temporary folder) or unpacked folder; it
#          must hold irradcast_tests and irradcast-bench-backend (deploy/bundle.sh without a
#          BUILD_DIR builds them)
# SPONZA   the Dabrovic Sponza folder (the one holding sponza.gltf; ../shared/testdata/
#          dabrovic-sponza here), or a folder holding dabrovic-sponza/
# OUT_DIR  where everything goes; at most 8 files (the device tool's limit):
#          gpu-run.log (all output), summary.txt (each step's result and the key numbers),
#          tests.xml (gtest, with the parity tests' recorded numbers), backend.json and
#          backend_rays.png (irradcast-bench-backend), load-vulkan.json and load-embree.json
#          (irradcast-load), servers.log (both servers' logs and /metrics scrapes)
# --quick  small sizes (lavapipe on the 2-core VM: about 2 minutes) to check the script itself.
# IRRADCAST_GPU_STEPS=tests,bench,load (the default) picks steps 3-5, to split a run over calls.
# Steps, each under its own time limit so that one hang loses only itself (about 6 minutes on a
# 16-core GPU machine):
#  1. the machine: GPU (nvidia-smi), glibc, the bundle's libraries all found (ldd);
#  2. irradcast-server --list-devices (VK_DRIVER_FILES: the NVIDIA ICD at
#     /usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json when present and unset);
#  3. the Vulkan tests that run in-process, with the bundle's validation layer: the parity tests
#     (Vulkan vs Embree lightmaps within Monte Carlo noise), the furnace, determinism and staging,
#     the reference, the sky and cut-outs;
#  4. irradcast-bench-backend on cornell, rooms:4 and sponza: Embree on all cores vs Vulkan,
#     interleaved in one run (docs/BENCHMARKS.md, "Backends");
#  5. irradcast-server on the Sponza with 64 simulated users of irradcast-load on the same
#     machine for 30 s, with --backend vulkan and then --backend embree: updates per second
#     (/metrics) and tile latency (the load report).
set -uo pipefail
quick=0
if [ "${1:-}" = --quick ]; then
  quick=1
  shift
fi
[ $# -eq 3 ] || {
  echo "usage: deploy/gpu-run.sh [--quick] BUNDLE SPONZA OUT_DIR" >&2
  exit 2
}
bundle=$1
sponza=$(cd "$2" 2>/dev/null && pwd) || {
  echo "gpu-run: no folder $2" >&2
  exit 2
}
mkdir -p "$3" && out=$(cd "$3" && pwd) || exit 2
tmp=$(mktemp -d /tmp/irradcast-gpu-run.XXXXXX)
trap 'rm -rf "$tmp"' EXIT

exec > >(tee "$out/gpu-run.log") 2>&1
summary=$out/summary.txt
: >"$summary"
note() { echo "$*" | tee -a "$summary"; }

if [ -f "$bundle" ]; then
  tar -C "$tmp" -xzf "$bundle" || exit 1
  root=$(find "$tmp" -mindepth 1 -maxdepth 1 -type d -name 'irradcast-bundle-*' | head -n 1)
else
  root=$(cd "$bundle" && pwd)
fi
[ -n "$root" ] && [ -x "$root/bin/irradcast-server" ] || {
  echo "gpu-run: $bundle is no bundle (bin/irradcast-server missing)" >&2
  exit 2
}
bin=$root/bin

# The sample data as the programs look for it: $IRRADCAST_TESTDATA/dabrovic-sponza/sponza.gltf.
if [ -f "$sponza/sponza.gltf" ]; then
  mkdir -p "$tmp/testdata"
  ln -s "$sponza" "$tmp/testdata/dabrovic-sponza"
  export IRRADCAST_TESTDATA=$tmp/testdata
elif [ -f "$sponza/dabrovic-sponza/sponza.gltf" ]; then
  export IRRADCAST_TESTDATA=$sponza
else
  echo "gpu-run: $sponza holds neither sponza.gltf nor dabrovic-sponza/sponza.gltf" >&2
  exit 2
fi

nvidia_icd=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
if [ -z "${VK_DRIVER_FILES:-}" ] && [ -z "${VK_ICD_FILENAMES:-}" ] && [ -f "$nvidia_icd" ]; then
  export VK_DRIVER_FILES=$nvidia_icd
fi
# The ICD names its library without a folder; the driver's folder may not be in ld.so.cache.
for d in /usr/local/nvidia/lib /usr/local/nvidia/lib64; do
  if [ -d "$d" ]; then export LD_LIBRARY_PATH=$d${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}; fi
done
# The bundle's validation layer (the tests open Vulkan with it).
if [ -d "$root/share/vulkan/explicit_layer.d" ]; then
  export VK_LAYER_PATH=$root/share/vulkan/explicit_layer.d
fi

if [ "$quick" = 1 ]; then
  tests_filter='Vulkan/VulkanParity.*/cornell_biased:Vulkan/VulkanFurnace.*:VulkanBackend.*'
  bench_args=(--texels-per-scene 24 --updates 1 --warmup 1 --reference-spp 1)
  server_args='--texels-per-scene 24'
  users=8 duration=15 limit_tests=300 limit_bench=300 limit_load=120
else
  tests_filter='Vulkan/VulkanParity.*:Vulkan/VulkanFurnace.*:VulkanBackend.*:VulkanReference.*'
  tests_filter+=':VulkanSky.*:VulkanCutOut.*:Vulkan.FindsADeviceWithComputeOnThisMachine'
  tests_filter+=':Vulkan.OpensTheBestDeviceWithValidationAndNoMessages'
  bench_args=(--updates 5 --warmup 1 --reference-spp 16)
  server_args=
  users=64 duration=30 limit_tests=120 limit_bench=180 limit_load=80
fi

# step NAME LIMIT_S COMMAND...: runs it under `timeout` (which ends the command's whole process
# group: a server it started too), notes the result and the time. A COMMAND that is one of the
# functions below runs in a child bash, which gets them and the variables they use exported.
export bin root tmp out summary users duration server_args
failures=0
step() {
  local name=$1 limit=$2 start=$SECONDS rc=0
  shift 2
  echo "=== $name: $*"
  timeout -k 10 "$limit" bash -c '"$@"' _ "$@" || rc=$?
  if [ "$rc" = 0 ]; then
    note "$name: ok ($((SECONDS - start)) s)"
  else
    failures=$((failures + 1))
    note "$name: FAILED, exit $rc$([ "$rc" = 124 ] && echo " (over its ${limit} s)") ($((SECONDS - start)) s)"
  fi
  return "$rc"
}

machine() {
  uname -a
  ldd --version | head -n 1
  nproc
  if command -v nvidia-smi >/dev/null; then
    nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv
  fi
  echo "VK_DRIVER_FILES=${VK_DRIVER_FILES:-} VK_LAYER_PATH=${VK_LAYER_PATH:-}"
  echo "LD_LIBRARY_PATH=${LD_LIBRARY_PATH:-} IRRADCAST_TESTDATA=$IRRADCAST_TESTDATA"
  cat "$root/BUNDLE.txt"
  local missing
  missing=$(for f in "$bin"/* "$root"/lib/*; do ldd "$f" | grep 'not found' | sed "s#^#$f: #"; done)
  [ -z "$missing" ] || {
    echo "libraries not found: $missing"
    return 1
  }
}
export -f note machine
step machine 30 machine

list_devices() {
  "$bin/irradcast-server" --list-devices | tee "$tmp/devices.txt"
  grep -q '^vulkan: \[0\]' "$tmp/devices.txt"
}
export -f list_devices
step list-devices 60 list_devices && note "  $(grep -E '^(vulkan: \[|--backend auto)' "$tmp/devices.txt" | tr '\n' ' ')"

want() { [[ ",${IRRADCAST_GPU_STEPS:-tests,bench,load}," == *",$1,"* ]]; }

if ! want tests; then
  :
elif [ -x "$bin/irradcast_tests" ]; then
  step vulkan-tests "$limit_tests" "$bin/irradcast_tests" --gtest_filter="$tests_filter" \
    --gtest_output="xml:$out/tests.xml"
  grep -E '^\[  (PASSED|FAILED|  SKIPPED) ' "$out/gpu-run.log" | sed 's/^/  /' >>"$summary"
else
  note "vulkan-tests: FAILED, the bundle has no irradcast_tests (bundle a build with tests)"
  failures=$((failures + 1))
fi

if ! want bench; then
  :
elif [ -x "$bin/irradcast-bench-backend" ]; then
  step bench-backend "$limit_bench" "$bin/irradcast-bench-backend" \
    --scenes cornell,rooms:4,sponza --backends embree,vulkan --threads 0 "${bench_args[@]}" \
    --out "$out" --json "$out/backend.json"
else
  note "bench-backend: FAILED, the bundle has no irradcast-bench-backend (bundle a build with benches)"
  failures=$((failures + 1))
fi

# GET /metrics over bash's /dev/tcp (no curl on a bare machine).
scrape() {
  exec 3<>"/dev/tcp/127.0.0.1/$1" || return 1
  printf 'GET /metrics HTTP/1.0\r\nHost: 127.0.0.1\r\n\r\n' >&3
  timeout 5 cat <&3
  exec 3<&-
}
metric() { awk -v m="$1" '$1 == m {print $2}' "$2"; }

# serve BACKEND: a server on the Sponza, $users simulated users for $duration s, the metrics
# before and after.
serve() {
  local backend=$1 log=$tmp/server-$1.log port='' mport='' i server_pid
  "$bin/irradcast-server" --scene sponza --backend "$backend" --bind 127.0.0.1 --port 0 \
    --metrics-port 0 --max-clients-per-peer 0 --status-every 5 $server_args >"$log" 2>&1 &
  server_pid=$!
  for i in $(seq 600); do
    port=$(sed -n 's/.*listening on 127\.0\.0\.1:\([0-9][0-9]*\).*/\1/p' "$log")
    mport=$(sed -n 's#.*metrics on http://127\.0\.0\.1:\([0-9][0-9]*\)/.*#\1#p' "$log")
    [ -n "$port" ] && [ -n "$mport" ] && break
    kill -0 "$server_pid" 2>/dev/null || break
    sleep 0.1
  done
  local ok=0
  if [ -n "$port" ] && [ -n "$mport" ]; then
    scrape "$mport" >"$tmp/metrics-$backend-0.txt"
    "$bin/irradcast-load" --connect "127.0.0.1:$port" --users "$users" --duration "$duration" \
      --json "$out/load-$backend.json" || ok=1
    scrape "$mport" >"$tmp/metrics-$backend-1.txt"
  else
    echo "the $backend server did not start"
    ok=1
  fi
  kill -TERM "$server_pid" 2>/dev/null
  wait "$server_pid" || ok=1
  {
    echo "===== server --backend $backend"
    cat "$log"
    for i in 0 1; do
      echo "===== /metrics, $([ $i = 0 ] && echo before || echo after) the load"
      cat "$tmp/metrics-$backend-$i.txt" 2>/dev/null
    done
  } >>"$out/servers.log"
  local u0 u1 s0 s1
  u0=$(metric irradcast_engine_updates_total "$tmp/metrics-$backend-0.txt")
  u1=$(metric irradcast_engine_updates_total "$tmp/metrics-$backend-1.txt")
  s0=$(metric irradcast_engine_seconds_total "$tmp/metrics-$backend-0.txt")
  s1=$(metric irradcast_engine_seconds_total "$tmp/metrics-$backend-1.txt")
  if [ -n "$u0" ] && [ -n "$u1" ]; then
    note "  $backend: $((${u1%.*} - ${u0%.*})) updates during the load ($duration s), $(awk -v a="$s0" -v b="$s1" -v n="$((${u1%.*} - ${u0%.*}))" 'BEGIN { if (n > 0) printf "%.1f ms", 1000 * (b - a) / n; else print "-" }') per update"
  fi
  return "$ok"
}
export -f scrape metric serve
backends=(vulkan embree)
want load || backends=()
for backend in "${backends[@]}"; do
  step "server-$backend+load" "$limit_load" serve "$backend"
  if [ -f "$out/load-$backend.json" ] && command -v python3 >/dev/null; then
    python3 - "$out/load-$backend.json" >>"$summary" <<'EOF'
import json, sys
r = json.load(open(sys.argv[1]))
u = r["users"]
print("  users %d connected, %d failed, %d with a full image" % (u["connected"], u["failed"], u["full_image"]))
for key in ("tile_latency_ms", "steady_tile_latency_ms", "full_image_ms"):
    p = r[key]
    print("  %s: p50 %.1f, p99 %.1f, max %.1f (%d)" % (key, p["p50"], p["p99"], p["max"], p["count"]))
EOF
  fi
done

note "gpu-run: $failures step(s) failed; ${SECONDS} s in all; outputs in $out"
[ "$failures" = 0 ]
