"""High-speed video reconstruction: stream a recording through methods, one image per output instant.

:func:`reconstruct_video` (in :mod:`neuspike.video.stream`) is the streaming call;
:mod:`neuspike.video.truth` matches frames to a simulated recording's ground truth and scores them;
:mod:`neuspike.video.writers` writes videos, frames and contact sheets; ``python -m neuspike.video``
is the command (:mod:`neuspike.video.cli`).
"""

from typing import Any

__all__ = ["VideoRecording", "centred_span", "check_fps", "needs_centred_window", "frame_times", "open_recording", "reconstruct_video", "stream_methods", "stream_samples"]


def __getattr__(name: str) -> Any:
    """The streaming names, imported on first use (``python -m neuspike.video --help`` needs none of them)."""
    if name in __all__:
        from neuspike.video import stream

        return getattr(stream, name)
    raise AttributeError(f"module 'neuspike.video' has no attribute {name!r}")
