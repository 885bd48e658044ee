#!/bin/bash
# Device call 2: recipe hypotheses at 3000 iterations, 8 runs at a time.
for f in .gl/*.deb; do dpkg -x $f /; done; ldconfig
export VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
B=$PWD/.bin/dispflow-vk; L=$OUT/log.txt; mkdir -p runs
S5=$PWD/.data/mujoco-scene5_rapid_motion; S7=$PWD/.data/mujoco-scene7_deformation
one() {
  n=$1; s=$2; shift 2
  case $s in S5) d="--data $S5 --max-resolution 200";; S7) d="--data $S7 --max-resolution 200";; BI) d="";; esac
  it="--iterations 3000"; case "$*" in *--iterations*) it="";; esac
  timeout 150 $B train --preset fast $it $d --out runs/$n "$@" >runs/$n.log 2>&1; echo "$n rc=$?" >>$L
}
export -f one; export B L S5 S7
date >>$L
cat .bin/jobs2.txt | timeout 320 xargs -P 8 -L 1 bash -c 'one "$@"' _
date >>$L
python3 - >>$L 2>&1 <<'PY'
import json,glob,os
rows=[]
for m in sorted(glob.glob('runs/*/metrics.json')):
    d=json.load(open(m)); n=m.split('/')[1]
    pf=[f['psnr'] for f in d['per_frame'] if f.get('psnr') is not None]
    rows.append((n,d['iterations'],d['psnr'],d.get('dynamic_psnr'),d.get('static_psnr'),d.get('mmap'),d.get('drc'),min(pf),d['ms_per_step'],d['train_seconds']))
print('run it psnr dyn static mmap drc minframe ms/step train_s')
for r in rows: print(' '.join(str(round(x,3)) if isinstance(x,float) else str(x) for x in r))
best=sorted([r for r in rows if r[0].startswith('s5')], key=lambda r:-(r[3] or 0))[:2]+sorted([r for r in rows if r[0].startswith('bi')], key=lambda r:-(r[3] or 0))[:1]
open('best.txt','w').write(' '.join('runs/'+r[0] for r in best))
PY
tar czf $OUT/small.tgz --exclude=checkpoints --exclude=point_cloud.ply --exclude='*.bin' runs
tar czf $OUT/best.tgz --exclude=checkpoints $(cat best.txt)
ls -la $OUT >>$L
