#!/usr/bin/env bash
# Deformable-3DGS baseline vs DispFlow-GS on one scene, same seed and iterations:
# trains both (motion weight 0 and the default), evaluates them with `dispflow-vk eval`
# into one Markdown table, and prints the per-kernel GPU time of the last motion step.
#
#   tools/compare_motion.sh [--data DIR] [--out DIR] [-- extra train flags]
#
# Default: the built-in synthetic scene (fast preset) into runs/compare/<scene>.
set -euo pipefail
cd "$(dirname "$0")/.."
data="" out="" extra=()
while [[ $# -gt 0 ]]; do
    case "$1" in
        --data) data="$2"; shift 2 ;;
        --out) out="$2"; shift 2 ;;
        --) shift; extra=("$@"); break ;;
        -h|--help) sed -n 2,8p "$0"; exit 0 ;;
        *) echo "unknown argument $1 (see --help)" >&2; exit 2 ;;
    esac
done
scene="builtin"
data_flag=()
if [[ -n "$data" ]]; then
    scene="$(basename "$data")"
    data_flag=(--data "$data")
fi
out="${out:-runs/compare/$scene}"
mkdir -p "$out"
cargo build --release --quiet
bin=target/release/dispflow-vk
for run in baseline dispflow; do
    weight=()
    [[ "$run" == baseline ]] && weight=(--motion-weight 0)
    echo "== training $run ($scene) =="
    "$bin" train "${data_flag[@]}" --out "$out/$run" "${weight[@]}" "${extra[@]}" -v \
        >"$out/$run.log" 2>&1 || { tail -20 "$out/$run.log"; exit 1; }
    grep -E "^test PSNR" "$out/$run.log" || true
done
"$bin" eval --run "$out/baseline" --run "$out/dispflow" --table "$out/table.md"
python3 - "$out" <<'PY'
import json, sys, re
out = sys.argv[1]
rows = []
for run in ("baseline", "dispflow"):
    m = json.load(open(f"{out}/{run}/metrics.json"))
    rows.append((run, m["ms_per_step"], m["num_gaussians"]))
print("\n| run | median ms/step (all steps) | Gaussians |\n|---|---:|---:|")
for r in rows:
    print(f"| {r[0]} | {r[1]:.1f} | {r[2]} |")
# The last per-kernel breakdown of each run (printed by train -v at every log line).
for run in ("baseline", "dispflow"):
    text = open(f"{out}/{run}.log").read()
    blocks = re.findall(r"GPU time of iteration (\d+) \(([\d.]+) ms\):\n((?:  .*\n)+)", text)
    if not blocks:
        continue
    it, total, body = blocks[-1]
    zones = {}
    for line in body.splitlines():
        m = re.match(r"\s+(.+?)\s+([\d.]+) ms", line)
        if m:
            zone = m.group(1).split("/")[0]
            zones[zone] = zones.get(zone, 0.0) + float(m.group(2))
    print(f"\n{run}: GPU time of iteration {it}: {float(total):.1f} ms")
    for z, ms in sorted(zones.items(), key=lambda kv: -kv[1]):
        print(f"  {z:<24} {ms:9.2f} ms {100 * ms / float(total):5.1f}%")
PY
