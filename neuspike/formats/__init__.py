"""Readers and writers: Vidar ``.dat`` and ``.npz`` spikes; events in HDF5, text, ``.npz``, AEDAT4."""

from neuspike.formats.event_readers import read_events
from neuspike.formats.event_writers import EventsH5Writer, write_events_h5, write_events_npz, write_events_txt
from neuspike.formats.spike_npz import read_spike_npz, write_spike_npz
from neuspike.formats.vidar_dat import DatWriter, count_planes, read_dat, read_spike_stream, write_dat

__all__ = [
    "DatWriter",
    "EventsH5Writer",
    "count_planes",
    "read_dat",
    "read_events",
    "read_spike_npz",
    "read_spike_stream",
    "write_dat",
    "write_events_h5",
    "write_events_npz",
    "write_events_txt",
    "write_spike_npz",
]
