#!/bin/sh
# Two builds of irradcast-bench-engine side by side: the pass benchmark of each, run alternately
# (A B A B ...), one thread, then per round and pass engine / raw Embree and the engine's time.
# Usage: bench/engine/compare.sh A_BIN B_BIN [ROUNDS] [OUT_DIR] [-- extra bench options]
# (default 2 rounds, OUT_DIR /tmp/bench-engine-compare; the JSON of every run is kept there).
# Every side is timed with the thread's CPU time (--cpu-time), so a loaded machine's other work
# does not count.
set -eu
a=$1
b=$2
rounds=${3:-2}
out=${4:-/tmp/bench-engine-compare}
shift $(($# < 4 ? $# : 4))
[ "${1:-}" = "--" ] && shift
mkdir -p "$out"
uptime
r=1
while [ "$r" -le "$rounds" ]; do
  for side in A B; do
    bin=$a
    [ "$side" = B ] && bin=$b
    nice -n 10 "$bin" --skip-scaling --threads 1 --cpu-time --reps 3 --min-time 0 --out "$out" \
      --json "$out/$side-$r.json" "$@" > "$out/$side-$r.log" 2>&1
  done
  r=$((r + 1))
done
uptime
python3 - "$out" "$rounds" <<'PY'
import json, sys
out, rounds = sys.argv[1], int(sys.argv[2])
rows = {}
for side in "AB":
    for r in range(1, rounds + 1):
        for scene in json.load(open(f"{out}/{side}-{r}.json"))["passes"]:
            for p in ("direct", "scatter"):
                ms = [m for m in scene["passes"] if m["pass"] == p]
                eng = sum(m["pipeline_s_min"] for m in ms)
                raw = sum(m["raw_s_min"] for m in ms)
                verify = max(m["verify_max_abs_diff"] for m in ms)
                rows.setdefault((scene["scene"], p), {}).setdefault(side, []).append(
                    (raw / eng, eng, verify))
                # the rays also through raw Embree in the engine's packets
                packets = sum(m.get("raw_packet_s_min", 0.0) for m in ms)
                if packets > 0:
                    rows.setdefault((scene["scene"], p + "/pkt"), {}).setdefault(side, []).append(
                        (packets / eng, eng, verify))
print(f"{'scene':10} {'pass':8} {'A engine/raw':>22} {'B engine/raw':>22} {'engine ms A -> B':>22}")
print("(direct/pkt, scatter/pkt: engine / raw rtcOccluded8 / rtcIntersect16 on the same rays in"
      " the engine's packets of 8 / 16; '-': a build without that timing)")
for (scene, p), s in rows.items():
    f = lambda side: ", ".join(f"{x[0] * 100:.1f} %" for x in s[side]) if side in s else "-"
    ms = lambda side: sum(x[1] for x in s[side]) / len(s[side]) * 1e3 if side in s else float("nan")
    v = max(x[2] for side in s for x in s[side])
    print(f"{scene:10} {p:8} {f('A'):>22} {f('B'):>22} {ms('A'):9.1f} -> {ms('B'):7.1f}"
          f"  ({(ms('B') / ms('A') - 1) * 100:+.1f} %, verify {v:g})")
PY
