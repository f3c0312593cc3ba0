#!/bin/bash
# The GPU checks behind this folder, on a machine where torch sees a CUDA device and the package is
# installed (pip install -e .): Table 2 on the GPU, the auto-precision run, the device tests, and
# every command end to end with --device cuda. About 3 minutes on one H100.
#     bash reports/timing-gpu/checks.sh WEIGHTS OUT     (WEIGHTS: the folder of FireNet's published weights)
set -u
W=${1:?give the folder of published weights}; OUT=${2:-runs/gpu-checks}
export PYTHONUNBUFFERED=1 MPLBACKEND=Agg
NETS=e2vid,firenet,firenet-plus,firenet-sim,neuspike-net,neuspike-net-spike
mkdir -p "$OUT"
python -m bench.timing --full --device cuda --precision float32 --methods $NETS --weights "$W" --results none \
    --out "$OUT/timing-gpu"
python -m bench.timing --sizes 400x250 --repeats 10 --warmup 2 --device cuda --precision auto --methods $NETS \
    --weights "$W" --results none --no-report --out "$OUT/timing-gpu/auto"
python -m pytest -q tests/neuspike/train/test_device.py tests/bench/test_device_refusals.py tests/bench/test_sweep_identity.py
# one recording reconstructed on the GPU and on the CPU: the images should agree to rounding
python -m neuspike.simulate --image camera --light 0.25 --motion 128 --history 0.05 --out "$OUT/sim" --no-progress
for d in cuda cpu; do
  python -m neuspike.reconstruct --spikes "$OUT/sim/spikes.dat" --events "$OUT/sim/events.h5" \
      --method neuspike-net,neuspike-net-spike,e2vid,firenet --weights "$W" --device $d --out "$OUT/rec-$d"
done
python - "$OUT" <<'PY'
import sys
import numpy as np
out = sys.argv[1]
for n in ("neuspike-net", "neuspike-net-spike", "e2vid", "firenet"):
    a, b = np.load(f"{out}/rec-cuda/{n}.npy"), np.load(f"{out}/rec-cpu/{n}.npy")
    print(f"{n}: max |cuda - cpu| = {np.abs(a - b).max():.4f}, mean {np.abs(a - b).mean():.5f}")
PY
python -m bench.sweep --axis light --methods neuspike-net,neuspike-net-spike,e2vid,firenet,tfi --weights "$W" \
    --device cuda --workers 1 --no-progress --no-report --out "$OUT/sweep"
python -m bench.video --duration 0.02 --methods tfp,neuspike-net,neuspike-net-spike,e2vid,firenet --weights "$W" \
    --device cuda --no-progress --out "$OUT/video"
python -m neuspike.train e2vid --quick --device cuda --out "$OUT/train-e2vid" --shard "$OUT/shard-e2vid" --quiet
