# The full sweeps of the NeuSpike-Net variants, merged into the committed reports (run for stages 4 and 5).
# firenet-sim is included so that the same event history is simulated as in the committed sweeps.
set -e
W=../shared/weights
M=neuspike-net,neuspike-net-spike,firenet-sim
python -m bench.sweep --axis light --full --methods $M --weights $W --out runs/full/light-nsn4 --workers 2 --threads 1 --no-progress --no-report
python -m bench.sweep --axis motion --full --methods $M --weights $W --out runs/full/motion-nsn4 --workers 2 --threads 1 --no-progress --no-report
python -m bench.noise --level all --full --methods $M --weights $W --out runs/full/noise-nsn4 --workers 2 --threads 1 --no-progress --no-report
python -m bench.fast_motion --full --methods tfp-w8,tfp-w16,tfp-w32,tfp-w64,tfp,tfi,snm,neuspike-net,neuspike-net-spike --weights $W --out runs/full/fast-motion --workers 2 --threads 1 --no-progress
for a in light motion noise; do python -m bench.merge --replace reports/$a reports/$a runs/full/$a-nsn4; done
python reports/margins.py reports/light reports/motion reports/noise > reports/margins.md
echo ALLDONE
