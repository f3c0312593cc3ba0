"""Merge sweeps of the same cells run with different methods into one results folder.

A new method (a plug-in, a network trained further) joins an existing sweep without recomputing the
methods that did not change: run the sweep again with ``--methods NEW`` (and the same ``--cache``, so
the recordings are read, not simulated again), then merge the two folders::

    python -m bench.merge reports/light runs/light-base runs/light-new

The folders must hold the same sweep apart from its methods: the same grid (scenes, light, motion,
noise, seeds, effects), sensor, harness version and event history (the simulator is deterministic
given these, so every folder scored its methods on the same recordings). Their methods must not
overlap, and every folder must be complete (a ``results.csv`` with every cell). The output holds
``results.csv`` (sorted as a sweep's), ``config.json`` (the sweep with the union of the methods, and
``merged_from``: each folder's methods and configuration), ``metadata.json`` (the first folder's
provenance, each folder's own under ``merged_from``) and ``images/`` (every folder's saved
reconstructions side by side, so the report's grids show every method); then the report is rebuilt
from them.

With ``--replace`` the method sets may overlap: a method in a later folder replaces that method's
rows, images and place in the method list of every earlier folder (a network trained further takes
its old results' place: ``python -m bench.merge --replace reports/light reports/light runs/light-e2vid``).

``--take M1,M2`` reads only those methods from the folders after the first (with ``--replace``, the
usual way to rejoin a retrained network from a run that also computed other methods, for example to
simulate the same event history): every other method keeps the first folder's rows and images.

Writing is atomic per file; the output folder may be one of the inputs only if it is the first.

Exit status: 0 merged; 2 folders that do not fit together (the message says what differs).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any, Sequence


from neuspike.utils.atomic import write_bytes, write_json, write_text
from neuspike.errors import InputError, NeuSpikeError
from neuspike.utils.jsonio import portable_path

__all__ = ["merge_sweeps", "main"]

#: Cell identity columns: rows of two folders describe the same cell when these agree.
CELL_KEY = ("scene", "kind", "image", "width", "height", "planes", "light", "motion", "noise", "seed")

if TYPE_CHECKING:
    import pandas as pd


def _load(folder: Path) -> tuple[dict[str, Any], dict[str, Any], pd.DataFrame]:
    from bench.reporting.build import results_file

    # a committed report keeps its results gzipped (results.csv.gz), which reads as results.csv does
    paths = {name: folder / name for name in ("config.json", "metadata.json")}
    paths["results.csv"] = results_file(folder)
    missing = [str(p) for p in paths.values() if not p.is_file()]
    if missing:
        raise InputError(f"{folder}: not a finished sweep folder (missing {', '.join(missing)})")
    try:
        config = json.loads(paths["config.json"].read_text())
        metadata = json.loads(paths["metadata.json"].read_text())
    except ValueError as exc:
        raise InputError(f"{folder}: unreadable JSON ({exc})") from exc
    if "sweep" not in config:
        raise InputError(f"{folder}/config.json: no 'sweep' section (not written by bench.sweep or bench.noise)")
    from bench.harness.results import read_csv

    frame = read_csv(paths["results.csv"])
    key = [*CELL_KEY, "method", "metric"]
    repeated = frame.duplicated(key, keep=False)
    if repeated.any():
        first = frame.loc[repeated, key].iloc[0].to_dict()
        raise InputError(f"{paths['results.csv']}: {int(repeated.sum())} rows repeat a (cell, method, metric), e.g. "
                         f"{first}; a sweep writes each once")
    return config, metadata, frame


def _identity(sweep: dict[str, Any]) -> dict[str, Any]:
    """What must agree between merged folders: the sweep without its methods and weights folder.

    The device is part of it (a folder from before the device was recorded ran on the CPU); each
    method's precision travels with its rows (see :func:`merge_sweeps`).
    """
    from bench.harness.runner import LEGACY_DEVICE

    resolved = sweep.get("resolved", {})
    return {
        "name": sweep.get("name"), "axis": sweep.get("axis"), "grid": sweep.get("grid"),
        "sensor": sweep.get("sensor"), "harness_version": sweep.get("harness_version"),
        "history_s": resolved.get("history_s"), "device": sweep.get("device", LEGACY_DEVICE),
        # events are simulated for the history only when someone consumes them: the spike
        # recordings match either way, the event recordings only with the same history
        "events": "events" in resolved.get("modalities", []),
    }


def merge_sweeps(out: str | Path, folders: Sequence[str | Path], *, replace: bool = False,
                 take: Sequence[str] | None = None) -> pd.DataFrame:
    """Merge ``folders`` (see the module docstring) into ``out``; returns the merged results.

    ``replace``: a method present in several folders keeps only its last folder's rows (otherwise
    overlapping methods are an error). ``take``: the only methods read from the folders after the
    first (None: all); each must be in one of them.

    Raises
    ------
    InputError
        Fewer than two folders, a folder that is not a finished sweep, sweeps of different cells,
        overlapping methods (without ``replace``), cells missing from a folder, or a ``take`` method
        that no later folder holds.
    """
    import pandas as pd

    from bench.harness.results import sort_rows, to_csv_text

    folders = [Path(f) for f in folders]
    if len(folders) < 2:
        raise InputError("merge needs at least two sweep folders")
    out = Path(out)
    if out.resolve() in {f.resolve() for f in folders[1:]}:
        raise InputError(f"{out}: the output folder may be the first input, not a later one")
    loaded = [_load(f) for f in folders]
    if take is not None:
        take = list(dict.fromkeys(take))
        later = {m for _, _, frame in loaded[1:] for m in pd.unique(frame["method"])}
        absent = [m for m in take if m not in later]
        if absent:
            raise InputError(f"--take {','.join(absent)}: not in any folder after {folders[0]} "
                             f"(they hold {', '.join(sorted(later))})")
        loaded = [loaded[0]] + [(c, m, frame[frame["method"].isin(take)]) for c, m, frame in loaded[1:]]

    first_id = _identity(loaded[0][0]["sweep"])
    seen: dict[str, Path] = {}
    cells = None
    for folder, (config, _, frame) in zip(folders, loaded):
        ident = _identity(config["sweep"])
        if ident != first_id:
            changed = sorted(k for k in ident if ident[k] != first_id[k])
            raise InputError(f"{folder} is a different sweep from {folders[0]} (differs in: {', '.join(changed)}); "
                             "only sweeps of the same cells merge")
        for method in pd.unique(frame["method"]):
            if method in seen and not replace:
                raise InputError(f"method {method!r} is in both {seen[method]} and {folder}; merge disjoint method sets "
                                 "(or --replace to let the later folder's results take its place)")
            seen[method] = folder
        keys = set(map(tuple, frame[list(CELL_KEY)].astype(str).drop_duplicates().to_numpy()))
        if cells is None:
            cells = keys
        elif keys != cells:
            raise InputError(f"{folder} does not hold the same cells as {folders[0]} "
                             f"({len(keys ^ cells)} cells in one only); finish both sweeps first")

    # each method's rows come from the last folder that holds it (the only one without replace)
    kept = [frame[frame["method"].map(lambda m, f=folder: seen[m] == f)] for folder, (_, _, frame) in zip(folders, loaded)]
    merged = sort_rows(pd.concat(kept, ignore_index=True))
    sweep = dict(loaded[0][0]["sweep"])
    methods: list[str] = []
    for i, (c, _, _) in enumerate(loaded):
        wanted = [m for m in c["sweep"].get("methods", []) if i == 0 or take is None or m in take]
        methods += [m for m in wanted if m not in methods]
    sweep["methods"] = methods
    # the precision each kept method computed with, from the folder its rows come from
    precision = {m: p for f, (c, _, _) in zip(folders, loaded)
                 for m, p in (c["sweep"].get("precision") or {}).items() if seen.get(m) == f}
    if precision or "precision" in sweep:
        sweep["precision"] = {m: precision[m] for m in methods if m in precision}
    sources = [{"folder": portable_path(f), "methods": c["sweep"].get("methods", []), "sweep": c["sweep"],
                "execution": c.get("execution")} for f, (c, _, _) in zip(folders, loaded)]
    metadata = dict(loaded[0][1])
    metadata["merged_from"] = [{"folder": portable_path(f), **m} for f, (_, m, _) in zip(folders, loaded)]

    out.mkdir(parents=True, exist_ok=True)
    _merge_images(out / "images", [f / "images" for f in folders], [None] + [take] * (len(folders) - 1))
    write_text(out / "results.csv", to_csv_text(merged))
    write_json(out / "config.json", {"sweep": sweep, "merged_from": sources})
    write_json(out / "metadata.json", metadata)
    return merged


def _merge_images(target: Path, sources: Sequence[Path],
                  methods: Sequence[Sequence[str] | None] | None = None) -> None:
    """Copy each source's ``<scene>/<axis=value>/<method>.png`` into ``target`` (methods are disjoint;
    the ground truth ``gt.png`` is the same image in every folder, the first one's is kept); with
    ``methods``, only those methods' images of each source (None: all)."""
    for i, src in enumerate(sources):
        if not src.is_dir() or src.resolve() == target.resolve():
            continue
        wanted = None if methods is None else methods[i]
        for png in sorted(src.rglob("*.png")):
            if wanted is not None and png.stem not in wanted:
                continue
            dest = target / png.relative_to(src)
            if dest.exists() and png.name == "gt.png":
                continue
            dest.parent.mkdir(parents=True, exist_ok=True)
            write_bytes(dest, png.read_bytes())


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m bench.merge", description=__doc__.split("\n\n")[0],
                                epilog=__doc__.split("\n\n", 1)[1], formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("out", help="output folder (results.csv, config.json, metadata.json, report)")
    p.add_argument("folders", nargs="+", help="two or more finished sweep folders of the same cells")
    p.add_argument("--replace", action="store_true",
                   help="a method in a later folder replaces the same method's results in earlier ones")
    p.add_argument("--take", metavar="M1,M2", help="read only these methods from the folders after the first "
                   "(the others keep the first folder's rows and images)")
    p.add_argument("--no-report", action="store_true", help="do not rebuild the report")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        if Path(args.out).exists() and not Path(args.out).is_dir():
            raise InputError(f"OUT {args.out}: exists and is not a folder")
        take = None if args.take is None else [m for m in args.take.split(",") if m]
        merged = merge_sweeps(args.out, args.folders, replace=args.replace, take=take)
    except NeuSpikeError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(f"merged {merged['method'].nunique()} methods over "
          f"{len(merged.drop_duplicates(list(CELL_KEY)))} cells into {args.out}/results.csv")
    if not args.no_report:
        from bench.reporting.build import build_report

        print(f"report: {build_report(Path(args.out))}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
