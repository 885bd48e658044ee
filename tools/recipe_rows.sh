#!/usr/bin/env bash
# The motion-learning recipe rows (issue 27): trains the fast preset on a scene once per
# variant in tools/recipe/*.toml (each a `--config` over the fast preset) plus the preset
# itself, one run at a time, and writes one `eval` table of them all (PSNR, dynamic/static
# PSNR, SSIM, MMAP, DRC). The displacement EPE of each run is in its log.jsonl
# (`motion_epe` against `motion_gt_px`) and drawn in its training.png.
#
#   tools/recipe_rows.sh [--data DIR] [--out DIR] [--seed N] [VARIANT ...]
#
# Default: the built-in scene, every variant, seed 0, into runs/recipe/<scene>-seed<N>.
set -euo pipefail
cd "$(dirname "$0")/.."
data="" out="" seed=0 variants=()
while [[ $# -gt 0 ]]; do
    case "$1" in
        --data) data="$2"; shift 2 ;;
        --out) out="$2"; shift 2 ;;
        --seed) seed="$2"; shift 2 ;;
        -h|--help) sed -n 2,9p "$0"; exit 0 ;;
        -*) echo "unknown argument $1 (see --help)" >&2; exit 2 ;;
        *) variants+=("$1"); shift ;;
    esac
done
[[ ${#variants[@]} -gt 0 ]] || variants=($(ls tools/recipe | sed 's/\.toml$//'))
scene="builtin" data_flag=()
if [[ -n "$data" ]]; then
    scene="$(basename "$data")"
    data_flag=(--data "$data")
fi
out="${out:-runs/recipe/$scene-seed$seed}"
mkdir -p "$out"
cargo build --release --quiet
bin=target/release/dispflow-vk
runs=()
for v in preset "${variants[@]}"; do
    cfg=()
    [[ $v == preset ]] || cfg=(--config "tools/recipe/$v.toml")
    echo "== $v" >&2
    "$bin" train --preset fast "${data_flag[@]}" --seed "$seed" "${cfg[@]}" --out "$out/$v" 2>"$out/$v.log" | tail -1
    runs+=(--run "$out/$v")
done
"$bin" eval "${runs[@]}" --table "$out/table.md" >/dev/null
cat "$out/table.md"
