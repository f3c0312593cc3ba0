"""The real spike recording through neuspike-net-spike, tfp, tfi and snm, side by side.

    python reports/neuspike-net/realdata.py [--recording ../shared/realdata/spike/uhsr_helicopter.npz]

Runs ``python -m neuspike.reconstruct`` on the recording (its centre, each method's own window),
keeps each method's PNG in ``realdata/``, writes ``realdata/measures.csv`` (normalisation, time and
the no-reference measures, :func:`neuspike.metrics.no_reference`) and ``realdata/contact_sheet.png``.
There is no ground truth: which looks better is a judgement, stated in the README.
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

METHODS = ("tfp", "tfi", "snm", "neuspike-net-spike")
HERE = Path(__file__).resolve().parent


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--recording", default=str(HERE.parents[2] / "shared" / "realdata" / "spike" / "uhsr_helicopter.npz"))
    args = p.parse_args(argv)

    import pandas as pd

    from neuspike.utils.atomic import write_text
    from neuspike.metrics import no_reference
    from neuspike.formats.images import to_uint8, write_png
    from neuspike.video.writers import label_image, tile_row

    rec = Path(args.recording)
    out = HERE / "realdata"
    out.mkdir(exist_ok=True)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        printed = subprocess.run([sys.executable, "-m", "neuspike.reconstruct", "--spikes", str(rec), "--method",
                                  ",".join(METHODS), "--out", tmp], check=True, capture_output=True, text=True).stdout
        images = {m: np.load(Path(tmp) / f"{m}.npy") for m in METHODS}
        for m in METHODS:
            shutil.copyfile(Path(tmp) / f"{m}.png", out / f"{m}.png")
    for m in METHODS:
        line = next(x for x in printed.splitlines() if x.startswith(f"{m}: wrote"))
        norm = line.split("normalisation ", 1)[1].rsplit(" ms;", 1)[0].rsplit(";", 1)[0]
        ms = float(line.rsplit(" ms;", 1)[0].rsplit(";", 1)[1])
        rows.append({"method": m, "recording": rec.name, "normalisation": norm, "ms": round(ms, 1),
                     **{k: round(float(v), 6) for k, v in no_reference(images[m]).items()}})
    sheet = tile_row([label_image(to_uint8(images[m], clip=True), m) for m in METHODS])
    write_png(out / "contact_sheet.png", sheet, clip=False)
    frame = pd.DataFrame(rows)
    write_text(out / "measures.csv", frame.to_csv(index=False, lineterminator="\n"))
    print(frame.to_string(index=False))
    return 0


if __name__ == "__main__":
    sys.exit(main())
