"""The table of README.md beside this file: mean PSNR and SSIM per candidate, SSIM per scene kind.

    python reports/e2vid/candidates/summarise.py [RESULTS.csv ...]

Reads the harness results (default: ``results.csv`` beside this file, the candidates' validation
sweeps concatenated) and prints a Markdown table, best mean SSIM last.
"""

import sys
from pathlib import Path

import pandas as pd


def table(frame: pd.DataFrame) -> str:
    ok = frame[frame["status"] == "ok"]
    ssim = ok[ok["metric"] == "ssim"]
    psnr = ok[ok["metric"] == "psnr"].groupby("method")["value"].mean()
    by_kind = ssim.pivot_table(index="method", columns="kind", values="value")
    mean = ssim.groupby("method")["value"].mean().sort_values()
    kinds = list(by_kind.columns)
    lines = ["| method | cells | PSNR | SSIM | " + " | ".join(f"SSIM {k}" for k in kinds) + " |",
             "|---|---:|---:|---:|" + "---:|" * len(kinds)]
    for method, value in mean.items():
        cells = int((ssim["method"] == method).sum())
        lines.append(f"| `{method}` | {cells} | {psnr[method]:.2f} | {value:.3f} | "
                     + " | ".join(f"{by_kind.loc[method, k]:.3f}" for k in kinds) + " |")
    return "\n".join(lines)


def main(argv: list[str]) -> int:
    paths = [Path(p) for p in argv] or [Path(__file__).with_name("results.csv")]
    print(table(pd.concat([pd.read_csv(p) for p in paths], ignore_index=True)))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
