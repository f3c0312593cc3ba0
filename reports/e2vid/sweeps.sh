# The full sweeps of `e2vid` (or another recurrent event method trained here, such as
# `firenet-sim`) alone, joined into the committed reports in place of its old rows (run for stage 7):
#     bash reports/e2vid/sweeps.sh TAG [METHOD]    (TAG names the run folders: runs/full/AXIS-TAG)
# e2vid reads the same event history as the other recurrent methods, so its cells are the committed
# sweeps' cells; `bench.merge` checks that before it joins them.
set -e
TAG=${1:?give a tag for the run folders, e.g. e2vid7}
W=../shared/weights
M=${2:-e2vid}
python -m bench.sweep --axis light --full --methods $M --weights $W --out runs/full/light-$TAG --workers 2 --threads 1 --no-progress --no-report
python -m bench.sweep --axis motion --full --methods $M --weights $W --out runs/full/motion-$TAG --workers 2 --threads 1 --no-progress --no-report
python -m bench.noise --level all --full --methods $M --weights $W --out runs/full/noise-$TAG --workers 2 --threads 1 --no-progress --no-report
for a in light motion noise; do python -m bench.merge --replace reports/$a reports/$a runs/full/$a-$TAG; done
python reports/margins.py reports/light reports/motion reports/noise > reports/margins.md
echo ALLDONE
