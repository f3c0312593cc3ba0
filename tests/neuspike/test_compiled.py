"""``compiled=True``: a learned method's module through torch.compile gives the eager image, is recorded
only when on, and a machine where compiling fails gets an error that says so."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from neuspike.errors import InputError
from neuspike.methods import create, create_many
from neuspike.methods import precision


@pytest.fixture
def small_probe(monkeypatch):
    monkeypatch.setattr(precision, "PROBE_SIZE", (40, 24))
    return precision.probe_sample()


def test_compiled_firenet_gives_the_eager_image_and_is_recorded_only_when_on(small_probe, one_torch_thread):
    eager = create("firenet-sim", precision="float32")
    compiled = create("firenet-sim", precision="float32", compiled=True)
    assert "compiled" not in eager.params and compiled.describe()["params"]["compiled"] is True
    first = eager.reconstruct(small_probe)
    try:
        image = compiled.reconstruct(small_probe)
    except InputError as exc:  # a machine without the C++ compiler inductor needs: said, not a crash
        assert "torch.compile failed on this machine" in str(exc) and "compiled=False" in str(exc)
        return
    assert compiled.last_steps == eager.last_steps > 1  # recurrent: the stateless first step and the rest
    np.testing.assert_allclose(image, first, atol=1e-5)
    np.testing.assert_array_equal(compiled.reconstruct(small_probe), image)  # the state is reset per call


def test_a_failing_compiler_is_an_error_naming_it_and_a_failing_step_is_not_renamed(small_probe, monkeypatch):
    from torch._dynamo.exc import TorchDynamoException

    def broken(*args, **kwargs):
        raise TorchDynamoException("CppCompileError: no C++ compiler found")

    monkeypatch.setattr(torch, "compile", lambda module, **kw: broken)
    method = create("neuspike-net-spike", precision="float32", compiled=True)
    with pytest.raises(InputError, match=r"neuspike-net-spike.*torch.compile failed on this machine.*no C\+\+ compiler"):
        method.reconstruct(small_probe)

    def wrong(*args, **kwargs):  # an error of the step itself keeps its own type and message
        raise ValueError("shapes do not match")

    monkeypatch.setattr(torch, "compile", lambda module, **kw: wrong)
    with pytest.raises(ValueError, match="shapes do not match"):
        create("neuspike-net-spike", precision="float32", compiled=True).reconstruct(small_probe)


def test_compiled_must_be_a_bool_and_reaches_only_learned_methods():
    with pytest.raises(InputError, match="compiled: expected True or False"):
        create("firenet-sim", compiled="yes")
    made = create_many(["tfp", "firenet-sim"], precision="float32", compiled=True)
    assert "compiled" not in made["tfp"].method.params
    assert made["firenet-sim"].method.params["compiled"] is True


def test_timing_refuses_compile_without_a_warm_up_call(tmp_path):
    from bench import timing

    args = timing.build_parser().parse_args(["--methods", "firenet-sim", "--compile", "--warmup", "0",
                                             "--results", "none", "--out", str(tmp_path / "t")])
    with pytest.raises(InputError, match="--compile needs at least one warm-up call"):
        timing.run(args)
