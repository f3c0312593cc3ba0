"""Score e2vid candidates on the selection harness (from stage 17; see harness.sh beside this file).

    python reports/e2vid/candidates/score.py RESULTS [RESULTS ...]

Each RESULTS is a sweep's ``results.csv`` (or its folder, or a ``.csv.gz`` such as this folder's
``results.csv.gz``). Prints, per method, the mean SSIM of the harness's three groups and the score:

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
"""

import sys
from pathlib import Path

import pandas as pd

from bench.results import read_csv

EXPECTED = {"photos": 16, "leaves": 32, "noisy": 36}


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


def group(row) -> str:
    if row["noise"] != "none":
        return "noisy"
    return "leaves" if "leaves-" in str(row["image"]) else "photos"


def score(d: pd.DataFrame) -> pd.DataFrame:
    d = d.assign(group=d.apply(group, axis=1))
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
    if not argv:
        print(__doc__, file=sys.stderr)
        return 2
    table = score(load(argv))
    with pd.option_context("display.float_format", "{:.4f}".format, "display.width", 120):
        print(table.to_string())
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
