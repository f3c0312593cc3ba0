"""Training curves of the recurrent event networks from the logs kept here (run from the repository root).

python reports/e2vid/make_figures.py

Validation SSIM (8 held-out sequences of training photographs, steps after the warm-up) against the
step: ``firenet-sim``, ``e2vid`` stage 1 and stage 2 (stage 2 starts from stage 1's best weights, at
step 1,000, with 8-window sequences and a lower learning rate), and the published FireNet's score on
the same sequences for orientation. Stage 3 (from stage 2's best, at step 1,900: items cut from
400x250 views, cosine learning rate) is scored on its own 16 validation sequences, cut the same way,
so its curve is drawn on a second axis with the scores of the published FireNet and ``firenet-sim``
on those sequences (``validation_view.csv``, ``python reports/e2vid/validation.py --view 400x250``).
The third panel is the measure weights are chosen by since stage 3: the sweep harness on training
photographs (``candidates/results.csv.gz``, mean SSIM over its 16 cells) for stage 2's weights and the
snapshots of stages 5 and 6 (both from stage 2's weights), of stage 7 (from stage 6's step 200) and of
stage 8 (from stage 7's step 300; its steps are larger: batch 8 of 112-pixel crops against 4 of 48) and of
stage 9 (from stage 8's step 500), of stage 10 (from stage 9's step 400) and of stage 11 (from stage
10's step 200), with the published FireNet for orientation.
The fourth panel is the measure weights are chosen by since stage 18: the held-out harness
(``candidates/score.py --heldout``: 68 cells on pictures no network here trains on), by group, for
each stage scored on it and the published FireNet. Stages 12 to 16 were chosen on harnesses that
held training photographs; their figures are in ``README.md`` and ``candidates/README.md``.
Writes training_curves.png.
"""

import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import pandas as pd  # noqa: E402

here = Path(__file__).resolve().parent
PUBLISHED_FIRENET_VAL_SSIM = 0.347  # the published weights on the same 8 validation sequences
STAGE2_START = 1000  # the stage-1 step whose weights stage 2 starts from
STAGE3_START = 1900  # stage 2's best step (900) after stage 1's 1,000
# stage 2's weights on stage 3's sequences (validation_view.csv when stage 2 shipped; that file now
# holds the shipped stage-6 weights' score)
STAGE2_VIEW_VAL_SSIM = 0.495


def val(name: str, offset: int = 0) -> pd.DataFrame:
    log = pd.read_csv(here / name).drop_duplicates("step", keep="last")
    log = log[log.val_ssim.notna()]
    return log.assign(step=log.step + offset)


fig, ((ax, ax3), (axh, axs)) = plt.subplots(2, 2, figsize=(14, 8))
fs = val("firenet-sim_train_log.csv")
ax.plot(fs.step, fs.val_ssim, "-", label="firenet-sim, stage 1")
s1 = val("e2vid_train_log.csv")
ax.plot(s1.step, s1.val_ssim, "-", label="e2vid, stage 1 (6-window sequences, lr 5e-4)")
s2 = val("e2vid_stage2_train_log.csv", STAGE2_START)
ax.plot(s2.step, s2.val_ssim, "-", label="e2vid, stage 2 (8-window sequences, lr 2e-4)")
ax.axhline(PUBLISHED_FIRENET_VAL_SSIM, color="grey", ls=":", label="published firenet")
ax.set_xlabel("optimiser step")
ax.set_ylabel("validation SSIM")
ax.legend(fontsize=8)
ax.set_title("8 validation sequences, photographs fitted to 128x128", fontsize=9)
s3 = None
if (here / "e2vid_stage3_train_log.csv").is_file():
    s3 = val("e2vid_stage3_train_log.csv", STAGE3_START)
    start = pd.read_csv(here / "validation_view.csv").set_index("method")
    first = pd.DataFrame({"step": [STAGE3_START], "val_ssim": [STAGE2_VIEW_VAL_SSIM]})
    s3 = pd.concat([first, s3[["step", "val_ssim"]]])
    ax3.plot(s3.step, s3.val_ssim, "-o", ms=3, color="C1", label="e2vid, stage 3 (400x250 views, cosine lr; not shipped)")
    for name, style, what in (("firenet-sim", "--", "stage 1"), ("firenet", ":", "published")):
        ax3.axhline(start.loc[name, "val_ssim"], color="grey", ls=style, label=f"{name} ({what})")
    ax3.set_xlabel("optimiser step")
    ax3.set_ylabel("validation SSIM")
    ax3.set_title("16 validation sequences cut from 400x250 views", fontsize=9)
    ax3.legend(fontsize=8)
else:
    ax3.set_visible(False)
harness = pd.read_csv(here / "candidates" / "results.csv.gz")
# the 16 training-photograph cells every stage was scored on (not stage 13's added dead-leaves cells)
harness = harness[(harness.metric == "ssim") & (harness.status == "ok")
                  & ~harness.image.astype(str).str.contains("leaves-")].groupby("method")["value"].mean()
# each stage's snapshots, drawn from the weights it started from (stage 7 from stage 6's step 200)
for prefix, start, label, color in (
        ("e2vid-s5-", ("e2vid-stage2", 0), "stage 5 (16-window sequences, dead leaves)", "C3"),
        ("e2vid-s6-", ("e2vid-stage2", 0), "stage 6 (linear radiance, clean x2; shipped at 200)", "C2"),
        ("e2vid-s7-", ("e2vid-s6-00200", 200), "stage 7 (16-window linear sequences, from stage 6's 200)", "C4"),
        ("e2vid-s8-", ("e2vid-s7-00300", 500), "stage 8 (GPU: 4x the items, crop 112, batch 8)", "C5"),
        ("e2vid-s9-", ("e2vid-s8-00500", 1000), "stage 9 (half the items cut from 400x250 views; 400 shipped)", "C6"),
        ("e2vid-s10-", ("e2vid-s9-00400", 1400), "stage 10 (every window scored)", "C7"),
        ("e2vid-s11-", ("e2vid-s10-00200", 1600), "stage 11 (history term; shipped at 200)", "C8")):
    names = sorted(m for m in harness.index if m.startswith(prefix))
    steps = [start[1]] + [start[1] + int(m[len(prefix):]) for m in names]
    axh.plot(steps, [harness[start[0]]] + [harness[m] for m in names], "-o", ms=4, color=color, label=label)
axh.axhline(harness["firenet"], color="grey", ls=":", label="firenet (published)")
axh.axhline(harness["e2vid-stage3"], color="C1", ls="--", label="stage 3 (not shipped)")
axh.set_xlabel("optimiser steps after stage 2's weights")
axh.set_ylabel("harness SSIM")
axh.set_title("sweep harness on training photographs, 400x250 (16 cells)", fontsize=9)
axh.legend(fontsize=8)
sys.path.insert(0, str(here / "candidates"))
from score import load, score  # noqa: E402

held = score(load([str(here / "candidates" / f) for f in ("results.csv.gz", "flat.csv.gz")]), heldout=True)
held = held[held.note == ""]
order = sorted((m for m in held.index if m.startswith("e2vid-s")), key=lambda m: int(m.split("-")[1][1:]))
order += [m for m in ("firenet",) if m in held.index]
groups = ["leaves", "noisy_leaves", "flat", "score"]
width = 0.8 / len(order)
for i, m in enumerate(order):
    stage = "published firenet" if m == "firenet" else f"stage {m.split('-')[1][1:]} (step {int(m.split('-')[2])})"
    xs = [g + (i - (len(order) - 1) / 2) * width for g in range(len(groups))]
    bars = axs.bar(xs, [held.loc[m, g] for g in groups], width, label=stage,
                   color="grey" if m == "firenet" else f"C{i}")
    axs.bar_label(bars, fmt="%.3f", fontsize=6, rotation=90, padding=2)
axs.set_xticks(range(len(groups)), ["dead leaves (32)", "noisy dead leaves (12)", "flat pictures (24)", "score"])
axs.set_ylim(0.3, 0.7)
axs.set_ylabel("held-out harness SSIM")
axs.set_title("held-out harness, 400x250 (68 cells, pictures no network here trains on)", fontsize=9)
axs.legend(fontsize=8, loc="upper left")
fig.tight_layout()
fig.savefig(here / "training_curves.png", dpi=120)
print(f"best: firenet-sim {fs.val_ssim.max():.3f}, e2vid stage 1 {s1.val_ssim.max():.3f}, "
      f"stage 2 {s2.val_ssim.max():.3f} (step {int(s2.loc[s2.val_ssim.idxmax(), 'step'])})"
      + ("" if s3 is None else f"; stage 3 on its own sequences {s3.val_ssim.max():.3f}"))
