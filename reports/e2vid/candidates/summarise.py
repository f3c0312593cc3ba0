"""The table of README.md beside this file: mean PSNR and SSIM per candidate, SSIM per scene kind.

    python reports/e2vid/candidates/summarise.py [RESULTS.csv ...]

Reads the harness results (default: ``results.csv.gz`` beside this file, the candidates' validation
sweeps concatenated) and prints a Markdown table, best mean SSIM last.
"""

import sys
from pathlib import Path

import pandas as pd


def table(frame: pd.DataFrame) -> str:
    """Columns over the training-photograph cells (as every stage was scored); from stage 13 also the
    held-out dead-leaves cells (images named ``leaves-*``) and all cells together, best-first by the
    latter where a method has both."""
    ok = frame[frame["status"] == "ok"]
    leaves = ok["image"].astype(str).str.contains("leaves-")
    ssim_all = ok[ok["metric"] == "ssim"]
    ssim = ssim_all[~leaves[ssim_all.index]]
    on_leaves = ssim_all[leaves[ssim_all.index]].groupby("method")["value"].mean()
    psnr = ok[(ok["metric"] == "psnr") & ~leaves].groupby("method")["value"].mean()
    by_kind = ssim.pivot_table(index="method", columns="kind", values="value")
    mean = ssim.groupby("method")["value"].mean()
    both = ssim_all.groupby("method")["value"].mean()
    order = sorted(mean.index, key=lambda m: (m in on_leaves.index, both[m] if m in on_leaves.index else mean[m]))
    kinds = list(by_kind.columns)
    lines = ["| method | cells | PSNR | SSIM | " + " | ".join(f"SSIM {k}" for k in kinds)
             + " | SSIM dead leaves | SSIM all |",
             "|---|---:|---:|---:|" + "---:|" * len(kinds) + "---:|---:|"]
    for method in order:
        cells = int((ssim["method"] == method).sum())
        extra = (f" | {on_leaves[method]:.3f} | {both[method]:.3f} |" if method in on_leaves.index else " | | |")
        lines.append(f"| `{method}` | {cells} | {psnr[method]:.2f} | {mean[method]:.3f} | "
                     + " | ".join(f"{by_kind.loc[method, k]:.3f}" for k in kinds) + extra)
    return "\n".join(lines)


def main(argv: list[str]) -> int:
    paths = [Path(p) for p in argv] or [Path(__file__).with_name("results.csv.gz")]
    print(table(pd.concat([pd.read_csv(p) for p in paths], ignore_index=True)))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
