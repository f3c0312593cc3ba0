"""One-page model cards for the networks trained here, from their JSON cards and the committed reports.

    python -m bench.reporting.cards              # writes neuspike/trained/<network>.md for every shipped network

(``python -m bench.rebuild`` runs it after the reports it reads.)

Each card says what the network is, the file and its sha256, how it was trained (the recipe and the
command, from the JSON card beside the weights: its ``training.spec`` is the spec of the last stage
and ``training.commit`` the code that ran it), its data, and its scores: the mean PSNR and SSIM over
the cells of every committed sweep and of the held-out report, beside the best rival: the method,
not trained here, with the best mean SSIM among those that read no input the network does not read. The held-out report's pictures were never trained or selected on.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

import pandas as pd

ROOT = Path(__file__).resolve().parents[2]  # the repository (bench/reporting/cards.py)
NETWORKS = ("neuspike-net", "neuspike-net-spike", "neuspike-net-lite", "neuspike-net-spike-lite", "e2vid",
            "firenet-sim")
OURS = set(NETWORKS)
#: The networks whose training history is in the tree: their campaign's folder.
CAMPAIGNS = {"neuspike-net-lite": "campaigns/neuspike-net-lite", "neuspike-net-spike-lite": "campaigns/neuspike-net-lite"}
#: The last commit whose tree holds the training history of the shipped networks, and each one's folder there.
HISTORY_COMMIT = "61a150f81431d38169df37943aa4282840d07702"
HISTORY = {"neuspike-net": "reports/neuspike-net", "neuspike-net-spike": "reports/neuspike-net",
           "e2vid": "reports/e2vid", "firenet-sim": "reports/e2vid"}
#: (label, results folder, what it holds)
REPORTS = (
    ("light sweep", "reports/light", "test photographs, L 1/32 to 1/2, S 128, no noise"),
    ("motion sweep", "reports/motion", "test photographs, S 16 to 256, L 1/4, no noise"),
    ("noise sweep", "reports/noise", "test photographs, noise small to high, L 1/4, S 128"),
    ("light x noise", "reports/light-noise", "test photographs, five light scales x four noise levels"),
    ("held-out, light x noise", "reports/heldout/light-noise", "held-out pictures, five light scales x four noise levels"),
    ("held-out, fast pans", "reports/heldout/fast-motion", "held-out pictures, pans 1x to 16x, L 1/4 and 1/16, S 256"),
)


def _means(folder: Path) -> pd.DataFrame | None:
    from bench.reporting.build import results_file

    path = results_file(folder)
    if not path.is_file():
        return None
    frame = pd.read_csv(path)
    ok = frame[(frame["status"] == "ok") & frame["metric"].isin(["psnr", "ssim"])]
    means = ok.groupby(["method", "metric"])["value"].mean().unstack("metric")
    means["inputs"] = ok.groupby("method")["inputs"].first()
    return means


def _scores(name: str, root: Path = ROOT) -> list[str]:
    rows = ["| report | what | PSNR / SSIM | best rival (by SSIM) | its PSNR / SSIM |", "|---|---|---:|---|---:|"]
    for label, folder, what in REPORTS:
        means = _means(root / folder)
        if means is None or name not in means.index:
            continue
        # the rivals: methods that are not trained here and read nothing this network does not read
        ours = set(str(means.loc[name, "inputs"]).split("+"))
        others = means.loc[[m for m in means.index
                            if m not in OURS and set(str(means.loc[m, "inputs"]).split("+")) <= ours]]
        best = others["ssim"].idxmax() if len(others) else None
        theirs = (f"{others.loc[best, 'psnr']:.2f} / {others.loc[best, 'ssim']:.3f}" if best is not None else "-")
        rows.append(f"| [{label}](../../{folder}) | {what} | {means.loc[name, 'psnr']:.2f} / "
                    f"{means.loc[name, 'ssim']:.3f} | `{best}` | {theirs} |")
    return rows


def _history_paths(text: str) -> str:
    """Paths into the training history (which left the tree) written as ``COMMIT:path``."""
    for folder in sorted(set(HISTORY.values())):
        text = text.replace(f"{folder}/", f"{HISTORY_COMMIT[:8]}:{folder}/")
    return text


def _started_from(name: str, previous: Any) -> list[str]:
    """The card's line on the file a stage started from: the file shipped before it, directly or through one
    unshipped stage (``previous.via``, whose spec the JSON card holds); none without a ``previous`` commit."""
    if not isinstance(previous, dict) or not previous.get("commit"):
        return []
    commit = previous["commit"][:12]
    shipped = f"the file shipped before it (sha256 `{previous['sha256'][:12]}...`"
    show = f"`git show {commit}:neuspike/trained/{name}.safetensors > start.safetensors`"
    via = previous.get("via")
    if not via:
        return [f"**Started from:** {shipped}), at commit `{commit}`: {show} (its card likewise), then point the "
                f"spec's `init_from` at it."]
    return [f"**Started from:** {shipped}, at commit `{commit}`: {show}) through one unshipped stage: that stage's "
            f"spec is the card's `previous.via.spec` (its `init_from` the file shipped before), its step "
            f"{via['step']:,} (sha256 `{via['sha256'][:12]}...`) is this spec's `init_from`."]


def card(name: str, root: Path = ROOT) -> str:
    meta = json.loads((root / "neuspike" / "trained" / f"{name}.json").read_text())
    training, data = meta.get("training", {}), meta.get("data", {})
    trained = str(training.get("spec", {}).get("method", name))  # the method the trainer was run for
    # the run's file of this variant (one run of a fusion network exports its spike-only variant too)
    export = f"{trained}-spike" if name.removesuffix("-lite").endswith("-spike") and trained != name else trained
    model = meta.get("model", {})
    lines = [
        f"# `{name}`: model card",
        "",
        f"**What:** `{model.get('class', '?')}` with {meta.get('parameters', 0):,} parameters "
        f"({json.dumps(model.get('params', {}), sort_keys=True)}).",
        f"**File:** `{name}.safetensors`, {meta.get('dtype', '?')}, sha256 `{meta.get('sha256', '?')}`; its JSON "
        f"card `{name}.json` holds the full training record.",
        "",
        "**Recipe:** " + (" → ".join(f"stage {s['stage']} ({s['steps']} steps)" for s in meta["stages"])
                          if meta.get("stages") else f"{training.get('step', '?')} steps")
        + f"; the last stage ran at commit `{str(training.get('commit', '?'))[:12]}` on {training.get('device', '?')} "
          f"in {training.get('precision', '?')} ({float(training.get('wall_s', 0)) / 60:.0f} min).",
        f"**Command:** `python -m neuspike.train {trained} --spec spec.json`, the spec written out of the JSON card "
        f"with `python -c \"import json; print(json.dumps(json.load(open('neuspike/trained/{name}.json'))['training']"
        f"['spec']))\" > spec.json`. A run writes into `runs/` only"
        + (f"; it trains the fusion network and its spike-only variant in the same weights and exports both (its "
           f"`{export}.safetensors` is this file)" if export != trained else "")
        + (f"; `--export` would replace the full network's files: leave it out, and copy the run's `{export}` files "
           f"to `{name}.safetensors` and `{name}.json`" if name.endswith("-lite") else "; `--export` replaces this file")
        + ".",
        *_started_from(name, meta.get("previous")),
        (f"**History:** the stages before this file (their specs, selection rules, logs and probes) left the tree; "
         f"they stay at commit `{HISTORY_COMMIT[:8]}`: `git show {HISTORY_COMMIT[:8]}:{HISTORY[name]}/README.md` "
         "(a `--depth 1` clone fetches it with `git fetch --depth 1 origin " + HISTORY_COMMIT + "`)."
         if name in HISTORY else
         f"**History:** its training campaign, its runs and what was tried: [`{CAMPAIGNS[name]}`](../../{CAMPAIGNS[name]}/README.md)."),
        f"**Data:** simulated {data.get('kind', '?')} from the training photographs "
        f"({', '.join(data.get('photos', []))})" + (f" and procedural {data['procedural']}" if data.get("procedural") else "")
        + (f" (scene kinds {', '.join(dict.fromkeys(data['kinds']))})" if data.get("kinds") else "")
        + f"; {data.get('train_items', '?')} training and {data.get('val_items', '?')} validation items. "
          "No test photograph or held-out picture is ever drawn.",
        f"**Chosen by:** {_history_paths(meta.get('selection', 'the best validation score on the training photographs'))}"
        .rstrip(".") + ".",
        "",
        "**Scores** (mean over each report's ok cells; regenerated by `python -m bench.rebuild`):",
        "",
        *_scores(name, root),
        "",
    ]
    return "\n".join(lines)


def write_cards(names: list[str] | None = None, root: Path = ROOT) -> list[Path]:
    """Write ``neuspike/trained/<network>.md`` for these networks (default: every one shipped, with its JSON card) from the
    reports under ``root``; return the paths written."""
    from neuspike.utils.atomic import write_text

    written = []
    shipped = [n for n in NETWORKS if (root / "neuspike" / "trained" / f"{n}.json").is_file()]
    for name in names or shipped:
        if name not in NETWORKS:
            raise ValueError(f"no model card for {name!r}; the networks trained here: {', '.join(NETWORKS)}")
        path = root / "neuspike" / "trained" / f"{name}.md"
        write_text(path, card(name, root))
        written.append(path)
    return written


def main(argv: list[str] | None = None) -> int:
    try:
        paths = write_cards((sys.argv[1:] if argv is None else argv) or None)
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    for path in paths:
        print(f"wrote {path.relative_to(ROOT) if path.is_relative_to(ROOT) else path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
