#!/usr/bin/env bash
# Installs what is missing, builds, and runs the main job: an irradcast-server on the built-in
# Cornell box and four irradcast-view clients with different cameras. Each viewer downloads the
# scene, streams the irradiance tiles while the server refines them, composes its own viewpoint,
# and writes it once the server's lightmaps are final. Then the server is stopped with SIGINT.
# Images and per-viewer reports land in out/demo/; the server's log in out/demo/server.log.
#   PORT=7450 UPDATES=16 bash deploy/demo.sh
set -euo pipefail
cd "$(dirname "$0")/.."
bash deploy/install-deps.sh
bash deploy/build.sh build
out=out/demo
port=${PORT:-7450}
updates=${UPDATES:-16}
mkdir -p "$out"
rm -f "$out"/view*.png "$out"/view*.json

./build/server/irradcast-server --scene cornell --port "$port" --bind 127.0.0.1 \
  --max-updates "$updates" --status-every 2 >"$out/server.log" 2>&1 &
server=$!
trap 'kill -INT $server 2>/dev/null || true' EXIT
for _ in $(seq 100); do
  grep -q "listening on" "$out/server.log" 2>/dev/null && break
  kill -0 $server 2>/dev/null || { cat "$out/server.log"; echo "demo: the server did not start" >&2; exit 1; }
  sleep 0.1
done
echo "demo: server on 127.0.0.1:$port (log: $out/server.log), $updates engine updates"

cameras=(
  ""                                                         # the scene's own camera
  "eye=0.05,0.45,0.05:target=0.45,0.1,0.5:fov=75"            # from the top left corner
  "eye=0.5,0.1,0.05:target=0.15,0.3,0.5:fov=70"              # low, from the right
  "eye=0.278,0.52,0.278:target=0.278,0,0.3:fov=95:up=0,0,1"  # looking down from the light
)
pids=()
for i in "${!cameras[@]}"; do
  args=(--connect "127.0.0.1:$port" --out "$out/view$i.png" --json "$out/view$i.json"
        --until-converged --name "viewer$i" --cache-dir "$out/cache" --timeout 300
        --log-level warn)
  [ -n "${cameras[$i]}" ] && args+=(--camera "${cameras[$i]}")
  ./build/client/irradcast-view "${args[@]}" &
  pids+=($!)
done
status=0
for p in "${pids[@]}"; do wait "$p" || status=1; done

kill -INT $server
wait $server || status=1
trap - EXIT
echo
echo "demo: viewer  bytes received  time to converged image"
for i in "${!cameras[@]}"; do
  python3 - "$out/view$i.json" "$i" <<'PY' 2>/dev/null || echo "        view$i (no report)"
import json, sys
r = json.load(open(sys.argv[1]))
print(f"        view{sys.argv[2]}  {r['bytes_received'] / 1024:10.1f} KB   {r['seconds_to_converged']:6.2f} s"
      f"   ({r['tiles_applied']} tiles, scene {'from cache' if r['scene_from_cache'] else 'downloaded'})")
PY
done
grep "stopped:" "$out/server.log" | sed 's/^/demo: server /' || true
echo "demo: wrote $out/view0.png .. view$(( ${#cameras[@]} - 1 )).png"
exit $status
