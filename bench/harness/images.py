"""Where a run keeps its reconstruction images, and how it writes them (the report reads them back).

Sweeps: ``images/<scene>/<axis>=<value>/<method>.png`` and ``images/<scene>/<axis>=<value>/gt.png``

* ``<scene>`` is the scene's name (``KIND:IMAGE``) passed through :func:`safe_name` (characters other
  than letters, digits, ``.``, ``_``, ``-`` and ``=`` become ``_``: ``pan:camera`` -> ``pan_camera``);
* ``<axis>`` is a swept axis of :data:`bench.harness.axes.AXES`; ``<value>`` the axis value as
  ``results.csv`` writes it (``light=0.03125``, ``motion=128``, ``noise=high``);
* ``<method>`` is the registry name through :func:`safe_name`; ``gt.png`` is the ground truth;
* each PNG is 8-bit greyscale, ``round(255 * clip(image, 0, 1))``, of one seed (the first).

Datasets (``python -m bench.dataset``): ``images/<recording>/<method>.png`` of a recording's middle instant.
"""

from __future__ import annotations

import os
import re
from pathlib import Path
from typing import Any

import numpy as np

from bench.harness.axes import AXIS
from neuspike.formats.images import write_png


def safe_name(name: str) -> str:
    """``name`` with every character other than letters, digits, ``. _ - =`` replaced by ``_``
    (how scene and method names become file and folder names)."""
    return re.sub(r"[^A-Za-z0-9._=-]", "_", str(name))


def axis_folder(axis: str, value: Any) -> str:
    """``<axis>=<value>``, the value as ``results.csv`` writes it (``light=0.03125``, ``motion=128``)."""
    if axis not in AXIS:
        raise ValueError(f"axis: expected one of {tuple(AXIS)}, got {axis!r}")
    return safe_name(f"{axis}={AXIS[axis].text(value)}")


def image_path(images_dir: str | os.PathLike, scene: str, axis: str, value: Any, name: str) -> Path:
    """Where the reconstruction of ``name`` (a method, or ``"gt"``) of one scene and axis value lives."""
    return Path(images_dir) / safe_name(scene) / axis_folder(axis, value) / f"{safe_name(name)}.png"


def recording_image_path(images_dir: str | os.PathLike, recording: str, name: str) -> Path:
    """Where a dataset run keeps a method's (or ``"gt"``'s) image of a recording's middle instant."""
    return Path(images_dir) / safe_name(recording) / f"{safe_name(name)}.png"


def write_image_png(path: str | os.PathLike, image01: np.ndarray) -> Path:
    """Write a float image in [0, 1] as 8-bit greyscale PNG, atomically.

    Raises
    ------
    InputError
        When the image is not 2-D, not finite, or outside [0, 1] (it is never clipped silently).
    """
    return write_png(path, image01, clip=False)
