"""Which precision ``"auto"`` means for one module on one device: bfloat16 only where a measured step
is faster.

A CPU with bfloat16 instructions is not always faster in bfloat16: without AMX, an Intel Xeon's
bfloat16 matrix product runs at about half its float32 rate, while an AMD EPYC with AVX512-BF16 runs
about twice as fast. So where the device can compute bfloat16 at all, one step of the module is timed
in float32 and under bfloat16 autocast (a warm-up call, then the median of a few), and bfloat16 is
chosen only when its step takes at most :data:`BF16_MARGIN` of the float32 step. Elsewhere (a CPU
without the instructions, where bfloat16 is emulated and always slower) ``"auto"`` is float32 without
measuring.

The choice is remembered per machine, torch version, device, thread count and module (its class and
architecture parameters) in a small JSON file (:func:`cache_path`: ``$NEUSPIKE_CACHE/precision.json``,
by default ``~/.cache/neuspike/precision.json``), so each module is measured once per machine.
"""

from __future__ import annotations

import json
import os
import platform
import statistics
import time
from pathlib import Path
from typing import Any, Callable

from neuspike.utils.atomic import write_json
from neuspike.utils.cli import PRECISIONS
from neuspike.utils.jsonio import canonical_json, stable_hash
from neuspike.utils.resources import cpu_model

__all__ = ["BF16_MARGIN", "PRECISIONS", "cache_path", "choose_precision", "machine_key"]

# PRECISIONS (the precisions a learned method runs in, ``"auto"`` resolved per device and module) lives in
# neuspike.utils.cli, so that a command's parser offers them without importing numpy or torch.

#: bfloat16 is chosen only when its step takes at most this fraction of the float32 step.
BF16_MARGIN = 0.9
#: Timed calls per precision after one warm-up call.
REPEATS = 3


def cache_path() -> Path:
    """Where measured choices are remembered (``$NEUSPIKE_CACHE`` or ``~/.cache/neuspike``)."""
    root = os.environ.get("NEUSPIKE_CACHE") or os.path.join(os.path.expanduser("~"), ".cache", "neuspike")
    return Path(root) / "precision.json"


def machine_key(device: str, threads: int) -> dict[str, Any]:
    """What a measurement depends on besides the module: the CPU model, torch, the device, the threads."""
    import torch

    return {"cpu": cpu_model() or platform.machine(), "torch": torch.__version__, "device": device, "threads": int(threads)}


def _median_ms(step: Callable[[], Any]) -> float:
    step()  # warm-up: first-call allocations and kernel selection
    times = []
    for _ in range(REPEATS):
        t0 = time.perf_counter()
        step()
        times.append((time.perf_counter() - t0) * 1000.0)
    return statistics.median(times)


def choose_precision(module_key: dict[str, Any], device: str, threads: int,
                     step: Callable[[str], Any]) -> tuple[str, dict[str, Any]]:
    """``"bfloat16"`` or ``"float32"`` for a module whose bfloat16 the device can compute.

    Parameters
    ----------
    module_key : dict
        What identifies the module's cost (class and architecture parameters; JSON-serialisable).
    device : str
        The torch device.
    threads : int
        torch's intra-op threads (a measurement with other threads does not carry over).
    step : callable
        ``step(precision)`` runs one forward step of the module in ``"float32"`` or ``"bfloat16"``.

    Returns
    -------
    precision, record
        The choice, and what it rests on (``float32_ms``, ``bfloat16_ms``, ``cached``).
    """
    key = stable_hash({"machine": machine_key(device, threads), "module": module_key})
    path = cache_path()
    try:
        known = json.loads(path.read_text()) if path.is_file() else {}
        if not isinstance(known, dict):
            known = {}
    except (OSError, ValueError):
        known = {}  # an unreadable cache is measured again and rewritten
    record = known.get(key)
    if isinstance(record, dict) and record.get("choice") in ("float32", "bfloat16"):
        return record["choice"], {**record, "cached": True}
    f32 = _median_ms(lambda: step("float32"))
    bf16 = _median_ms(lambda: step("bfloat16"))
    choice = "bfloat16" if bf16 <= BF16_MARGIN * f32 else "float32"
    record = {"choice": choice, "float32_ms": round(f32, 3), "bfloat16_ms": round(bf16, 3),
              "module": module_key, "machine": machine_key(device, threads)}
    try:
        write_json(path, {**known, key: record})
    except OSError:
        pass  # a read-only home: the choice holds for this process, and is measured again next time
    return choice, {**record, "cached": False}


def module_identity(cls: type, params: dict[str, Any]) -> dict[str, Any]:
    """A module's cost identity: its class and the parameters that shape its architecture (JSON)."""
    shaping = {k: v for k, v in params.items() if k not in ("precision", "weights_file")}
    return {"class": f"{cls.__module__}.{cls.__qualname__}", "params": canonical_json(shaping)}


#: (width, height) of the probe: the size of the suite's benchmarks.
PROBE_SIZE = (400, 250)


def probe_sample(*, seed: int = 0) -> Any:
    """A synthetic sample of the size the suite's benchmarks use (400x250), for timing one step:
    256 spike planes at a firing probability of 0.2 per plane, and 24 windows' worth of events at
    the event methods' 0.35 events per pixel, spread over the window and its history. Its content
    does not matter, only its size and density."""
    import numpy as np

    from neuspike.sample import Sample
    from neuspike.streams import EventStream, SpikeStream

    width, height = PROBE_SIZE
    rng = np.random.default_rng(seed)
    planes = rng.random((256, height, width)) < 0.2
    window_s = 256 / 20_000.0
    n = int(0.35 * height * width * 24)
    t = np.sort(rng.uniform(-4 * window_s, window_s, n))
    events = EventStream(t_s=t, x=rng.integers(0, width, n).astype(np.uint16),
                         y=rng.integers(0, height, n).astype(np.uint16),
                         p=np.where(rng.random(n) < 0.5, -1, 1).astype(np.int8), width=width, height=height)
    return Sample(height=height, width=width, key_time_s=window_s / 2, window_start_s=0.0, window_end_s=window_s,
                  spikes=SpikeStream(planes, plane_rate_hz=20_000.0, start_s=0.0, gain=1.0, threshold=1.0),
                  events=events, event_threshold=0.2)
