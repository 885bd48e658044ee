#!/bin/bash
# Issue 37 device call: tracked transients vs off, two seeds, GPU targets. Not committed as is (docs/gpu gets a copy).
cd "$(dirname "$0")/.."
ROOT=$PWD; L=$OUT/log.txt
for f in .gl/*.deb; do dpkg -x $f /; done; ldconfig
export VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
B=$ROOT/.bin/dispflow-vk; C=$ROOT/.bin/cfg
S5=$ROOT/.data/mujoco-scene5_rapid_motion; S7=$ROOT/.data/mujoco-scene7_deformation; MN=$ROOT/.data/movingnerf-capture1
mkdir -p ../shared && ln -sfn $ROOT/.data ../shared/data
mkdir -p runs; nvidia-smi -L >>$L 2>&1; timeout 30 $B devices >>$L 2>&1
one() {
  n=$1; s=$2; shift 2
  case $s in S5) d="--data $S5 --max-resolution 200";; S7) d="--data $S7 --max-resolution 200";; MN) d="--data $MN";; BI) d="";; esac
  timeout ${T_JOB:-330} $B train --preset fast $d --out runs/$n "$@" >runs/$n.log 2>&1; echo "$n rc=$? ${SECONDS}s" >>$L
}
export -f one; export B L S5 S7 MN C
sed "s|CFG/|$C/|g" ${JOBS:-.bin/jobs1.txt} >/tmp/jobs.txt
# the built-in scene is generated once into the cache: do it before the parallel jobs
timeout 60 $B train --preset fast --iterations 1 --out /tmp/warm >/dev/null 2>&1
echo "start ${SECONDS}s" >>$L
timeout ${T_JOBS:-370} xargs -P ${P:-8} -L 1 bash -c 'one "$@"' _ </tmp/jobs.txt
echo "jobs done ${SECONDS}s" >>$L
for f in runs/*.log; do echo "$f spawn ms: $(grep -o '[0-9]* ms$' $f | sort -n | awk '{a[NR]=$1} END {if (NR) print NR, "spawns, median", a[int((NR+1)/2)], "max", a[NR]}')"; done >>$L
for r in ${GIFS:-bi-seqon-1800-s0 bi-seqoff-1800-s0}; do
  timeout 40 $B render --run runs/$r --path fixed --camera 0 --gif --fps 12 >>runs/$r.render.log 2>&1; echo "gif $r rc=$?" >>$L
done
python3 - >>$L 2>&1 <<'PY'
import json,glob
print('run it psnr dyn static ssim mmap drc minframe ms/step train_s gauss canon trans')
for m in sorted(glob.glob('runs/*/metrics.json')):
    d=json.load(open(m)); n=m.split('/')[1]
    pf=[f['psnr'] for f in d['per_frame'] if f.get('psnr') is not None]
    r=(n,d['iterations'],d['psnr'],d.get('dynamic_psnr'),d.get('static_psnr'),d.get('ssim'),d.get('mmap'),d.get('drc'),min(pf) if pf else None,d['ms_per_step'],d['train_seconds'],d.get('num_gaussians'),d.get('gaussians_canonical'),d.get('gaussians_transient'))
    print(' '.join(str(round(x,3)) if isinstance(x,float) else str(x) for x in r))
PY
tar czf $OUT/small.tgz --exclude=checkpoints --exclude='*.ply' --exclude='*.bin' --exclude=renders --exclude=render runs
tar czf $OUT/renders.tgz runs/s5-*/renders runs/s7-seq*-10k-s0/renders runs/bi-*-s0/renders 2>/dev/null
find runs -name '*.gif' | head -4 | while read g; do cp $g $OUT/$(echo $g | cut -d/ -f2).gif; done
if [ "${BENCH:-1}" = 1 ]; then timeout 90 $B bench step >$OUT/bench_step.txt 2>&1; echo "bench rc=$? ${SECONDS}s" >>$L; fi
ls -la $OUT >>$L
