#!/usr/bin/env bash
# Does a moving object survive as the training frames span more time? (issue 27, "why objects
# vanish"). For each K, trains the fast preset on the first K training frames of a D-NeRF-style
# scene (their time span grows with K; with a teleporting camera, so does the number of views)
# and scores the same K frames (train = test). Runs each deformation setting, so the
# deformation's share shows: with `--deform off` (a static model) against the deformation
# fields. Prints a Markdown table (PSNR, dynamic/static PSNR, worst frame, Gaussians).
#
#   tools/time_span.sh --data DIR [--out DIR] [--res PX] [--iterations N] [--ks "6 12 24"]
#
# Default: --res 100 --iterations 600 --ks "6 12 24 48 all", into runs/time-span/<scene>.
# The subsets are frame lists beside the runs (transforms_*.json naming the dataset's images).
set -euo pipefail
cd "$(dirname "$0")/.."
data="" out="" res=100 its=600 ks="6 12 24 48 all"
while [[ $# -gt 0 ]]; do
    case "$1" in
        --data) data="$2"; shift 2 ;;
        --out) out="$2"; shift 2 ;;
        --res) res="$2"; shift 2 ;;
        --iterations) its="$2"; shift 2 ;;
        --ks) ks="$2"; shift 2 ;;
        -h|--help) sed -n 2,12p "$0"; exit 0 ;;
        *) echo "unknown argument $1 (see --help)" >&2; exit 2 ;;
    esac
done
[[ -n "$data" && -f "$data/transforms_train.json" ]] || {
    echo "--data must name a D-NeRF-style scene (transforms_train.json)" >&2
    exit 2
}
data=$(cd "$data" && pwd)
out=${out:-runs/time-span/$(basename "$data")}
mkdir -p "$out"
cargo build --release -q
bin=target/release/dispflow-vk
printf 'warm_up = 0\n' >"$out/no_warm_up.toml"

subset() { # K → a dataset directory of the first K training frames, scored on themselves
    local k=$1 dir="$out/data-$1"
    mkdir -p "$dir"
    for f in train fused.ply class_mapping.json points3d.ply; do
        [[ -e "$data/$f" ]] && ln -sfn "$data/$f" "$dir/$f"
    done
    python3 - "$data" "$dir" "$k" <<'PY'
import json, sys
src, dst, k = sys.argv[1], sys.argv[2], sys.argv[3]
t = json.load(open(f"{src}/transforms_train.json"))
if k != "all":
    t["frames"] = t["frames"][: int(k)]
for split in ("train", "test"):
    json.dump(t, open(f"{dst}/transforms_{split}.json", "w"))
PY
    echo "$dir"
}

echo "| frames | setting | PSNR | dyn PSNR | static PSNR | worst frame | Gaussians |"
echo "|---|---|---:|---:|---:|---:|---:|"
for k in $ks; do
    dir=$(subset "$k")
    for setting in nodes mlp off; do
        case $setting in
            nodes) extra=() ;;
            mlp) extra=(--deform-field mlp) ;;
            off) extra=(--deform off) ;;
        esac
        run="$out/$setting-$k"
        "$bin" train --preset fast --data "$dir" --max-resolution "$res" --iterations "$its" \
            --config "$out/no_warm_up.toml" --out "$run" "${extra[@]}" >"$run.log" 2>&1 || {
            echo "| $k | $setting | failed: see $run.log | | | | |"
            continue
        }
        python3 - "$run/metrics.json" "$k" "$setting" <<'PY'
import json, sys
m = json.load(open(sys.argv[1]))
f = lambda v: "n/a" if v is None else f"{v:.2f}"
worst = min(p["psnr"] for p in m["per_frame"])
print(f"| {sys.argv[2]} | {sys.argv[3]} | {f(m['psnr'])} | {f(m.get('dynamic_psnr'))} | "
      f"{f(m.get('static_psnr'))} | {f(worst)} | {m['num_gaussians']} |")
PY
    done
done
