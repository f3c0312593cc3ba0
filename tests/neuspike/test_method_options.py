"""One set of method options (``MethodOptions``): declared with one wording by every command that builds
methods, read and checked in one place."""

import argparse

import pytest

from neuspike.errors import InputError
from neuspike.utils.cli import MethodOptions, WEIGHTS_ENV


def _parsers():
    from bench import dataset, method_speed, sweep, timing
    from bench import video as video_bench
    from neuspike import reconstruct
    from neuspike.video import cli as video_cli

    return {"reconstruct": reconstruct.build_parser(), "video": video_cli.build_parser(),
            "sweep": sweep.build_parser(), "dataset": dataset.build_parser(), "timing": timing.build_parser(),
            "video-bench": video_bench.build_parser(), "method-speed": method_speed.build_parser()}


def _helps(parser: argparse.ArgumentParser) -> dict[str, str]:
    return {opt: a.help for a in parser._actions for opt in a.option_strings}


def test_every_command_words_each_method_option_the_same_and_sweeps_take_precision():
    reference = argparse.ArgumentParser()
    MethodOptions.add_arguments(reference, flags=MethodOptions.FLAGS)
    wording = _helps(reference)
    offered = {}
    for name, parser in _parsers().items():
        helps = _helps(parser)
        for flag in ("--weights", "--precision", "--compile", "--read-out", "--plugin"):
            if flag in helps:
                assert helps[flag] == wording[flag], (name, flag)
                offered.setdefault(flag, []).append(name)
        if "--device" in helps:  # a command may add what the device means to it
            assert helps["--device"].startswith(wording["--device"]), name
    assert set(offered["--weights"]) == {"reconstruct", "video", "sweep", "dataset", "timing", "video-bench",
                                         "method-speed"}
    assert {"sweep", "dataset", "timing", "reconstruct", "video"} <= set(offered["--precision"])
    # every command that runs methods by name loads plug-ins (method-speed times the suite's own targets)
    assert set(offered["--plugin"]) == {"reconstruct", "video", "sweep", "dataset", "timing", "video-bench"}


def test_a_weights_folder_that_is_not_one_is_refused_naming_where_it_came_from(tmp_path, monkeypatch):
    monkeypatch.delenv(WEIGHTS_ENV, raising=False)
    args = argparse.Namespace(weights=str(tmp_path / "missing"))
    with pytest.raises(InputError, match=r"^--weights: .*missing' is not a folder"):
        MethodOptions.from_args(args)
    monkeypatch.setenv(WEIGHTS_ENV, str(tmp_path / "gone"))
    with pytest.raises(InputError, match=rf"^\${WEIGHTS_ENV}: .*gone' is not a folder"):
        MethodOptions.from_args(argparse.Namespace(weights=None))
    monkeypatch.setenv(WEIGHTS_ENV, str(tmp_path))
    options = MethodOptions.from_args(argparse.Namespace(weights=None, device="cpu", precision="float32", compile=True))
    assert options.weights_dir == tmp_path.resolve()
    assert options.create_kwargs() == {"weights_dir": tmp_path.resolve(), "device": "cpu", "precision": "float32",
                                       "compiled": True}
    with pytest.raises(InputError, match="--device: expected a torch device"):
        MethodOptions.from_args(argparse.Namespace(device="  "))
    with pytest.raises(ValueError, match="unknown"):
        MethodOptions.add_arguments(argparse.ArgumentParser(), flags=("weights", "dtype"))
