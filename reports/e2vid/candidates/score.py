"""Score e2vid candidates on the selection harness (from stage 17; see harness.sh beside this file).

    python reports/e2vid/candidates/score.py [--heldout] RESULTS [RESULTS ...]

Each RESULTS is a sweep's ``results.csv`` (or its folder, or a ``.csv.gz`` such as this folder's
``results.csv.gz`` and ``flat.csv.gz``). Prints, per method, the mean SSIM of the harness's three
groups and the score. The 84-cell harness of stages 17 (the default):

- ``photos``: clean cells on the training photographs (16 cells);
- ``leaves``: clean cells on the held-out dead-leaves pictures (32 cells: pictures 1-4);
- ``noisy``: the noise test's three levels on 8 photograph and 4 dead-leaves scenes (36 cells);
- ``score``: the mean of the three group means, so that clean photographs, flat regions and sensor
  noise weigh the same whatever their cell counts (the test sweeps are two clean sweeps and one noisy
  one over photographs with both textures and large flat regions).

A method with fewer cells than a complete harness in some group is marked ``incomplete``: its score is
not comparable. Rows repeated across files (the same scene, size, light, motion, noise, seed and
method) count once, the last file's row kept: the same condition scored on two machines agrees to
about 1e-7 in float32.

``--heldout`` scores the held-out harness of stage 18 (``harness.sh NAMES heldout``: no picture any
network here trains on), again the mean of three group means:

- ``leaves``: the 32 clean cells on the held-out dead-leaves pictures, as above;
- ``noisy_leaves``: the noise test's three levels on the 4 dead-leaves scenes (12 cells);
- ``flat``: the four scene kinds on the three flat synthetic pictures of ``flat.py`` at L = 1/16 and
  1/4 (24 cells), which no network here trains on and no test sweep scores.
"""

import sys
from pathlib import Path

import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent))
from flat import NAMES as FLAT_NAMES  # noqa: E402

from bench.results import read_csv

EXPECTED = {"photos": 16, "leaves": 32, "noisy": 36}
EXPECTED_HELDOUT = {"leaves": 32, "noisy_leaves": 12, "flat": 24}


def load(paths: list[str]) -> pd.DataFrame:
    frames = []
    for p in map(Path, paths):
        if p.is_dir():
            p = p / "results.csv"
        frames.append(read_csv(p))
    d = pd.concat(frames, ignore_index=True)
    d = d[(d.metric == "ssim") & (d.status == "ok")]
    # a cell's id also hashes where and how it ran, so the same condition is matched on what it is
    return d.drop_duplicates(subset=["scene", "width", "height", "light", "motion", "noise", "seed", "method"],
                             keep="last")


def picture(row) -> str:
    """``leaves``, ``flat`` or ``photos``: what a cell's picture is."""
    image = str(row["image"])
    if "leaves-" in image:
        return "leaves"
    return "flat" if Path(image).stem in FLAT_NAMES else "photos"


def group(row) -> str:
    """The cell's group in the 84-cell harness (``flat`` cells belong to none of its groups)."""
    kind = picture(row)
    if kind == "flat":
        return "flat"
    return "noisy" if row["noise"] != "none" else kind


def group_heldout(row) -> str:
    """The cell's group in the held-out harness (photograph cells belong to none of its groups)."""
    kind = picture(row)
    if row["noise"] != "none":
        return "noisy_leaves" if kind == "leaves" else "noisy_photos"
    return kind


def score(d: pd.DataFrame, heldout: bool = False) -> pd.DataFrame:
    EXPECTED = EXPECTED_HELDOUT if heldout else globals()["EXPECTED"]
    d = d.assign(group=d.apply(group_heldout if heldout else group, axis=1))
    d = d[d.group.isin(list(EXPECTED))]
    means = d.pivot_table(index="method", columns="group", values="value", aggfunc="mean")
    counts = d.pivot_table(index="method", columns="group", values="value", aggfunc="count")
    means = means.reindex(columns=list(EXPECTED))
    counts = counts.reindex(columns=list(EXPECTED)).fillna(0).astype(int)
    means["score"] = means[list(EXPECTED)].mean(axis=1, skipna=False)
    complete = (counts >= pd.Series(EXPECTED)).all(axis=1)
    means["cells"] = counts.sum(axis=1)
    means["note"] = ["" if ok else "incomplete" for ok in complete]
    return means.sort_values("score", ascending=False)


def main(argv: list[str]) -> int:
    if {"-h", "--help"} & set(argv):
        print(__doc__)
        return 0
    heldout = "--heldout" in argv
    argv = [a for a in argv if a != "--heldout"]
    unknown = [a for a in argv if a.startswith("-")]
    if unknown or not argv:
        print(__doc__, file=sys.stderr)
        if unknown:
            print(f"error: unknown option(s) {' '.join(unknown)}", file=sys.stderr)
        return 2
    table = score(load(argv), heldout=heldout)
    with pd.option_context("display.float_format", "{:.4f}".format, "display.width", 120):
        print(table.to_string())
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
