"""The condition axes a sweep spans, declared once: name, title, scale, how a value is written and
ordered, and the folder a reconstruction of that value is kept in. The grids (:mod:`bench.harness.grid`),
the images' layout (:mod:`bench.harness.images`), the tables and the figures (:mod:`bench.reporting`)
all read these declarations, so an axis is added here and nowhere else.
"""

from __future__ import annotations

from dataclasses import dataclass
from fractions import Fraction
from typing import Any, Iterable, Mapping

#: The noise levels in order of severity (the paper's Table 3 levels after ``none``).
NOISE_ORDER: tuple[str, ...] = ("none", "small", "medium", "high")


@dataclass(frozen=True)
class Axis:
    """One condition axis.

    ``kind``: ``"fraction"`` (values written as exact fractions, ``1/32``; the light scale),
    ``"count"`` (whole numbers; the motion scale) or ``"level"`` (named levels in ``levels``' order;
    the noise). ``log2``: plotted on a log2 scale.
    """

    name: str
    title: str
    kind: str
    log2: bool
    levels: tuple[str, ...] = ()

    def label(self, value: Any) -> str:
        """How a value is written in tables and figures: ``1/32``, ``128``, ``high``."""
        if self.kind == "fraction":
            frac = Fraction(float(value)).limit_denominator(4096)
            if abs(float(frac) - float(value)) <= 1e-12 * max(1.0, abs(float(value))):
                return str(frac)
            return f"{float(value):g}"
        if self.kind == "count":
            return str(int(value))
        return str(value)

    def text(self, value: Any) -> str:
        """The value as ``results.csv`` writes it (``0.03125``, ``128``, ``high``): the images' folders."""
        if self.kind == "fraction":
            return repr(float(value))
        if self.kind == "count":
            return str(int(value))
        return str(value)

    def ordered(self, values: Iterable[Any]) -> list[Any]:
        """``values`` in the axis's order (numbers ascending; levels by ``levels``, unknown ones last)."""
        values = list(values)
        if self.kind == "level":
            rank = {v: i for i, v in enumerate(self.levels)}
            return sorted(values, key=lambda v: (rank.get(v, len(rank)), str(v)))
        return sorted(values)


#: Every axis, in the order they are reported.
AXIS: Mapping[str, Axis] = {a.name: a for a in (
    Axis("light", "light scale L", "fraction", log2=True),
    Axis("motion", "motion scale S", "count", log2=True),
    Axis("noise", "noise level", "level", log2=False, levels=NOISE_ORDER),
)}
#: Their names.
AXES: tuple[str, ...] = tuple(AXIS)
