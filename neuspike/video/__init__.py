"""High-speed video reconstruction: stream a recording through methods, one image per output instant.

:func:`reconstruct_video` (in :mod:`neuspike.video.stream`) is the streaming call;
:mod:`neuspike.video.truth` matches frames to a simulated recording's ground truth and scores them;
:mod:`neuspike.video.writers` writes videos, frames and contact sheets; ``python -m neuspike.video``
is the command (:mod:`neuspike.video.cli`).
"""

from neuspike.video.stream import (
    VideoRecording,
    check_fps,
    frame_times,
    open_recording,
    reconstruct_video,
    stream_methods,
    stream_samples,
)

__all__ = ["VideoRecording", "check_fps", "frame_times", "open_recording", "reconstruct_video", "stream_methods", "stream_samples"]
