#!/bin/bash
# Device call 1: devices, bench step, bench methods, a paper-preset run, long runs on scene5/7.
for f in .gl/*.deb; do dpkg -x $f /; done; ldconfig
export VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
mkdir -p ../shared && ln -sfn $PWD/.data ../shared/data
B=$PWD/.bin/dispflow-vk; L=$OUT/log.txt
T0=$(date +%s); el() { echo "=== [$(( $(date +%s) - T0 )) s] $*" | tee -a $L; }
nvidia-smi -L >>$L 2>&1
el devices; timeout 40 $B devices >>$L 2>&1 || { VK_LOADER_DEBUG=error,warn $B devices 2>&1 | tail -30 >>$L; exit 1; }
el bench step; timeout 80 $B bench step --json $OUT/bench_step.json >>$L 2>&1; echo rc=$? >>$L
el bench methods; timeout 80 $B bench methods --json $OUT/bench_methods.json >>$L 2>&1; echo rc=$? >>$L
mkdir -p runs
el paper builtin; timeout 130 $B train --preset paper --out runs/paper-builtin >runs/paper-builtin.log 2>&1; echo rc=$? >>$L
tail -c 1500 runs/paper-builtin.log | tr '\r' '\n' | tail -8 >>$L
el parallel long runs
S5=$PWD/.data/mujoco-scene5_rapid_motion; S7=$PWD/.data/mujoco-scene7_deformation
run() { n=$1; shift; timeout $TL $B train --out runs/$n "$@" >runs/$n.log 2>&1; echo "$n rc=$?" >>$L; }
TL=150
run s5-fast-3000 --preset fast --data $S5 --max-resolution 200 --iterations 3000 &
run s5-fast-3000-w0 --preset fast --data $S5 --max-resolution 200 --iterations 3000 --config .bin/w0.toml &
run s7-fast-3000 --preset fast --data $S7 --max-resolution 200 --iterations 3000 &
run bi-fast-3000 --preset fast --iterations 3000 &
run s5-paper-200 --preset paper --data $S5 --max-resolution 200 &
wait
el done
for r in runs/*/; do n=$(basename $r); echo "--- $n" >>$L; python3 -c "
import json,sys
m=json.load(open('$r/metrics.json'))
print({k:m.get(k) for k in ['iterations','psnr','dynamic_psnr','static_psnr','mmap','drc','ms_per_step','train_seconds','num_gaussians','device']})" >>$L 2>&1; done
tar czf $OUT/runs.tgz --exclude='*.ckpt' --exclude=checkpoints runs 2>/dev/null
ls -la $OUT >>$L
