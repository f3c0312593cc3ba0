"""Scene motion: the image speed is the exact flow's rate at the point it names."""

import math

import numpy as np
import pytest

from neuspike.errors import InputError
from neuspike.scenes import SceneSpec
from neuspike.scenes.motion import backward_flow, image_speed_px_s


@pytest.mark.parametrize("spec", [
    SceneSpec("pan", image="brick", size=(64, 48), velocity_px_s=(3000.0, -400.0)),
    SceneSpec("zoom", image="brick", size=(80, 40), zoom_rate_hz=12.0, focus=(20.0, 30.0)),
])
def test_the_image_speed_is_the_flow_rate(spec):
    dt = 1e-6
    flow = backward_flow(spec, 0.0, dt).astype(np.float64) / dt
    if spec.kind == "pan":
        rate = math.hypot(flow[0, 5, 5], flow[1, 5, 5])
    else:  # a point 0.35 * min(W, H) to the right of the focus
        fx, fy = spec.focus
        x = int(round(fx + 0.35 * min(spec.size)))
        assert x == fx + 0.35 * min(spec.size)  # lands on a pixel
        rate = math.hypot(flow[0, int(fy), x], flow[1, int(fy), x])
    assert rate == pytest.approx(image_speed_px_s(spec), rel=1e-3)


def test_still_scenes_do_not_move_and_video_has_no_closed_form():
    still = SceneSpec("still", image="brick", size=(16, 12))
    assert image_speed_px_s(still) == 0.0 and not backward_flow(still, 0.0, 1.0).any()
    with pytest.raises(InputError, match="video"):
        image_speed_px_s(SceneSpec("video", video="clip.mp4", size=(16, 12)))
