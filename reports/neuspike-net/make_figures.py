"""Figures of the NeuSpike-Net note from its results files only (run from the repository root).

python reports/neuspike-net/make_figures.py [RUN_DIR]   (default runs/neuspike-net)

Reads RUN_DIR/train_log.csv (copied here as train_log.csv) and writes training_curve.png: the
training loss (mean over 25 steps) and the validation PSNR of the fusion network and of the
spike-only variant (the motion path silenced) against the step.
"""

import shutil
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import pandas as pd  # noqa: E402

here = Path(__file__).resolve().parent
run = Path(sys.argv[1]) if len(sys.argv) > 1 else Path("runs/neuspike-net")
if (run / "train_log.csv").exists():
    shutil.copyfile(run / "train_log.csv", here / "train_log.csv")
log = pd.read_csv(here / "train_log.csv")
train = log[log.kind == "train"]
val = log[log.kind == "val"]
fig, (a, b) = plt.subplots(1, 2, figsize=(10, 3.6))
a.plot(train.step, train.loss.rolling(25, min_periods=1).mean(), label="L1 + SSIM loss (25-step mean)")
a.set_xlabel("step")
a.set_ylabel("training loss")
a.legend()
for variant, style in (("fusion", "o-"), ("spike", "s--")):
    v = val[val.variant == variant]
    b.plot(v.step, v.val_psnr, style, label={"fusion": "neuspike-net", "spike": "neuspike-net-spike"}[variant])
b.set_xlabel("step")
b.set_ylabel("validation PSNR (dB)")
b.legend()
fig.tight_layout()
fig.savefig(here / "training_curve.png", dpi=120)
summary = val.pivot_table(index="step", columns="variant", values=["val_psnr", "val_ssim"])
summary.round(4).to_csv(here / "validation_curve.csv")
print(summary.round(3).to_string())
