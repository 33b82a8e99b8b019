#!/bin/sh
# The client frame against raw Embree (issue 22), before and after a change, side by side in one
# run: the command of docs/CLIENT_PASSES.md ("The frame against raw Embree") with BEFORE's bench,
# then with AFTER's (which writes docs/images/client_bench_raw_720p.json and .png), then a table of
# both runs' plain / raw ratios and frame hashes. Each run interleaves its scenes and configurations
# repeat by repeat and keeps the fastest of 3.
#   bench/client/raw_before_after.sh BEFORE/irradcast-bench-client AFTER/irradcast-bench-client
set -eu
before=$1 after=$2
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
run() {
  nice -n "${NICE:-0}" "$1" --scene cornell,rooms:2,sponza --configs plain,raw \
    --width 1280 --height 720 --frames 20 --repeat 3 --keep fastest --updates 2 \
    --json "$2" --plot "$3"
}
uptime
run "$before" "$tmp/before.json" ''
run "$after" docs/images/client_bench_raw_720p.json docs/images/client_bench_raw_720p.png
uptime
python3 - "$tmp/before.json" docs/images/client_bench_raw_720p.json <<'PY'
import json, sys
b, a = (json.load(open(p))["scenes"] for p in sys.argv[1:3])
def ms(s, c): return next(x for x in s["configs"] if x["config"] == c)
print("| Scene | plain ms | raw ms | **plain / raw** | fps (2 cores) | plain / raw before | speed-up | hash before | hash after |")
print("|---|---|---|---|---|---|---|---|---|")
for sb, sa in zip(b, a):
    pa, ra = ms(sa, "plain"), ms(sa, "raw")
    rb, r = sb["ratio_plain_over_raw"], sa["ratio_plain_over_raw"]
    print(f"| {sa['scene']} | {pa['ms_per_frame']:.2f} | {ra['ms_per_frame']:.2f} | **{r:.2f}** | "
          f"{1000 / pa['ms_per_frame']:.1f} | {rb:.2f} | {rb / r:.2f}x | "
          f"{ms(sb, 'plain')['image_hash']} | {pa['image_hash']} |")
PY
