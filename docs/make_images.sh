#!/usr/bin/env bash
# Regenerates the engine-vs-reference and probe-leak pictures in docs/images/ and prints the
# error numbers quoted in docs/ENGINE.md. Needs a build (bash deploy/build.sh) and python3
# (standard library only) for the report numbers and the side-by-side montage. ~7 min on 2 cores.
set -euo pipefail
cd "$(dirname "$0")/.."
BAKE=build/server/irradcast-bake
OUT=${OUT:-out/docs}
IMG=docs/images
mkdir -p "$OUT" "$IMG"
err() { python3 -c "import json,sys; r=json.load(open(sys.argv[1])); e=r['error']; print(f\"{sys.argv[2]}: relMSE {e['rel_mse']:.4f}  RMSE {e['rmse']:.4f}  ({r['engine']['updates'] if 'engine' in r else ''} updates vs {e['reference_spp']} spp)\")" "$1" "$2"; }

# Method beside the reference path tracer (same camera, same bounce count).
$BAKE --quiet --scene cornell --out "$OUT/cornell" --updates 16 --reference 256
cp "$OUT/cornell/view_vs_reference.png" "$IMG/cornell_engine_vs_reference.png"
err "$OUT/cornell/report.json" "cornell, range 0.3"
$BAKE --quiet --scene cornell --out "$OUT/cornell_inf" --updates 16 --reference 256 --tracing-range inf
cp "$OUT/cornell_inf/view_vs_reference.png" "$IMG/cornell_unbiased_vs_reference.png"
err "$OUT/cornell_inf/report.json" "cornell, range inf"
$BAKE --quiet --scene rooms:2 --out "$OUT/rooms2" --width 480 --height 360 --updates 16 --reference 512 --cell-size 0.25 --tracing-range 0.3
cp "$OUT/rooms2/view_vs_reference.png" "$IMG/rooms2_engine_vs_reference.png"
err "$OUT/rooms2/report.json" "rooms:2, range 0.3"

# Probe leaks at tracing range 0.05, seen from the unlit room (1,1) toward its two lit
# neighbours: the seed's probes (cell centres, no visibility) against ours, and the reference.
CAM="eye=7.6,1.7,7.6:target=4.3,1.0,4.3:fov=70"
LEAK="--scene rooms:2 --camera $CAM --width 480 --height 360 --tracing-range 0.05 --cell-size 0.125 --updates 16"
$BAKE --quiet $LEAK --out "$OUT/leak_fixed" --reference 512
# The same exposure for all three panels (auto exposure would hide a uniformly brighter image).
EV=$(python3 -c "import json; print(json.load(open('$OUT/leak_fixed/report.json'))['settings']['exposure_ev'])")
$BAKE --quiet $LEAK --out "$OUT/leak_seed" --reference 512 --exposure "$EV" --no-probe-relocation --no-probe-visibility
err "$OUT/leak_fixed/report.json" "rooms:2 unlit room, range 0.05, relocation + visibility"
err "$OUT/leak_seed/report.json" "rooms:2 unlit room, range 0.05, seed probes"
python3 docs/png_montage.py "$IMG/rooms2_leaks_seed_fixed_reference.png" \
  "$OUT/leak_seed/view.png" "$OUT/leak_fixed/view.png" "$OUT/leak_fixed/reference.png"

# Noise and bias of the probes by probe-map resolution (docs/ENGINE.md): the sky-lit Sponza's
# gallery and view up, three seeds each at 8 x 8 and 12 x 12 maps, and the unbiased mode; each
# panel the mean of its views over the seed-1 reference (docs/bias_map.py). ~12 min on 2 cores.
# (The Sponza is read from $IRRADCAST_TESTDATA or ../shared/testdata.)
if [ -d "${IRRADCAST_TESTDATA:-../shared/testdata}/dabrovic-sponza" ]; then
  mean() { python3 -c "import json,sys; print(sys.argv[2], json.load(open(sys.argv[1]))['timings_s']['lightmaps'])" "$1" "$2"; }
  for view in gallery up; do
    case $view in
      gallery) CAM="eye=-10,1.6,-5.6:target=10,1.6,-5.6:fov=60" ;;
      up) CAM="eye=0,1.6,0:target=0.5,20,0:fov=70" ;;
    esac
    S="--scene sponza --width 200 --height 150 --updates 16 --camera $CAM"
    $BAKE --quiet $S --out "$OUT/$view-8-1" --reference 128
    groups=()
    for cfg in 8 12 inf; do
      files=()
      for seed in 1 2 3; do
        dir="$OUT/$view-$cfg-$seed"
        if [ "$cfg" = inf ]; then extra="--tracing-range inf"; else extra="--probe-resolution $cfg"; fi
        [ -f "$dir/view.exr" ] || $BAKE --quiet $S $extra --seed $seed --out "$dir"
        mean "$dir/report.json" "$view $cfg seed $seed lightmap seconds:"
        files+=("$dir/view.exr")
      done
      groups+=("$(IFS=,; echo "${files[*]}")")
    done
    python3 docs/bias_map.py --mean "$OUT/$view-8-1/reference.exr" ${groups[@]//,/ }
    python3 docs/bias_map.py "$OUT/$view-bias.png" "$OUT/$view-8-1/reference.exr" "${groups[@]}"
    python3 docs/png_montage.py "$IMG/sponza_${view}_bias_by_probe_resolution.png" \
      "$OUT/$view-8-1/reference.png" "$OUT/$view-bias.png"
  done
fi
