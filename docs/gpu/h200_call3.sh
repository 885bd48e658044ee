#!/bin/bash
# Device calls 3-5 (2026-11-26): the norm-grad default, the method effect at 3000 iterations, 10000-iteration recipe runs.
# Call 3 read h200_call3_jobs.txt (its bi-base-s1, bi-det-s0 and bi-oracle-full failed on the built-in cache race and
# were rerun by hand, alone); calls 4 and 5 ran the same script on a binary with the new default, reading
# h200_call4_jobs.txt and h200_call5_jobs.txt (mujoco-scene5 added: S5) with the job and xargs limits at 320/330 s and
# 230/235 s, then `bench step` (call 4). The jobs file was .bin/jobs3.txt in the carried working tree.
for f in .gl/*.deb; do dpkg -x $f /; done; ldconfig
export VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
B=$PWD/.bin/dispflow-vk; L=$OUT/log.txt; mkdir -p runs
S5=$PWD/.data/mujoco-scene5_rapid_motion; S7=$PWD/.data/mujoco-scene7_deformation; MN=$PWD/.data/movingnerf-capture1
$B devices >>$L 2>&1
one() {
  n=$1; s=$2; shift 2
  case $s in S7) d="--data $S7 --max-resolution 200";; MN) d="--data $MN";; BI) d="";; esac
  it="--iterations 3000"; case "$*" in *--iterations*) it="";; esac
  timeout 420 $B train --preset fast $it $d --out runs/$n "$@" >runs/$n.log 2>&1; echo "$n rc=$? $(date +%T)" >>$L
}
export -f one; export B L S5 S7 MN
date >>$L
cat .bin/jobs3.txt | timeout 470 xargs -P 8 -L 1 bash -c 'one "$@"' _
date >>$L
python3 - >>$L 2>&1 <<'PY'
import json,glob
print('run it psnr dyn static mmap drc minframe epe gt ms/step train_s gaussians')
for m in sorted(glob.glob('runs/*/metrics.json')):
    d=json.load(open(m)); n=m.split('/')[1]
    pf=[f['psnr'] for f in d['per_frame'] if f.get('psnr') is not None]
    epe=gt=None
    try:
        for line in open('runs/%s/log.jsonl'%n):
            l=json.loads(line)
            if l.get('motion_epe') is not None: epe=l['motion_epe']; gt=l.get('motion_gt_px')
    except Exception as e: pass
    r=(n,d['iterations'],d['psnr'],d.get('dynamic_psnr'),d.get('static_psnr'),d.get('mmap'),d.get('drc'),min(pf),epe,gt,d['ms_per_step'],d['train_seconds'],d.get('gaussians'))
    print(' '.join(str(round(x,3)) if isinstance(x,float) else str(x) for x in r))
PY
tar czf $OUT/small.tgz --exclude=checkpoints --exclude=point_cloud.ply --exclude='*.bin' --exclude='*.ply' runs
ls -la $OUT >>$L
