#!/bin/bash
# E2VID stage 8 on one GPU: stage 7's data recipe (16-window sequences of linear radiance, clean events
# drawn twice as often) with four times the items (1,200), crops of 112 pixels (48 before) and batch 8
# (4 before), from the shipped stage-7 weights, for as long as the deadline allows. The shard is
# simulated by one process per CPU core; the network trains on the GPU in float32 (cuDNN's default
# TF32 convolutions). Three snapshots come back as bfloat16 safetensors for selection on the CPU
# through the sweep harness on training photographs (reports/e2vid/candidates).
#     bash reports/e2vid/gpu_stage8.sh OUT [DEADLINE_S]     (DEADLINE_S: seconds from now to be done)
#     DRY=1 bash reports/e2vid/gpu_stage8.sh OUT            (the same flow on the CPU in a minute)
set -u
OUT=${1:?give an output folder}; DEADLINE_S=${2:-480}
T0=$(date +%s)
export PYTHONUNBUFFERED=1 MPLBACKEND=Agg
mkdir -p "$OUT" runs
RUN=runs/e2vid-stage8
cp neuspike/trained/e2vid.safetensors runs/e2vid-stage8-start.safetensors
cp neuspike/trained/e2vid.json runs/e2vid-stage8-start.json
if [ "${DRY:-0}" = 1 ]; then
  DEV=cpu; ITEMS=4; VAL=2; WORKERS=2; STEPS=4; EVERY=2; CROP=48; BATCH=2; THREADS=2; RUN=$OUT/dry-run
  SHARD=$OUT/dry-shards
else
  DEV=cuda; ITEMS=1200; VAL=16; WORKERS=$(nproc); STEPS=2000; EVERY=250; CROP=112; BATCH=8; THREADS=8
  SHARD=runs/shards
  nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv
fi
COMMON=(e2vid --hdr-fraction 0 --noise-levels none,none,small,medium,high --windows 16 --length 16
        --train-items $ITEMS --val-items $VAL --workers $WORKERS --shard $SHARD --out $RUN
        --export-dir $RUN/export --crop $CROP --batch $BATCH --lr 1e-4 --lr-min 1e-5 --warmup 50
        --steps $STEPS --val-every $EVERY --snapshot-every $EVERY --threads $THREADS --device $DEV
        --precision float32 --init-from runs/e2vid-stage8-start.safetensors)
python -m neuspike.train "${COMMON[@]}" --simulate-only --quiet || exit 1
echo "shard simulated after $(( $(date +%s) - T0 )) s"
LEFT=$(( DEADLINE_S - ($(date +%s) - T0) - 45 ))   # 45 s: loading the shard, the last save, packing
MINUTES=$(python -c "print(max(0.5, $LEFT / 60))")
echo "training for at most $MINUTES min"
python -m neuspike.train "${COMMON[@]}" --max-minutes "$MINUTES" --quiet
echo "trained after $(( $(date +%s) - T0 )) s"
cp $RUN/train_log.csv $RUN/spec.json "$OUT"/
# three snapshots (a third, two thirds and all of the steps reached), packed in 15 MiB pieces
SNAPS=($(ls -d $RUN/snapshots/step-* | sort))
N=${#SNAPS[@]}
PICK=($(python -c "n=$N; print(*sorted({max(0, n // 3 - 1), max(0, 2 * n // 3 - 1), n - 1}))"))
FILES=()
for i in "${PICK[@]}"; do FILES+=("${SNAPS[$i]}"); done
echo "snapshots: ${FILES[*]}"
tar -cf - "${FILES[@]}" | split -b 15M -d - "$OUT/snapshots.tar.part"
ls -la "$OUT"
echo "done after $(( $(date +%s) - T0 )) s"
