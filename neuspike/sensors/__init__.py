"""The sensor simulators: the spike camera (integrate-and-fire) and the event camera (DVS)."""

from neuspike.sensors.event_camera import EventCamera, log_intensity
from neuspike.sensors.spike_camera import (
    PackedPlanes,
    SpikeCamera,
    draw_dark_charge,
    draw_initial_charge,
    integrate_and_fire,
    pack_planes,
)

__all__ = [
    "EventCamera",
    "PackedPlanes",
    "SpikeCamera",
    "draw_dark_charge",
    "draw_initial_charge",
    "integrate_and_fire",
    "log_intensity",
    "pack_planes",
]
