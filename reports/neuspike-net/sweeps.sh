# The full sweeps of the NeuSpike-Net variants, merged into the committed reports (run for stages 4 to 6):
#     bash reports/neuspike-net/sweeps.sh TAG     (TAG names the run folders: runs/full/AXIS-TAG)
#     WORKERS=1 bash reports/neuspike-net/sweeps.sh TAG   (beside another job that holds one core)
# firenet-sim is included so that the same event history is simulated as in the committed sweeps; only
# the two NeuSpike-Net variants are joined (--take), so the committed firenet-sim rows stay as they were.
set -e
TAG=${1:?give a tag for the run folders, e.g. nsn6}
W=../shared/weights
WORKERS=${WORKERS:-2}   # worker processes of one thread each (1 when another job holds a core)
M=neuspike-net,neuspike-net-spike,firenet-sim
python -m bench.sweep --axis light --full --methods $M --weights $W --out runs/full/light-$TAG --workers $WORKERS --threads 1 --no-progress --no-report
python -m bench.sweep --axis motion --full --methods $M --weights $W --out runs/full/motion-$TAG --workers $WORKERS --threads 1 --no-progress --no-report
python -m bench.noise --level all --full --methods $M --weights $W --out runs/full/noise-$TAG --workers $WORKERS --threads 1 --no-progress --no-report
python -m bench.fast_motion --full --methods tfp-w8,tfp-w16,tfp-w32,tfp-w64,tfp,tfi,snm,neuspike-net,neuspike-net-spike --weights $W --out runs/full/fast-motion-$TAG --workers $WORKERS --threads 1 --no-progress
for a in light motion noise; do
    python -m bench.merge --replace --take neuspike-net,neuspike-net-spike reports/$a reports/$a runs/full/$a-$TAG
done
python reports/margins.py reports/light reports/motion reports/noise > reports/margins.md
echo ALLDONE
