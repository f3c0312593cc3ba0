"""How many events a window holds at each light scale: the event camera's dark floor (a probe, no network).

    python reports/neuspike-net/event_count_probe.py [--photos astronaut,coffee] [--kind pan] [--motion 128]

Simulates the light sweep's points (L = 1/32 .. 1/2, no sensor noise, the sweeps' default effects and
sensor, seed 0) on training photographs (never the test photographs) at 400x250 and prints the events
per pixel in each key window, beside the mean spike count per pixel. The DVS pixel's response is v2e's
lin-log (``neuspike/sensors/dvs_pixel.py``): linear below 20/255 of reference white, so at the lowest
lights, where ``light * radiance`` stays below that floor everywhere, a pixel needs a much larger
relative change to fire and the events thin out, while the spike camera's counts fall in proportion to
the light.
"""

from __future__ import annotations

import argparse

import numpy as np

from bench import grid as grids
from neuspike.conditions import Condition
from neuspike.scenes.photos import TEST_PHOTOS
from neuspike.simulation.cell import simulate_sample
from neuspike.simulation.recording import SensorConfig

LIGHTS = (1 / 32, 1 / 16, 1 / 8, 1 / 4, 1 / 2)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--photos", default="astronaut,coffee", help="training photographs (comma-separated)")
    p.add_argument("--kind", default="pan", help="scene kind (pan, zoom, fan, still; default pan)")
    p.add_argument("--motion", type=int, default=128, help="motion scale S (default 128)")
    args = p.parse_args(argv)
    photos = [s.strip() for s in args.photos.split(",") if s.strip()]
    refused = sorted(set(photos) & set(TEST_PHOTOS))
    if refused:
        raise SystemExit(f"--photos: {refused} are test photographs; use training photographs")
    print(f"{args.kind}, S = {args.motion}, no sensor noise, 400x250: events per pixel / spikes per pixel in the key window")
    for photo in photos:
        cells = []
        for light in LIGHTS:
            scene = grids.scene_entry(f"{args.kind}:{photo}", (400, 250))
            cond = Condition(light=light, motion=args.motion, noise="none", effects=grids.DEFAULT_EFFECTS)
            sample = simulate_sample(scene.spec, cond, sensor=SensorConfig(), seed=0, modalities=("spikes", "events"))
            pixels = 400 * 250
            spikes = float(np.count_nonzero(np.asarray(sample.spikes.planes)))  # binary planes: one spike each
            cells.append(f"L = 1/{round(1 / light)}: {len(sample.window_events()) / pixels:.3f} / {spikes / pixels:.2f}")
        print(f"  {photo:10s} " + "; ".join(cells))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
