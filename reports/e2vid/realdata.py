"""The real event recordings through e2vid, firenet-sim and the published firenet, side by side.

    python reports/e2vid/realdata.py --weights ../shared/weights [--realdata ../shared/realdata/events]

For each recording in the folder: ``python -m neuspike.reconstruct`` with the three methods at the
recording's centre (each method's own windowing and warm-up), one panel image
``realdata_<recording>.png`` and the no-reference measures of every output in
``realdata_noreference.csv`` (noise estimate and sharpness, :func:`neuspike.metrics.no_reference`).
There is no ground truth: which looks better is a judgement, stated in the README.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

METHODS = ("firenet", "firenet-sim", "e2vid")
HERE = Path(__file__).resolve().parent
NAMES = {"pku_vidar_dvs_driving_outdoor3.hdf5": "driving", "dvxplorer_sample.aedat4": "dvxplorer"}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--weights", required=True, help="folder holding the published FireNet weights")
    p.add_argument("--realdata", default=str(HERE.parents[2] / "shared" / "realdata" / "events"),
                   help="folder of real event recordings")
    p.add_argument("--out", default=str(HERE), help="where the panels and the CSV go")
    args = p.parse_args(argv)

    import pandas as pd

    from neuspike.utils.atomic import write_text
    from neuspike.metrics import no_reference
    from neuspike.formats.images import to_uint8, write_png
    from neuspike.video.writers import label_image, tile_row

    out = Path(args.out)
    rows = []
    recordings = sorted(f for f in Path(args.realdata).iterdir() if f.name in NAMES)
    if not recordings:
        print(f"error: no known recording in {args.realdata}", file=sys.stderr)
        return 2
    for rec in recordings:
        with tempfile.TemporaryDirectory() as tmp:
            subprocess.run([sys.executable, "-m", "neuspike.reconstruct", "--events", str(rec), "--method",
                            ",".join(METHODS), "--weights", args.weights, "--out", tmp], check=True)
            images = {m: np.load(Path(tmp) / f"{m}.npy") for m in METHODS}
        # one labelled row of the methods' images (the video contact sheet's tiles)
        write_png(out / f"realdata_{NAMES[rec.name]}.png",
                  tile_row([label_image(to_uint8(images[m], clip=True), m) for m in METHODS]), clip=False)
        rows += [{"recording": rec.name, "method": m,
                  **{k: round(float(v), 6) for k, v in no_reference(images[m]).items()}} for m in METHODS]
    frame = pd.DataFrame(rows)
    write_text(out / "realdata_noreference.csv", frame.to_csv(index=False, lineterminator="\n"))
    print(frame.to_string(index=False))
    return 0


if __name__ == "__main__":
    sys.exit(main())
