#!/bin/bash
# NeuSpike-Net stage 19 on one GPU: stage 17's data (spec_stage17.json) with 4,000 windows (the first
# 3,000 are stage 17's) and batch 16 (8 before), from the shipped stage-17 weights, for as long as the
# deadline allows (spec_stage19.json). The shard is simulated on the CPU by one process per core
# (--device cpu: no CUDA context in the forking parent); the network trains on the GPU at the `auto`
# precision. Up to four snapshots (both files each) come back for selection on the CPU
# (reports/neuspike-net/fullsize_check.py on training photographs).
#     bash reports/neuspike-net/gpu_stage19.sh OUT [DEADLINE_S]
#     DRY=1 bash reports/neuspike-net/gpu_stage19.sh OUT    (the same flow on the CPU, a few steps)
set -u
OUT=${1:?give an output folder}; DEADLINE_S=${2:-200}
T0=$(date +%s)
export PYTHONUNBUFFERED=1 MPLBACKEND=Agg
mkdir -p "$OUT" runs
cp neuspike/trained/neuspike-net.safetensors runs/nsn-stage19-start.safetensors
cp neuspike/trained/neuspike-net.json runs/nsn-stage19-start.json
SPEC=reports/neuspike-net/spec_stage19.json
if [ "${DRY:-0}" = 1 ]; then  # the spec made small (a spec file runs as written: flags cannot shrink it)
  python - "$SPEC" "$OUT" <<'PY'
import json, sys
s = json.load(open(sys.argv[1])); out = sys.argv[2]
s["data"].update(train_items=6, val_items=2, workers=2, shard_dir=f"{out}/dry-shard")
s.update(steps=4, batch=2, threads=2, val_every=2, out_dir=f"{out}/dry-run")
json.dump(s, open(f"{out}/dry-spec.json", "w"))
PY
  SPEC=$OUT/dry-spec.json; EVERY=2; DEV=cpu; RUN=$OUT/dry-run
else
  EVERY=300; DEV=cuda; RUN=runs/nsn-stage19
  nvidia-smi --query-gpu=name,memory.total --format=csv,noheader
fi
python -m neuspike.train neuspike-net --spec $SPEC --device cpu --simulate-only --quiet || exit 1
echo "shard simulated after $(( $(date +%s) - T0 )) s"
LEFT=$(( DEADLINE_S - ($(date +%s) - T0) - 25 ))   # 25 s: loading, the last save, packing
MINUTES=$(python -c "print(max(0.2, $LEFT / 60))")
echo "training for at most $MINUTES min"
python -m neuspike.train neuspike-net --spec $SPEC --device $DEV --snapshot-every $EVERY \
    --max-minutes "$MINUTES" --quiet
echo "trained after $(( $(date +%s) - T0 )) s"
cp $RUN/train_log.csv $RUN/spec.json "$OUT"/
SNAPS=($(ls -d $RUN/snapshots/step-* | sort | tail -4))
echo "snapshots: ${SNAPS[*]}"
tar -cf - "${SNAPS[@]}" | split -b 15M -d - "$OUT/snapshots.tar.part"
ls -la "$OUT"
echo "done after $(( $(date +%s) - T0 )) s"
