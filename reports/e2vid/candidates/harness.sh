# The selection harness for e2vid candidates (from stage 17): 84 cells, none on a test photograph.
#     bash reports/e2vid/candidates/harness.sh NAME[,NAME...] [clean|noisy|leaves34|all|heldout]
# NAME is a candidate whose weights are runs/e2vid-candidates/e2vid-NAME.safetensors, or, written
# firenet-sim-NAME, one whose weights are runs/e2vid-candidates/firenet-sim-NAME.safetensors (see
# README.md beside this file); the methods are registered by variants.py. Parts:
#   clean     the 32 cells used since stage 13: 8 scenes on training photographs and 8 on the held-out
#             dead-leaves pictures 1-2, at L = 1/16 and 1/4 (S = 128, no sensor noise)
#   leaves34  16 more clean cells: the four scene kinds on held-out dead-leaves pictures 3 and 4
#   noisy     36 cells: the noise test's three levels (L = 1/4, S = 128) on the 8 training-photograph
#             scenes and 4 dead-leaves scenes
# all (the default) runs the three (score with score.py). heldout (from stage 18; score with
# score.py --heldout) runs only cells on pictures no network here trains on: the 32 clean dead-leaves
# cells, the noise test's three levels on the 4 dead-leaves scenes (12 cells), and the four kinds on the
# three flat synthetic pictures of flat.py at L = 1/16, 1/4 (24 cells). HARNESS_EXTRA (comma-separated registry names, e.g. firenet, whose
# weights must then be in runs/e2vid-candidates too) adds reference methods; HARNESS_WORKERS (default 2)
# sets the worker processes (1 thread each). Every cell is 400x250, seed 0, float32, so that scores from
# different machines compare. Results go to runs/harness-PART-NAMES; score them with
# `python reports/e2vid/candidates/score.py`.
set -e
NAMES=${1:?give candidate names, comma-separated (e.g. s17-00200)}
PART=${2:-all}
HERE=reports/e2vid/candidates
LEAVES=runs/harness-leaves
python $HERE/leaves.py $LEAVES > /dev/null
METHODS=$(echo "$NAMES" | tr ',' '\n' | sed '/^firenet-sim-/!s/^/e2vid-/' | paste -sd,)${HARNESS_EXTRA:+,$HARNESS_EXTRA}
E2VID=$(echo "$NAMES" | tr ',' '\n' | grep -v '^firenet-sim-' | paste -sd, || true)
FIRENET_SIM=$(echo "$NAMES" | tr ',' '\n' | grep '^firenet-sim-' | sed 's/^firenet-sim-//' | paste -sd, || true)
PHOTOS=pan:astronaut,zoom:brick,fan:cat,still:coffee,pan:rocket,zoom:grass,fan:page,still:cell
COMMON="--size 400x250 --seeds 0 --methods $METHODS --plugin $HERE/variants.py --weights runs/e2vid-candidates
        --cache runs/e2vid-cand-cache --workers ${HARNESS_WORKERS:-2} --threads 1 --no-progress --no-report"
export E2VID_CANDIDATES=${E2VID:-none} FIRENET_SIM_CANDIDATES=${FIRENET_SIM:-none} E2VID_PRECISION=float32
TAG=$(echo "$NAMES" | tr ',' '+')
if [ "$PART" = clean ] || [ "$PART" = all ]; then
  python -m bench.sweep --axis light --lights 1/16,1/4 $COMMON --out runs/harness-clean-$TAG \
    --scenes $PHOTOS,$(echo {pan,zoom,fan,still}:$LEAVES/leaves-{1,2}.png | tr ' ' ',')
fi
if [ "$PART" = leaves34 ] || [ "$PART" = all ]; then
  python -m bench.sweep --axis light --lights 1/16,1/4 $COMMON --out runs/harness-leaves34-$TAG \
    --scenes $(echo {pan,zoom,fan,still}:$LEAVES/leaves-{3,4}.png | tr ' ' ',')
fi
if [ "$PART" = heldout ]; then
  FLAT=runs/flat
  python $HERE/flat.py $FLAT > /dev/null
  python -m bench.sweep --axis light --lights 1/16,1/4 $COMMON --out runs/harness-heldout-clean-$TAG \
    --scenes $(echo {pan,zoom,fan,still}:$LEAVES/leaves-{1,2,3,4}.png {pan,zoom,fan,still}:$FLAT/{horse,shepp_logan_phantom,logo}.png | tr ' ' ',')
  python -m bench.noise --level all $COMMON --out runs/harness-heldout-noisy-$TAG \
    --scenes pan:$LEAVES/leaves-3.png,zoom:$LEAVES/leaves-4.png,fan:$LEAVES/leaves-1.png,still:$LEAVES/leaves-2.png
fi
if [ "$PART" = noisy ] || [ "$PART" = all ]; then
  python -m bench.noise --level all $COMMON --out runs/harness-noisy-$TAG \
    --scenes $PHOTOS,pan:$LEAVES/leaves-3.png,zoom:$LEAVES/leaves-4.png,fan:$LEAVES/leaves-1.png,still:$LEAVES/leaves-2.png
fi
