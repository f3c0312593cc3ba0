#!/bin/bash
# E2VID stages 23 and 24 on one GPU (rules rule_stage23.md and rule_stage24.md, written before training):
# stage 22's shard (spec seed 1: 480 + 16 sequences of 16 windows) is simulated by one process per CPU
# core, then stage 23 (120 steps at 3e-5 from stage 20) trains to its end, then stage 24 (the same over
# 360 steps) for the time left before the deadline. The specs run as written (precision auto: the
# trainer times a step in float32 and bfloat16 on the device and keeps its choice in precision.json);
# only the device, the simulating processes and the torch threads are given here. The snapshots the
# rules score come back as bfloat16 safetensors with their cards, packed in 15 MiB pieces, for the
# held-out harness on the CPU (reports/e2vid/candidates/harness.sh).
#     bash reports/e2vid/gpu_stage23.sh OUT [DEADLINE_S]     (DEADLINE_S: seconds from now to be done)
#     DRY=1 bash reports/e2vid/gpu_stage23.sh OUT            (the same flow on the CPU on tiny specs)
#     SKIP23=1 bash reports/e2vid/gpu_stage23.sh OUT [DEADLINE_S]   (stage 24 alone: stage 23 ran on a CPU)
# Unpack on the CPU with: cat OUT/snapshots.tar.part* | tar -xf -
# Every phase runs under `timeout` inside the deadline and writes one line to OUT/progress.txt, so a
# phase that stalls still leaves the script time to pack what exists (a first try on an H200 gave no
# output at all when the device tool's own limit killed it mid-run; where it stalled is not known).
set -u
OUT=${1:?give an output folder}; DEADLINE_S=${2:-540}
T0=$(date +%s)
note() { echo "$(( $(date +%s) - T0 )) s: $*" | tee -a "$OUT/progress.txt"; }
left() { echo $(( DEADLINE_S - ($(date +%s) - T0) - ${1:-0} )); }
export PYTHONUNBUFFERED=1 MPLBACKEND=Agg
mkdir -p "$OUT" runs
S23=reports/e2vid/spec_stage23.json; S24=reports/e2vid/spec_stage24.json; R23=runs/e2vid-stage23; R24=runs/e2vid-stage24
if [ "${DRY:-0}" = 1 ]; then
  DEV=cpu; WORKERS=2; THREADS=2; EVERY23=2; EVERY24=2
  # the same specs shrunk to a minute on the CPU, written beside the output
  python - "$S23" "$S24" "$OUT" <<'PY' || exit 1
import json, sys
for src, tag in zip(sys.argv[1:3], ("23", "24")):
    spec = json.load(open(src))
    spec["data"].update(train_items=4, val_items=2, windows=4, length=4, size=64, view=[96, 64],
                        shard_root=f"{sys.argv[3]}/dry-shards")
    spec.update(steps=4 if tag == "23" else 6, val_every=2, crop=48, batch=2, warmup=1,
                out_dir=f"{sys.argv[3]}/e2vid-stage{tag}", export_dir=f"{sys.argv[3]}/dry-export{tag}",
                init_from=f"{sys.argv[3]}/e2vid-start.safetensors")
    json.dump(spec, open(f"{sys.argv[3]}/spec_stage{tag}.json", "w"), indent=2)
PY
  S23=$OUT/spec_stage23.json; S24=$OUT/spec_stage24.json; R23=$OUT/e2vid-stage23; R24=$OUT/e2vid-stage24
  rm -rf $R23 $R24
  cp neuspike/trained/e2vid.safetensors $OUT/e2vid-start.safetensors
else
  DEV=cuda; WORKERS=$(( $(nproc) > 8 ? 8 : $(nproc) )); THREADS=8; EVERY23=30; EVERY24=60
  export NUMBA_NUM_THREADS=1 OMP_NUM_THREADS=1   # one thread per simulating process: no oversubscription
  nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv
  python -c "import torch; print('torch', torch.__version__, torch.cuda.get_device_name(0))"
  cp neuspike/trained/e2vid.safetensors runs/e2vid-stage23-start.safetensors
  cp neuspike/trained/e2vid.safetensors runs/e2vid-stage24-start.safetensors
fi
note "simulating the shard with $WORKERS processes"
timeout -k 10 $(left 240) python -m neuspike.train e2vid --spec "$S23" --device $DEV --workers $WORKERS --threads $THREADS \
    --simulate-only --quiet || { note "simulation failed or ran out of time (rc $?)"; exit 1; }
note "shard simulated"
if [ "${SKIP23:-0}" = 1 ]; then
  note "stage 23 skipped (SKIP23=1)"; R23=/nonexistent
else
  MINUTES=$(python -c "print(max(0.5, $(left 90) / 60))")   # 90 s: loading the shard, the last save, packing
  note "stage 23: training for at most $MINUTES min"
  timeout -k 10 $(left 30) python -m neuspike.train e2vid --spec "$S23" --device $DEV --threads $THREADS \
      --snapshot-every $EVERY23 --max-minutes "$MINUTES" --quiet
  note "stage 23 ended (rc $?)"
fi
LEFT=$(left 90)
if [ "$LEFT" -gt 30 ]; then
  MINUTES=$(python -c "print($LEFT / 60)")
  note "stage 24: training for at most $MINUTES min"
  timeout -k 10 $(left 30) python -m neuspike.train e2vid --spec "$S24" --device $DEV --threads $THREADS \
      --snapshot-every $EVERY24 --max-minutes "$MINUTES" --quiet
  note "stage 24 ended (rc $?)"
else
  note "stage 24: no time left ($LEFT s)"
fi
FILES=()
for run in $R23 $R24; do
  [ -d $run ] || continue
  tag=$(basename $run)
  for f in train_log.csv precision.json; do [ -f $run/$f ] && cp $run/$f "$OUT/$tag-$f"; done
  LAST=$(ls -d $run/snapshots/step-* 2>/dev/null | sort | tail -1)
  [ -n "$LAST" ] && FILES+=("$LAST")
done
echo "snapshots: ${FILES[*]}"
[ ${#FILES[@]} -gt 0 ] && tar -cf - "${FILES[@]}" | split -b 15M -d - "$OUT/snapshots.tar.part"
ls -la "$OUT"
note "done"
