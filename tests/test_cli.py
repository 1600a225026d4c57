"""Tests of the ``leoc`` command line."""

from __future__ import annotations

import json
import signal
import subprocess
import sys

import numpy as np
import pytest

from leoc.cli import main
from leoc.control import design_lqr
from leoc.systems import make_system


def test_lqr_json_matches_the_library(capsys) -> None:
    assert main(["lqr", "cartpole", "--json"]) == 0
    printed = json.loads(capsys.readouterr().out)
    design = design_lqr(make_system("cartpole"))
    np.testing.assert_allclose(printed["K"], design.K)
    np.testing.assert_allclose(printed["W"], design.W)
    assert printed["spectral_radius"] < 1


def test_lqr_with_custom_weights_and_bad_weights(capsys) -> None:
    assert main(["lqr", "pendulum", "--q", "1", "1", "--r", "2"]) == 0
    assert "spectral radius" in capsys.readouterr().out
    assert main(["lqr", "pendulum", "--q", "1", "1", "1"]) == 2
    assert "Q: expected shape" in capsys.readouterr().err


def test_unknown_system_lists_the_valid_names(capsys) -> None:
    with pytest.raises(SystemExit):
        main(["lqr", "segway"])  # acrobot was unknown before it was built
    assert "pendulum" in capsys.readouterr().err


def test_simulate_writes_a_png_and_prints_metrics(tmp_path, capsys) -> None:
    figure = tmp_path / "impulse.png"
    assert main(["simulate", "mountaincar", "--test", "impulse", "--plot", str(figure)]) == 0
    out = capsys.readouterr().out
    assert "settling time" in out and "overshoot" in out
    assert figure.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_simulate_with_a_missing_run_folder_is_a_clear_error(tmp_path, capsys) -> None:
    assert main(["simulate", "pendulum", "--controller", str(tmp_path / "nope")]) == 2
    assert "run folder" in capsys.readouterr().err


def test_help_of_every_command() -> None:
    for command in ["lqr", "simulate", "train", "reproduce"]:
        result = subprocess.run(
            [sys.executable, "-m", "leoc.cli", command, "--help"], capture_output=True, text=True
        )
        assert result.returncode == 0 and "usage" in result.stdout


def test_roa_json_matches_the_library_and_plots(tmp_path, capsys) -> None:
    from leoc.control import certify_lqr

    plot = tmp_path / "roa.png"
    args = ["roa", "mountaincar", "--json", "--samples", "5000", "--starts", "40"]
    assert main([*args, "--slice-points", "5", "--plot", str(plot)]) == 0
    report = json.loads(capsys.readouterr().out)
    system = make_system("mountaincar")
    expected = certify_lqr(system, design_lqr(system), samples=5000, seed=0)
    assert report["certificate"]["rho"] == expected.rho
    assert report["certificate"]["samples"] == 5000
    assert report["basins"]["LQR (period 1)"]["certified_set_held"] == 1.0
    assert plot.is_file()
    assert (
        main(["roa", "pendulum", "--action-repeat", "3", "--samples", "2000", "--starts", "20"])
        == 0
    )
    text = capsys.readouterr().out
    assert "control period 3 step(s)" in text and "violating volume fraction" in text


@pytest.mark.parametrize("command", [["lqr", "pendulum", "--json"], ["--help"]])
def test_a_closed_pipe_ends_without_traceback(command) -> None:
    # The reader is gone before leoc writes (as with `leoc ... | head -0`): no traceback, and
    # the status of a process ended by SIGPIPE (or 0 when the command exits on its own).
    process = subprocess.Popen(
        [sys.executable, "-m", "leoc.cli", *command],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    process.stdout.close()
    _, errors = process.communicate(timeout=120)
    assert b"Traceback" not in errors and b"BrokenPipeError" not in errors
    assert process.returncode in (0, 128 + signal.SIGPIPE)
