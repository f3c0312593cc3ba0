set -e
W=../shared/weights
M=neuspike-net,neuspike-net-spike,firenet-sim
python -m bench.sweep --axis light --full --methods $M --weights $W --out runs/full/light-nsn4 --workers 2 --threads 1 --no-progress --no-report
python -m bench.sweep --axis motion --full --methods $M --weights $W --out runs/full/motion-nsn4 --workers 2 --threads 1 --no-progress --no-report
python -m bench.noise --level all --full --methods $M --weights $W --out runs/full/noise-nsn4 --workers 2 --threads 1 --no-progress --no-report
python -m bench.fast_motion --full --methods tfp-w8,tfp-w16,tfp-w32,tfp-w64,tfp,tfi,snm,neuspike-net,neuspike-net-spike --weights $W --out runs/full/fast-motion --workers 2 --threads 1 --no-progress
echo ALLDONE
