"""The paper's statements about its Figures 3 and 4 and Table 3, checked against our numbers.

Each claim (from the paper's discussion of those figures and that table) is a small function over the long results DataFrame
(:mod:`bench.harness.results`) that returns ``(status, evidence)``: ``status`` is one of
:data:`HOLDS`, :data:`FAILS` or :data:`UNCHECKED` ("cannot check": the axis or the methods the
claim needs are not in the results), and ``evidence`` gives the numbers the verdict rests on.

Common rules
    * Numbers are mean PSNR (dB) over scenes and seeds of the ok rows at each axis value
      (:func:`bench.reporting.tables.axis_means`).
    * Families come from the methods' inputs (:func:`bench.reporting.tables.method_families`): *spike* methods
      consume spikes only, *event* methods events only, *fusion* methods both. TFP variants are the
      methods named ``tfp`` or ``tfp-*``; TFI is ``tfi``; SNM is ``snm``.
    * "Rises with the axis" means: the value at the largest axis value exceeds the value at the
      smallest, and the Spearman rank correlation between axis value and value is positive (both,
      so that one end point alone cannot decide). "Falls" is the mirror image. For a family the curve
      is the mean of its members' curves over the axis values where every member has a value; the
      evidence also says how many members agree on their own.
    * "Much less sensitive" (light): the median PSNR range over L of the spike methods is more than
      :data:`MUCH_LESS_FACTOR` times that of the event methods.

The thresholds are choices of this project, stated here and in each claim's ``test`` text, so a
reader can disagree with a verdict by reading its numbers.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np
import pandas as pd

from bench.harness.results import method_descriptions, tfp_windows

#: The ``implementation`` of the NeuSpike-Net methods in their description.
NEUSPIKE_NET_IMPLEMENTATION = "neuspike.nets.method.NeuSpikeNetMethod"
from bench.reporting.tables import axis_label, axis_means, method_families, ok_rows, swept_axes
from neuspike.errors import one_line

HOLDS = "holds"
FAILS = "does not hold"
UNCHECKED = "cannot check"
STATUSES = (HOLDS, FAILS, UNCHECKED)
#: Spike methods' median PSNR range over L must exceed this multiple of the event methods'.
MUCH_LESS_FACTOR = 2.0
#: Event methods "fail to recover static texture" when their mean static-texture correlation is
#: below this fraction of the spike methods' mean.
STATIC_TEXTURE_FACTOR = 0.5

Verdict = tuple[str, str]


@dataclass(frozen=True)
class Claim:
    """A statement of the paper and the function that checks it.

    ``key`` names it; ``statement`` is the paper's claim; ``test`` says how it is checked;
    ``figure`` the axis whose figure shows it (``"light"``, ``"motion"``, ``"noise"`` or ``""``).
    """

    key: str
    statement: str
    test: str
    figure: str
    check: Callable[[pd.DataFrame], Verdict]


# ----------------------------------------------------------------------------------------------
# Helpers over curves
# ----------------------------------------------------------------------------------------------

def spearman(x: Sequence[float], y: Sequence[float]) -> float:
    """Spearman rank correlation of two sequences (ties share their mean rank); 0 when either is constant."""
    xr = pd.Series(np.asarray(x, dtype=np.float64)).rank().to_numpy()
    yr = pd.Series(np.asarray(y, dtype=np.float64)).rank().to_numpy()
    if len(xr) < 2 or np.ptp(xr) == 0 or np.ptp(yr) == 0:
        return 0.0
    xc, yc = xr - xr.mean(), yr - yr.mean()
    return float((xc * yc).sum() / math.sqrt((xc * xc).sum() * (yc * yc).sum()))


def _rank_positions(values: Sequence) -> list[float]:
    return [float(i) for i in range(len(values))]


def trend(curve: pd.Series) -> tuple[float, float]:
    """``(last - first, Spearman rho)`` of a curve indexed by axis values in order (NaNs dropped)."""
    c = curve.dropna()
    if len(c) < 2:
        return math.nan, math.nan
    return float(c.iloc[-1] - c.iloc[0]), spearman(_rank_positions(c.index), c.to_numpy())


def rises(curve: pd.Series) -> bool:
    delta, rho = trend(curve)
    return bool(delta > 0 and rho > 0)


def falls(curve: pd.Series) -> bool:
    delta, rho = trend(curve)
    return bool(delta < 0 and rho < 0)


def _members(frame: pd.DataFrame, names: Sequence[str], axis: str, metric: str = "psnr") -> pd.DataFrame:
    """Curves (rows = methods, columns = axis values) of those ``names`` with >= 2 axis values."""
    wide = axis_means(frame, axis, metric)
    if wide.empty:
        return wide
    wide = wide.loc[[m for m in names if m in wide.index]]
    return wide[wide.notna().sum(axis=1) >= 2]


def _family_curve(curves: pd.DataFrame) -> pd.Series:
    """Mean of the members' curves over the axis values where every member has a value."""
    complete = curves.dropna(axis=1, how="any")
    return complete.mean(axis=0)


def _curve_text(axis: str, curve: pd.Series) -> str:
    return ", ".join(f"{axis_label(axis, v)}: {curve[v]:.2f}" for v in curve.index if not pd.isna(curve[v]))


def _axis_ready(frame: pd.DataFrame, axis: str) -> str | None:
    """``None`` when ``axis`` is swept in ``frame``; else the reason it cannot be checked."""
    if axis in swept_axes(frame):
        return None
    if axis in frame.columns and frame[axis].nunique() == 1:
        return f"the results hold one {axis} value ({axis_label(axis, frame[axis].iloc[0])}); the claim needs a {axis} sweep"
    return f"the results have no {axis} axis"


def _tfp_names(frame: pd.DataFrame) -> list[str]:
    """The TFP methods of ``frame``, known by their implementation (not their names), sorted."""
    return sorted(tfp_windows(frame))


def _widest_tfp(frame: pd.DataFrame) -> str | None:
    """The TFP method with the widest window (the whole window counts as widest), by its parameters."""
    windows = tfp_windows(frame)
    return max(sorted(windows), key=lambda m: windows[m]) if windows else None


def _family_names(frame: pd.DataFrame, family: str) -> list[str]:
    fam = method_families(frame)
    ok = set(ok_rows(frame)["method"])
    return sorted(m for m, f in fam.items() if f == family and m in ok)


def _trend_claim(frame: pd.DataFrame, names: Sequence[str], label: str, axis: str, direction: str) -> Verdict:
    """A family (or method set) rises / falls along ``axis`` (see the module docstring)."""
    reason = _axis_ready(frame, axis)
    if reason:
        return UNCHECKED, reason
    curves = _members(frame, names, axis)
    if curves.empty:
        return UNCHECKED, f"no {label} method with ok results at two or more {axis} values"
    curve = _family_curve(curves)
    if len(curve) < 2:
        return UNCHECKED, f"the {label} methods share fewer than two {axis} values with ok results"
    test = rises if direction == "rises" else falls
    agree = [m for m in curves.index if test(curves.loc[m])]
    delta, rho = trend(curve)
    lo, hi = axis_label(axis, curve.index[0]), axis_label(axis, curve.index[-1])
    members = "; ".join(f"{m} {trend(curves.loc[m])[0]:+.2f} dB" for m in curves.index)
    text = (f"{label} mean PSNR from {axis} {lo} to {hi}: {curve.iloc[0]:.2f} -> {curve.iloc[-1]:.2f} dB "
            f"({delta:+.2f} dB, Spearman {rho:+.2f}); {len(agree)} of {len(curves)} {direction.removesuffix('s')} "
            f"on their own ({members})")
    return (HOLDS if test(curve) else FAILS), text


# ----------------------------------------------------------------------------------------------
# The claims
# ----------------------------------------------------------------------------------------------

def spike_light_sensitive(frame: pd.DataFrame) -> Verdict:
    """Spike methods are sensitive to light, event methods much less."""
    reason = _axis_ready(frame, "light")
    if reason:
        return UNCHECKED, reason
    spike = _members(frame, _family_names(frame, "spike"), "light")
    event = _members(frame, _family_names(frame, "event"), "light")
    missing = [f for f, c in (("spike", spike), ("event", event)) if c.empty]
    if missing:
        return UNCHECKED, f"no {' or '.join(missing)} method with ok results at two or more light values"
    s_rng = (spike.max(axis=1) - spike.min(axis=1))
    e_rng = (event.max(axis=1) - event.min(axis=1))
    s_med, e_med = float(s_rng.median()), float(e_rng.median())
    holds = s_med > MUCH_LESS_FACTOR * e_med
    ratio = f"{s_med / e_med:.1f}x" if e_med > 0 else "inf"
    text = (f"PSNR range over L: spike methods median {s_med:.2f} dB ("
            + ", ".join(f"{m} {v:.2f}" for m, v in s_rng.items())
            + f"); event methods median {e_med:.2f} dB ("
            + ", ".join(f"{m} {v:.2f}" for m, v in e_rng.items())
            + f"); ratio {ratio} (holds above {MUCH_LESS_FACTOR:g}x)")
    return (HOLDS if holds else FAILS), text


def events_miss_static_texture(frame: pd.DataFrame) -> Verdict:
    """Event methods fail to recover static background texture: the static-texture measure decides.

    PSNR and SSIM cannot (a uniform image can outscore a noisy textured one), so each cell also
    scores ``static_texture``: the correlation of gradient magnitudes with the ground truth over
    the pixels that never change while the cameras look (:func:`neuspike.metrics.static_texture`;
    still scenes everywhere, fan scenes outside the blades). The claim holds when the event
    family's mean is below :data:`STATIC_TEXTURE_FACTOR` times the spike family's.
    """
    rows = ok_rows(frame, "static_texture")  # ok rows with a value: cells without a static region drop out
    if rows.empty:
        return UNCHECKED, ("no static-texture values: the results hold no scene with a static region "
                           "(still or fan scenes) or predate the measure")
    fam = method_families(frame)
    means = rows.groupby("method")["value"].mean()
    spike = means[[m for m in means.index if fam.get(m) == "spike"]]
    event = means[[m for m in means.index if fam.get(m) == "event"]]
    missing = [f for f, v in (("spike", spike), ("event", event)) if not len(v)]
    if missing:
        return UNCHECKED, f"no {' or '.join(missing)} method with static-texture values"
    s_mean, e_mean = float(spike.mean()), float(event.mean())
    n_cells = rows.drop_duplicates([c for c in ("scene", "light", "motion", "noise", "seed") if c in rows]).shape[0]
    text = (f"gradient correlation over static regions ({n_cells} cells): event methods mean {e_mean:.3f} ("
            + ", ".join(f"{m} {v:.3f}" for m, v in event.items())
            + f"); spike methods mean {s_mean:.3f} (" + ", ".join(f"{m} {v:.3f}" for m, v in spike.items())
            + f"); holds below {STATIC_TEXTURE_FACTOR:g}x the spike mean ({STATIC_TEXTURE_FACTOR * s_mean:.3f})")
    return (HOLDS if e_mean < STATIC_TEXTURE_FACTOR * s_mean else FAILS), text


def tfp_noisy_low_light(frame: pd.DataFrame) -> Verdict:
    """TFP is noisy at low light: its PSNR rises with L."""
    names = _tfp_names(frame)
    if not names:
        return UNCHECKED, "no TFP method (tfp, tfp-*) in the results"
    return _trend_claim(frame, names, "TFP", "light", "rises")


def tfp_blurs_large_motion(frame: pd.DataFrame) -> Verdict:
    """TFP blurs at large motion: its PSNR falls as S grows."""
    names = _tfp_names(frame)
    if not names:
        return UNCHECKED, "no TFP method (tfp, tfp-*) in the results"
    return _trend_claim(frame, names, "TFP", "motion", "falls")


def tfi_noisy_high_light(frame: pd.DataFrame) -> Verdict:
    """TFI is noisy at high light: its PSNR peaks below the brightest L."""
    reason = _axis_ready(frame, "light")
    if reason:
        return UNCHECKED, reason
    curves = _members(frame, ["tfi"], "light")
    if curves.empty:
        return UNCHECKED, "no tfi results at two or more light values"
    curve = curves.loc["tfi"].dropna()
    peak = curve.idxmax()
    brightest = curve.index[-1]
    holds = bool(curve[brightest] < curve[peak])
    text = (f"tfi PSNR by L: {_curve_text('light', curve)}; peak at L = {axis_label('light', peak)}, "
            f"{curve[peak] - curve[brightest]:.2f} dB above the brightest L = {axis_label('light', brightest)}")
    tfp = _widest_tfp(frame)
    wide = axis_means(frame, "light")
    if tfp is not None and tfp in wide.index and brightest in wide.columns and not pd.isna(wide.loc[tfp, brightest]):
        text += f" (at that L {tfp}: {wide.loc[tfp, brightest]:.2f} dB)"
    return (HOLDS if holds else FAILS), text


def tfi_snm_keep_motion(frame: pd.DataFrame) -> Verdict:
    """TFI and SNM keep high-speed motion: from the slowest to the fastest S they lose less PSNR than the widest TFP."""
    reason = _axis_ready(frame, "motion")
    if reason:
        return UNCHECKED, reason
    tfp = _widest_tfp(frame)
    wide = axis_means(frame, "motion")
    present = [m for m in ("tfi", "snm") if m in wide.index]
    if tfp is None or tfp not in wide.index or not present:
        return UNCHECKED, "needs a TFP method and tfi or snm with ok motion results"
    cols = wide.loc[[tfp, *present]].dropna(axis=1, how="any").columns
    if len(cols) < 2:
        return UNCHECKED, "fewer than two motion values shared by TFP and tfi/snm"
    lo, hi = cols[0], cols[-1]
    loss = {m: float(wide.loc[m, lo] - wide.loc[m, hi]) for m in [tfp, *present]}
    holds = all(loss[m] < loss[tfp] for m in present)
    text = (f"PSNR lost from S = {axis_label('motion', lo)} to {axis_label('motion', hi)}: "
            + ", ".join(f"{m} {loss[m]:+.2f} dB" for m in [tfp, *present]))
    if len(present) < 2:
        text += f" ({'snm' if 'tfi' in present else 'tfi'} not in the results)"
    return (HOLDS if holds else FAILS), text


def events_better_with_motion(frame: pd.DataFrame) -> Verdict:
    """Event methods do better as motion grows: their PSNR rises with S."""
    names = _family_names(frame, "event")
    if not names:
        return UNCHECKED, "no event method with ok results"
    return _trend_claim(frame, names, "event", "motion", "rises")


def paper_fusion(frame: pd.DataFrame) -> list[str]:
    """The methods the paper's fusion claims are about: the NeuSpike-Net fusion network when the results
    hold it (found by implementation, not name; its spike-only variant is not a fusion), else every
    method of the fusion family (inputs spikes+events)."""
    nets = sorted(m for m, info in method_descriptions(frame).items()
                  if info.get("implementation") == NEUSPIKE_NET_IMPLEMENTATION
                  and not info.get("params", {}).get("spike_only", False)
                  and m in set(ok_rows(frame)["method"]))
    return nets or _family_names(frame, "fusion")


def fusion_best_everywhere(frame: pd.DataFrame) -> Verdict:
    """The fusion is best everywhere: at every swept axis value the fusion network (else a fusion method) has the highest PSNR."""
    fusion = paper_fusion(frame)
    if not fusion:
        return UNCHECKED, "no fusion method (inputs spikes+events) with ok results"
    others = [m for m in pd.unique(ok_rows(frame)["method"]) if m not in fusion]
    if not others:
        return UNCHECKED, "no other method to compare the fusion with"
    axes = swept_axes(frame)
    margins = []  # (margin dB, where, best other)
    if axes:
        for axis in axes:
            wide = axis_means(frame, axis)
            for v in wide.columns:
                f = wide.loc[[m for m in fusion if m in wide.index], v].dropna()
                o = wide.loc[[m for m in others if m in wide.index], v].dropna()
                if len(f) and len(o):
                    margins.append((float(f.max() - o.max()), f"{axis} {axis_label(axis, v)}", str(o.idxmax())))
    else:
        means = ok_rows(frame, "psnr").groupby("method")["value"].mean()
        f, o = means[[m for m in fusion if m in means.index]], means[[m for m in others if m in means.index]]
        if len(f) and len(o):
            margins.append((float(f.max() - o.max()), "the one condition", str(o.idxmax())))
    if not margins:
        return UNCHECKED, "the fusion and the other methods share no condition with ok results"
    worst = min(margins, key=lambda t: t[0])
    n_best = sum(1 for m in margins if m[0] >= 0)
    text = (f"best fusion method ahead of the best other method at {n_best} of {len(margins)} conditions; "
            f"smallest margin {worst[0]:+.2f} dB at {worst[1]} (vs {worst[2]})")
    return (HOLDS if n_best == len(margins) else FAILS), text


def fusion_degrades_least(frame: pd.DataFrame) -> Verdict:
    """The fusion degrades least with noise: the smallest PSNR loss from the mildest to the worst noise level."""
    reason = _axis_ready(frame, "noise")
    if reason:
        return UNCHECKED, reason
    fusion = paper_fusion(frame)
    if not fusion:
        return UNCHECKED, "no fusion method (inputs spikes+events) with ok results"
    wide = axis_means(frame, "noise")
    curves = wide.dropna(axis=1, how="any") if not wide.empty else wide
    if curves.empty or curves.shape[1] < 2:
        return UNCHECKED, "fewer than two noise levels with ok results for every method"
    lo, hi = curves.columns[0], curves.columns[-1]
    loss = (curves[lo] - curves[hi]).astype(float)
    f_loss = loss[[m for m in fusion if m in loss.index]]
    o_loss = loss[[m for m in loss.index if m not in fusion]]
    if f_loss.empty or o_loss.empty:
        return UNCHECKED, "needs the fusion and at least one other method at the same noise levels"
    holds = float(f_loss.min()) < float(o_loss.min())
    text = (f"PSNR lost from noise {lo} to {hi}: best fusion {f_loss.idxmin()} {f_loss.min():+.2f} dB; "
            f"least-affected other method {o_loss.idxmin()} {o_loss.min():+.2f} dB ("
            + ", ".join(f"{m} {v:+.2f}" for m, v in loss.items()) + ")")
    return (HOLDS if holds else FAILS), text


CLAIMS: tuple[Claim, ...] = (
    Claim("spike-light", "Spike methods are sensitive to light, event methods much less.",
          f"median PSNR range over L of spike methods > {MUCH_LESS_FACTOR:g}x that of event methods",
          "light", spike_light_sensitive),
    Claim("event-static", "Event methods fail to recover static background texture.",
          "event family's mean static-texture correlation (gradient magnitudes against the ground truth over "
          "the regions that never move) below half the spike family's", "",
          events_miss_static_texture),
    Claim("tfp-light", "TFP is noisy at low light (too few spikes in its window).",
          "mean PSNR of the TFP variants rises with L", "light", tfp_noisy_low_light),
    Claim("tfp-motion", "TFP blurs at large motion.", "mean PSNR of the TFP variants falls as S grows",
          "motion", tfp_blurs_large_motion),
    Claim("tfi-light", "TFI is noisy at high light.", "TFI's PSNR peaks below the brightest L", "light",
          tfi_noisy_high_light),
    Claim("tfi-snm-motion", "TFI and SNM keep high-speed motion.",
          "from the slowest to the fastest S, TFI and SNM lose less PSNR than the widest TFP", "motion",
          tfi_snm_keep_motion),
    Claim("event-motion", "Event methods do better as motion grows.", "mean PSNR of the event methods rises with S",
          "motion", events_better_with_motion),
    Claim("fusion-best", "The fusion is best everywhere.",
          "at every swept axis value, NeuSpike-Net (else any fusion method, spikes+events) has the highest mean PSNR", "",
          fusion_best_everywhere),
    Claim("fusion-noise", "The fusion degrades least with noise.",
          "NeuSpike-Net (else a fusion method) loses the least PSNR from the mildest to the worst noise level", "noise",
          fusion_degrades_least),
)


#: Fewer scene x seed cells than this behind a point, and a verdict is only indicative.
MIN_CELLS_PER_POINT = 4


def run_size_caveat(frame: pd.DataFrame) -> str:
    """A warning when the results are too few to conclude from, else ``""``.

    Counts the distinct (scene, seed) cells behind each condition (light, motion, noise) of the ok
    PSNR rows; below :data:`MIN_CELLS_PER_POINT` at any condition the verdicts rest on too little.
    """
    rows = ok_rows(frame, "psnr")
    if rows.empty:
        return ""
    conds = [c for c in ("light", "motion", "noise") if c in rows.columns]
    cells = [c for c in ("scene", "seed") if c in rows.columns]
    per_point = rows.drop_duplicates(conds + cells).groupby(conds, sort=False).size()
    fewest = int(per_point.min()) if len(per_point) else 0
    if fewest >= MIN_CELLS_PER_POINT:
        return ""
    return (f"Caution: some points average only {fewest} cell{'s' if fewest != 1 else ''} (scenes x seeds); "
            f"below {MIN_CELLS_PER_POINT} a verdict is indicative, not a conclusion. Rerun with more scenes "
            f"or seeds (--full) before drawing conclusions.")


def evaluate_claims(frame: pd.DataFrame, claims: Sequence[Claim] = CLAIMS) -> pd.DataFrame:
    """Every claim's verdict: columns ``key, statement, test, status, evidence, figure`` (the figure
    that shows it, when the claim could be checked and has one).

    A claim function that raises is reported as ``cannot check`` with the exception, so that one
    defect does not hide the other verdicts. ``attrs["caveat"]`` holds :func:`run_size_caveat`.
    """
    records = []
    for claim in claims:
        try:
            status, evidence = claim.check(frame)
        except Exception as exc:  # reported in the row, never silently
            status, evidence = UNCHECKED, f"the check failed: {one_line(exc)}"
        if status not in STATUSES:
            raise ValueError(f"claim {claim.key!r} returned status {status!r}; expected one of {STATUSES}")
        figure = f"figures/{claim.figure}_psnr_ssim.png" if claim.figure and status != UNCHECKED else ""
        records.append({"key": claim.key, "statement": claim.statement, "test": claim.test,
                        "status": status, "evidence": evidence, "figure": figure})
    verdicts = pd.DataFrame(records, columns=["key", "statement", "test", "status", "evidence", "figure"])
    verdicts.attrs["caveat"] = run_size_caveat(frame)
    return verdicts


def claims_markdown(verdicts: pd.DataFrame) -> str:
    """The claims as a Markdown list (statement, verdict, test, evidence)."""
    lines = ["# The paper's claims against our numbers\n",
             "Statements of NeuSpike-Net (ICCV 2021) about its Figures 3 and 4 and Table 3, checked on "
             "these results. Numbers are mean PSNR in dB over scenes and seeds unless said otherwise.\n"]
    if verdicts.attrs.get("caveat"):
        lines.append(f"**{verdicts.attrs['caveat']}**\n")
    counts = verdicts["status"].value_counts()
    lines.append(", ".join(f"{int(counts.get(s, 0))} {s}" for s in STATUSES) + ".\n")
    for r in verdicts.itertuples():
        shown = f" Figure: `{r.figure}`." if r.figure else ""
        lines.append(f"- **{r.statement}** — *{r.status}*. Test: {r.test}. {r.evidence}.{shown}")
    return "\n".join(lines) + "\n"
