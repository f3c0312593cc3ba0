"""Every committed report rebuilt by one command: ``python -m bench.rebuild``.

The catalogue below (:data:`CATALOGUE`) is the one list of what ``reports/`` holds: each folder, what
it is, the command that made its results, and how it is rebuilt from them. Without ``--rerun``
nothing is simulated and no method runs: each sweep folder's tables (and, not committed, its figures
and PDF) are rebuilt from its ``results.csv.gz`` by :func:`bench.reporting.build.build_report`; then the
derived pages, in order: ``summary/`` (the light, motion and noise sweeps together), Table 2's
accuracy-versus-time join in ``timing/``, ``margins.md``, and the model cards beside the shipped
weights (``neuspike/trained/<network>.md``). The tables come out byte for byte as committed when the
results are unchanged.

``--rerun FOLDER,...`` first runs the command behind each named folder into ``runs/rebuild/`` and,
when it finishes, moves its results, config, metadata and tables into the committed folder in one
rename (the folder's own notes, such as its README, are kept), so a folder never mixes two runs.
A full rerun takes hours on two cores (``--list`` prints the commands).
"""

from __future__ import annotations

import argparse
import gzip
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

ROOT = Path(__file__).resolve().parents[1]

#: The held-out pictures' pan scenes (``neuspike/scenes/heldout.py``).
HELDOUT_SCENES = "pan:portrait,pan:terrain,pan:typeset,pan:night,pan:foliage"
HELDOUT_PHOTOS = "portrait,terrain,typeset,night,foliage"
#: How a sweep runs on the 2-core machines the committed reports were made on.
TWO_WORKERS = ("--workers", "2", "--threads", "1")


@dataclass(frozen=True)
class Entry:
    """One committed report.

    ``kind``: ``"sweep"`` (a results folder of :mod:`bench.sweep` or :mod:`bench.fast_motion`),
    ``"timing"`` (Table 2 with its accuracy join), ``"dataset"`` (:mod:`bench.dataset`), ``"derived"``
    (built from other folders: ``summary``, ``margins``, ``cards``) or ``"rerun-only"`` (outputs that
    only their command writes: video contact sheets). ``command``: the arguments after ``python``
    that made the results, with ``{out}`` and ``{weights}`` filled in at a rerun; ``None`` for the
    derived pages.
    """

    folder: str
    what: str
    kind: str
    command: tuple[str, ...] | None = None
    needs: str | None = None  # what a rerun needs beside the CPU ("cuda", "../shared/realdata")

    def argv(self, out: Path, weights: str) -> list[str]:
        assert self.command is not None
        return [a.replace("{out}", str(out)).replace("{weights}", weights) for a in self.command]


CATALOGUE: tuple[Entry, ...] = (
    Entry("light", "the paper's Figure 3: L from 1/32 to 1/2 at S = 128, test photographs (80 cells)", "sweep",
          ("-m", "bench.sweep", "--axis", "light", "--full", *TWO_WORKERS, "--weights", "{weights}", "--out", "{out}")),
    Entry("motion", "the paper's Figure 4: S from 16 to 256 at L = 1/4 (80 cells)", "sweep",
          ("-m", "bench.sweep", "--axis", "motion", "--full", *TWO_WORKERS, "--weights", "{weights}", "--out", "{out}")),
    Entry("noise", "the paper's Table 3: noise small, medium, high at L = 1/4, S = 128 (48 cells)", "sweep",
          ("-m", "bench.sweep", "--axis", "noise", "--full", *TWO_WORKERS, "--weights", "{weights}", "--out", "{out}")),
    Entry("light-noise", "the light sweep's five light scales at each noise level (320 cells)", "sweep",
          ("-m", "bench.sweep", "--axis", "light-noise", "--full", *TWO_WORKERS, "--weights", "{weights}",
           "--out", "{out}")),
    Entry("heldout/light-noise", "held-out pictures, five light scales x four noise levels (100 cells)", "sweep",
          ("-m", "bench.sweep", "--axis", "light-noise", "--scenes", HELDOUT_SCENES, "--size", "400x250",
           "--seeds", "0", *TWO_WORKERS, "--weights", "{weights}", "--out", "{out}")),
    Entry("heldout/fast-motion", "held-out pictures panned at 1x-16x the sweeps' speed (50 cells)", "sweep",
          ("-m", "bench.fast_motion", "--photos", HELDOUT_PHOTOS, "--size", "400x250", "--seeds", "0",
           *TWO_WORKERS, "--weights", "{weights}", "--out", "{out}")),
    Entry("fast-motion", "test photographs panned at 1x-16x the sweeps' speed (40 cells)", "sweep",
          ("-m", "bench.fast_motion", "--full", *TWO_WORKERS, "--weights", "{weights}", "--out", "{out}")),
    Entry("timing", "the paper's Table 2: ms per frame at four sizes, and accuracy against time", "timing",
          ("-m", "bench.timing", "--full", "--weights", "{weights}", "--repeats", "3", "--threads", "2",
           "--history-windows", "1", "--results", "reports/light", "--out", "{out}")),
    Entry("timing-gpu", "Table 2's GPU column on an NVIDIA H100", "timing",
          ("-m", "bench.timing", "--full", "--device", "cuda", "--precision", "float32", "--methods",
           "e2vid,firenet,firenet-plus,firenet-sim,neuspike-net,neuspike-net-spike", "--weights", "{weights}",
           "--results", "none", "--out", "{out}"), needs="cuda"),
    Entry("realdata", "the paper's Figures 5 and 6 on the real recordings of ../shared/realdata", "dataset",
          ("-m", "bench.dataset", "../shared/realdata", "--manifest", "reports/realdata/manifest.json",
           "--weights", "{weights}", "--threads", "1", "--out", "{out}"), needs="../shared/realdata"),
    Entry("video", "video benchmarks and contact sheets (bench, bench-full, driving, fan2600, helicopter)",
          "rerun-only", ("-m", "bench.video"),),
    Entry("summary", "the light, motion and noise sweeps in one report, every claim of the paper checked",
          "derived"),
    Entry("margins.md", "the trained networks' margins and held targets at every point", "derived"),
    Entry("cards", "the model card beside each shipped network (neuspike/trained/<network>.md)", "derived"),
)

BY_FOLDER = {e.folder: e for e in CATALOGUE}
#: The sweeps the summary joins, and those the margins page reads (in its order).
SUMMARY_SWEEPS = ("light", "motion", "noise")
MARGIN_SWEEPS = ("light", "motion", "noise", "light-noise", "heldout/light-noise")
#: What a rerun carries into the committed folder (results.csv is committed gzipped).
KEPT = ("config.json", "metadata.json", "timing.csv", "accuracy_vs_time.csv", "fast_motion.md", "fast_motion.csv",
        "support.csv", "tables")


class RebuildError(Exception):
    """A rebuild that cannot go on (names the folder and the reason)."""


def _say(message: str) -> None:
    print(message, flush=True)


# ----------------------------------------------------------------------------------------------
# Rebuilding from committed results
# ----------------------------------------------------------------------------------------------

def rebuild_sweep(folder: Path) -> None:
    """Tables (and the uncommitted figures and PDF) of one results folder, from its files alone."""
    from bench.reporting.build import build_report

    build_report(folder)


def rebuild_summary(reports: Path) -> None:
    """``summary/``: the report over the light, motion and noise results concatenated; its tables and
    the accuracy-versus-time figure are what is committed."""
    import pandas as pd

    from bench.reporting.build import build_report, results_file

    with tempfile.TemporaryDirectory(prefix="summary-") as tmp:
        work = Path(tmp)
        frames = [pd.read_csv(results_file(reports / name)) for name in SUMMARY_SWEEPS]
        pd.concat(frames).to_csv(work / "results.csv", index=False)
        shutil.copy(reports / SUMMARY_SWEEPS[0] / "metadata.json", work / "metadata.json")
        build_report(work)
        out = reports / "summary"
        _replace_tree(work / "tables", out / "tables")
        (out / "figures").mkdir(parents=True, exist_ok=True)
        for src in (work / "figures").glob("*.png"):  # accuracy_vs_time.png is tracked; git ignores the rest
            shutil.copy(src, out / "figures" / src.name)
        if (work / "report.pdf").is_file():
            shutil.copy(work / "report.pdf", out / "report.pdf")


def rebuild_timing(folder: Path, reports: Path) -> None:
    """Table 2's report; for the CPU table, its accuracy join with the light sweep first."""
    import pandas as pd

    from bench.reporting import tables as tb
    from bench.reporting.accuracy import join_accuracy
    from bench.reporting.build import build_report, read_results, results_file
    from neuspike.utils.atomic import write_text

    if folder.name == "timing":
        light = reports / "light"
        joined = join_accuracy(read_results(results_file(light)), pd.read_csv(folder / "timing.csv"), "reports/light")
        write_text(folder / "accuracy_vs_time.csv", tb.to_csv_text(joined))
    build_report(folder)


def rebuild_margins(reports: Path) -> None:
    from bench.reporting.margins import margins_markdown
    from neuspike.utils.atomic import write_text

    folders = [reports / name for name in MARGIN_SWEEPS]
    text = margins_markdown([f.relative_to(reports.parent) if f.is_relative_to(reports.parent) else f
                             for f in folders])
    write_text(reports / "margins.md", text)


def rebuild_cards(reports: Path) -> None:
    from bench.reporting.cards import write_cards

    write_cards(root=reports.parent)


def _replace_tree(src: Path, dst: Path) -> None:
    """``dst`` becomes a copy of ``src`` in one rename (the old tree removed after)."""
    staged = dst.with_name(dst.name + ".rebuild-new")
    old = dst.with_name(dst.name + ".rebuild-old")
    for leftover in (staged, old):
        if leftover.exists():
            shutil.rmtree(leftover)
    shutil.copytree(src, staged)
    if dst.exists():
        dst.rename(old)
    staged.rename(dst)
    if old.exists():
        shutil.rmtree(old)


def rebuild(entry: Entry, reports: Path) -> str:
    """Rebuild one catalogue entry from what is committed; return a one-line account."""
    folder = reports / entry.folder
    if entry.kind == "sweep" or entry.kind == "dataset":
        if not folder.is_dir():
            raise RebuildError(f"{entry.folder}: no such folder under {reports}")
        if entry.kind == "dataset" and not (folder / "results.csv").is_file():
            raise RebuildError(f"{entry.folder}: no results.csv to rebuild from")
        rebuild_sweep(folder)
        return "tables, figures and report.pdf from its results"
    if entry.kind == "timing":
        rebuild_timing(folder, reports)
        return "tables and figures from timing.csv" + (", joined with light's accuracy" if folder.name == "timing" else "")
    if entry.folder == "summary":
        rebuild_summary(reports)
        return f"one report over {', '.join(SUMMARY_SWEEPS)}"
    if entry.folder == "margins.md":
        rebuild_margins(reports)
        return f"over {', '.join(MARGIN_SWEEPS)}"
    if entry.folder == "cards":
        rebuild_cards(reports)
        return "neuspike/trained/<network>.md"
    return "nothing to rebuild from results (rerun its command: " + " ".join(entry.command or ()) + ")"


# ----------------------------------------------------------------------------------------------
# Rerunning the command behind a folder
# ----------------------------------------------------------------------------------------------

def rerun(entry: Entry, reports: Path, weights: str, work: Path) -> None:
    """Run the command behind ``entry`` into ``work/<folder>``, then carry its results into the
    committed folder in one rename."""
    if entry.command is None or entry.kind in ("derived", "rerun-only"):
        raise RebuildError(f"{entry.folder}: nothing to rerun here ({entry.kind}: "
                           + ("rebuilt from the other folders" if entry.kind == "derived" else
                              "run its README's command") + ")")
    if entry.needs == "cuda":
        import torch

        if not torch.cuda.is_available():
            raise RebuildError(f"{entry.folder}: its command needs a CUDA device and none is here")
    elif entry.needs and not (ROOT / entry.needs).exists():
        raise RebuildError(f"{entry.folder}: its command reads {entry.needs}, which is not here")
    out = work / entry.folder
    if out.exists():
        shutil.rmtree(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    argv = [sys.executable, *entry.argv(out, weights)]
    _say(f"{entry.folder}: running {' '.join(argv[1:])}")
    start = time.monotonic()
    done = subprocess.run(argv, cwd=ROOT)
    if done.returncode != 0:
        raise RebuildError(f"{entry.folder}: its command exited with {done.returncode}; the committed folder is "
                           f"unchanged (the partial run is in {out})")
    _say(f"{entry.folder}: ran in {(time.monotonic() - start) / 60:.1f} min")
    target = reports / entry.folder
    staged = target.with_name(target.name + ".rebuild-new")
    if staged.exists():
        shutil.rmtree(staged)
    # the folder's own notes (README, manifest, ...) stay; what the run wrote replaces the rest
    if target.is_dir():
        # at the folder's top only: a subfolder of notes (another machine's timing.csv and metadata.json) stays whole
        run_names = shutil.ignore_patterns("figures", "images", "report.pdf", "results.csv*", *KEPT)

        def from_the_run(folder: str, names: list[str]) -> set[str]:
            return run_names(folder, names) if Path(folder) == target else set()

        shutil.copytree(target, staged, ignore=from_the_run)
    else:
        staged.mkdir(parents=True)
    for name in KEPT:
        src = out / name
        if src.is_dir():
            shutil.copytree(src, staged / name)
        elif src.is_file():
            shutil.copy(src, staged / name)
    # figures the folder holds that its results cannot rebuild (a dataset's contact sheets need the run's
    # images): each is carried over, replaced by the run's own version where the run drew it again
    if (target / "figures").is_dir():
        (staged / "figures").mkdir(exist_ok=True)
        for figure in sorted((target / "figures").iterdir()):
            fresh = out / "figures" / figure.name
            shutil.copy(fresh if fresh.is_file() else figure, staged / "figures" / figure.name)
    if (out / "results.csv").is_file():
        gzipped = entry.kind != "dataset"
        if gzipped:
            with open(out / "results.csv", "rb") as raw, gzip.GzipFile(staged / "results.csv.gz", "wb", mtime=0) as gz:
                shutil.copyfileobj(raw, gz)
        else:
            shutil.copy(out / "results.csv", staged / "results.csv")
    old = target.with_name(target.name + ".rebuild-old")
    if old.exists():
        shutil.rmtree(old)
    if target.exists():
        target.rename(old)
    staged.rename(target)
    if old.exists():
        shutil.rmtree(old)


# ----------------------------------------------------------------------------------------------
# Command line
# ----------------------------------------------------------------------------------------------

def _names(text: str | None, *, what: str) -> list[Entry]:
    if text is None:
        return []
    names = [n.strip().strip("/") for n in text.split(",") if n.strip()]
    if not names:
        raise RebuildError(f"{what}: expected folder names, got {text!r}")
    unknown = [n for n in names if n not in BY_FOLDER]
    if unknown:
        raise RebuildError(f"{what}: unknown {unknown}; the catalogue: {', '.join(BY_FOLDER)}")
    return [BY_FOLDER[n] for n in names]


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m bench.rebuild",
        description="Rebuild every committed report under reports/ from its committed results (tables; figures and "
        "PDFs beside them, not committed), then the summary, Table 2's accuracy join, margins.md and the model "
        "cards. With --rerun, first run the commands behind the named folders (hours on two cores).",
        epilog="examples:\n  python -m bench.rebuild --list\n  python -m bench.rebuild\n"
        "  python -m bench.rebuild --only light,summary,margins.md\n"
        "  python -m bench.rebuild --rerun light-noise,heldout/light-noise --weights ../shared/weights",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--list", action="store_true", help="print every folder, what it is and its command, and stop")
    p.add_argument("--only", metavar="F1,F2", help="rebuild only these catalogue entries (default: all, in order)")
    p.add_argument("--rerun", metavar="F1,F2",
                   help="rerun the commands behind these folders first, then rebuild everything derived from them")
    p.add_argument("--weights", default="../shared/weights",
                   help="published weights folder for a rerun (FireNet's; default ../shared/weights)")
    p.add_argument("--work", default="runs/rebuild", help="where reruns write before their results are carried "
                   "into reports/ (default runs/rebuild)")
    p.add_argument("--reports", default=str(ROOT / "reports"), help=argparse.SUPPRESS)
    return p


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    reports = Path(args.reports).resolve()
    if args.list:
        for e in CATALOGUE:
            cmd = ("python " + " ".join(e.argv(Path("runs/rebuild") / e.folder, "WEIGHTS"))) if e.command else \
                "rebuilt from the folders above"
            _say(f"{e.folder:22s} {e.what}\n{'':22s} {cmd}")
        return 0
    try:
        reruns = _names(args.rerun, what="--rerun")
        chosen = _names(args.only, what="--only") or list(CATALOGUE)
        if reruns and not args.only:
            # a rerun rebuilds itself and whatever is derived from the sweeps
            chosen = [e for e in CATALOGUE if e in reruns or e.kind == "derived"]
        if reruns and "{weights}" in " ".join(a for e in reruns for a in (e.command or ())) \
                and not Path(args.weights).is_dir():
            raise RebuildError(f"--weights: {args.weights} is not a folder (the published FireNet weights a rerun "
                               "reads)")
        for entry in reruns:
            rerun(entry, reports, args.weights, Path(args.work))
        for entry in chosen:
            start = time.monotonic()
            account = rebuild(entry, reports)
            _say(f"{entry.folder}: {account} ({time.monotonic() - start:.0f} s)")
    except (RebuildError, FileNotFoundError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
