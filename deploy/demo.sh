#!/usr/bin/env bash
# Installs what is missing, builds, and runs the main job: an irradcast-server on the built-in
# Cornell box and four irradcast-view clients with different cameras. Each viewer downloads the
# scene, streams the irradiance tiles while the server refines them, composes its own viewpoint,
# and writes it once the server's lightmaps are final. Then the server is stopped with SIGINT.
# Images and per-viewer reports land in out/demo/; the server's log in out/demo/server.log.
# The browser viewer (docs/VIEWER-WEB.md) is at the URL the demo prints; KEEP=1 keeps the server
# running after the viewers (Ctrl-C stops it) so that the page can be explored.
#   PORT=7450 HTTP_PORT=7451 UPDATES=16 KEEP=0 bash deploy/demo.sh
set -euo pipefail
cd "$(dirname "$0")/.."
bash deploy/install-deps.sh
bash deploy/build.sh build
out=out/demo
port=${PORT:-7450}
http_port=${HTTP_PORT:-7451}
updates=${UPDATES:-16}
mkdir -p "$out"
rm -f "$out"/view*.png "$out"/view*.json
# The control token for the live edit in the second half (a file, so it is not in `ps`).
head -c 18 /dev/urandom | base64 >"$out/token"
chmod 600 "$out/token"

./build/server/irradcast-server --scene cornell --port "$port" --bind 127.0.0.1 \
  --http-port "$http_port" --max-updates "$updates" --status-every 2 --control-token-file "$out/token" \
  >"$out/server.log" 2>&1 &
server=$!
trap 'kill -INT $server 2>/dev/null || true' EXIT
for _ in $(seq 100); do
  grep -q "listening on" "$out/server.log" 2>/dev/null && break
  kill -0 $server 2>/dev/null || { cat "$out/server.log"; echo "demo: the server did not start" >&2; exit 1; }
  sleep 0.1
done
echo "demo: server on 127.0.0.1:$port (log: $out/server.log), $updates engine updates"
echo "demo: browser viewer: http://127.0.0.1:$http_port/"

cameras=(
  ""                                                         # the scene's own camera
  "eye=0.05,0.45,0.05:target=0.45,0.1,0.5:fov=75"            # from the top left corner
  "eye=0.5,0.1,0.05:target=0.15,0.3,0.5:fov=70"              # low, from the right
  "eye=0.278,0.52,0.278:target=0.278,0,0.3:fov=95:up=0,0,1"  # looking down from the light
)
# Every viewer writes its converged image; `suffix` names the round.
status=0
view_round() {
  local suffix=$1 pids=()
  for i in "${!cameras[@]}"; do
    args=(--connect "127.0.0.1:$port" --out "$out/view$i$suffix.png"
          --json "$out/view$i$suffix.json" --until-converged --name "viewer$i"
          --cache-dir "$out/cache" --timeout 300 --log-level warn)
    [ -n "${cameras[$i]}" ] && args+=(--camera "${cameras[$i]}")
    ./build/client/irradcast-view "${args[@]}" &
    pids+=($!)
  done
  for p in "${pids[@]}"; do wait "$p" || status=1; done
}
view_round ""

# A live edit (docs/EDITS.md): move the light, repaint the red wall blue; the server refreshes
# what changed and the viewers of the second round get the edited scene and its lightmaps.
echo "demo: live edit: move the light, repaint the red wall"
./build/client/irradcast-edit --connect "127.0.0.1:$port" --token-file "$out/token" \
  --json '{"ops": [{"op": "move", "node": "light", "by": [0.1, -0.05, 0.08]},
                   {"op": "albedo", "material": "red", "color": [0.1, 0.2, 0.7]}]}' \
  | sed 's/^/demo: /' || status=1
view_round "_edited"

if [ "${KEEP:-0}" = 1 ]; then
  echo "demo: the server keeps running: http://127.0.0.1:$http_port/ (Ctrl-C stops it)"
  wait $server || true
else
  kill -INT $server
  wait $server || status=1
fi
trap - EXIT
echo
echo "demo: viewer  bytes received  time to converged image"
for suffix in "" _edited; do
  for i in "${!cameras[@]}"; do
    python3 - "$out/view$i$suffix.json" "view$i$suffix" <<'PY' 2>/dev/null || echo "        view$i$suffix (no report)"
import json, sys
r = json.load(open(sys.argv[1]))
print(f"        {sys.argv[2]:12s}  {r['bytes_received'] / 1024:10.1f} KB   {r['seconds_to_converged']:6.2f} s"
      f"   ({r['tiles_applied']} tiles, scene {'from cache' if r['scene_from_cache'] else 'downloaded'})")
PY
  done
done
grep "stopped:" "$out/server.log" | sed 's/^/demo: server /' || true
echo "demo: wrote $out/view0.png .. view$(( ${#cameras[@]} - 1 )).png (before the edit) and" \
  "view0_edited.png .. view$(( ${#cameras[@]} - 1 ))_edited.png (after)"
exit $status
