"""Figures of the NeuSpike-Net note from its results files only (run from the repository root).

python reports/neuspike-net/make_figures.py

Reads the training logs of the three stages kept here (``train_log.csv``, ``train_log_stage2.csv``,
``train_log_stage3.csv``; each stage starts from the previous stage's best weights) and writes
training_curve.png: the training loss (mean over 25 steps) and the validation PSNR of the fusion
network and of the spike-only variant (the motion path silenced) against the step counted across
the stages, and validation_curve.csv, the validation rows in one table.
"""

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import pandas as pd  # noqa: E402

here = Path(__file__).resolve().parent
STAGES = ("train_log.csv", "train_log_stage2.csv", "train_log_stage3.csv")

logs, offset = [], 0
for stage, name in enumerate(STAGES, start=1):
    path = here / name
    if not path.exists():
        continue
    log = pd.read_csv(path)
    log = log.assign(stage=stage, total_step=log.step + offset)
    offset += int(log.step.max())
    logs.append(log)
log = pd.concat(logs, ignore_index=True)
train = log[log.kind == "train"]
val = log[log.kind == "val"]
fig, (a, b) = plt.subplots(1, 2, figsize=(10, 3.6))
a.plot(train.total_step, train.loss.rolling(25, min_periods=1).mean(), label="L1 + SSIM loss (25-step mean)")
a.set_xlabel("step (all stages)")
a.set_ylabel("training loss")
a.legend()
for variant, style in (("fusion", "o-"), ("spike", "s--")):
    v = val[val.variant == variant]
    b.plot(v.total_step, v.val_psnr, style, label={"fusion": "neuspike-net", "spike": "neuspike-net-spike"}[variant])
for s in sorted(log.stage.unique())[1:]:
    start = log[log.stage == s].total_step.min()
    for ax in (a, b):
        ax.axvline(start, color="grey", lw=0.8, ls=":")
b.set_xlabel("step (all stages; dotted: a stage starts from the previous best)")
b.set_ylabel("validation PSNR (dB)")
b.legend()
fig.tight_layout()
fig.savefig(here / "training_curve.png", dpi=120)
summary = val.pivot_table(index=["stage", "step"], columns="variant", values=["val_psnr", "val_ssim"])
summary.round(4).to_csv(here / "validation_curve.csv")
print(summary.round(3).to_string())
