"""Training curves of the recurrent event networks from the logs kept here (run from the repository root).

python reports/e2vid/make_figures.py

Validation SSIM (8 held-out sequences of training photographs, steps after the warm-up) against the
step: ``firenet-sim``, ``e2vid`` stage 1 and stage 2 (stage 2 starts from stage 1's best weights, at
step 1,000, with 8-window sequences and a lower learning rate), and the published FireNet's score on
the same sequences for orientation. Writes training_curves.png.
"""

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import pandas as pd  # noqa: E402

here = Path(__file__).resolve().parent
PUBLISHED_FIRENET_VAL_SSIM = 0.347  # the published weights on the same 8 validation sequences
STAGE2_START = 1000  # the stage-1 step whose weights stage 2 starts from


def val(name: str, offset: int = 0) -> pd.DataFrame:
    log = pd.read_csv(here / name).drop_duplicates("step", keep="last")
    log = log[log.val_ssim.notna()]
    return log.assign(step=log.step + offset)


fig, ax = plt.subplots(figsize=(7, 3.8))
fs = val("firenet-sim_train_log.csv")
ax.plot(fs.step, fs.val_ssim, "-", label="firenet-sim")
s1 = val("e2vid_train_log.csv")
ax.plot(s1.step, s1.val_ssim, "-", label="e2vid, stage 1 (6-window sequences, lr 5e-4)")
s2 = val("e2vid_stage2_train_log.csv", STAGE2_START)
ax.plot(s2.step, s2.val_ssim, "-", label="e2vid, stage 2 (8-window sequences, lr 2e-4)")
ax.axhline(PUBLISHED_FIRENET_VAL_SSIM, color="grey", ls=":", label="published firenet")
ax.set_xlabel("optimiser step")
ax.set_ylabel("validation SSIM")
ax.legend(fontsize=8)
fig.tight_layout()
fig.savefig(here / "training_curves.png", dpi=120)
print(f"best: firenet-sim {fs.val_ssim.max():.3f}, e2vid stage 1 {s1.val_ssim.max():.3f}, "
      f"stage 2 {s2.val_ssim.max():.3f} (step {int(s2.loc[s2.val_ssim.idxmax(), 'step'])})")
