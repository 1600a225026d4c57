"""Reliability of the command line: one-line errors, clean interrupts, damaged files.

(Issue: one Ctrl-C stops cleanly, damaged files never block, every bad input a one-line error.)
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import time
from pathlib import Path

import pytest

from leoc.cli import main
from leoc.experiments.reproduce import EVALUATION_FILE, META_FILE, reproduce

INTERRUPT_DEADLINE_S = 10.0


BAD_ARGUMENTS = [
    (["reproduce", "--jobs", "0"], "--jobs: expected a positive integer, found 0"),
    (["reproduce", "--jobs", "-2"], "--jobs: expected a positive integer, found -2"),
    (["reproduce", "--seeds", "0"], "--seeds: expected a positive integer, found 0"),
    (["reproduce", "--profile", "fast"], "invalid choice: 'fast'"),
    (["reproduce", "--systems", "segway"], "invalid choice: 'segway'"),
    (["reproduce", "--controllers", "lqr"], "invalid choice: 'lqr'"),
    (["reproduce", "--backend", "spark"], "invalid choice: 'spark'"),
    (["simulate", "pendulum", "--steps", "0"], "--steps: expected a positive integer, found 0"),
    (
        ["simulate", "pendulum", "--steps", "ten"],
        "--steps: expected a positive integer, found 'ten'",
    ),
    (
        ["simulate", "pendulum", "--band", "wide"],
        "--band: expected a positive number, found 'wide'",
    ),
    (["train", "pendulum", "--algo", "ddpg", "--seed", "x"], "--seed: expected a non-negative"),
    (["simulate"], "system: expected a system name or a run folder"),
    (["simulate", "pendulum", "--band", "-1"], "--band: expected a positive number, found -1"),
    (["simulate", "pendulum", "--action-repeat", "0"], "--action-repeat: expected a positive"),
    (["simulate", "pendulum", "--test", "ramp"], "invalid choice: 'ramp'"),
    (["simulate", "cartpole", "--controller", "/no/such/run"], "does not exist"),
    (["simulate", "segway"], "invalid choice: 'segway' (expected a run folder or one of"),
    (["lqr", "segway"], "invalid choice: 'segway' (expected one of pendulum, cartpole"),
    (["train", "pendulum", "--algo", "ddpg", "--steps", "-5"], "expected a positive integer"),
    (["train", "pendulum", "--algo", "pilco", "--iterations", "0"], "expected a positive"),
    (["train", "pendulum", "--algo", "ddpg", "--seed", "-1"], "expected a non-negative"),
    (["train", "pendulum", "--algo", "ppo"], "invalid choice: 'ppo'"),
    (["train", "pendulum", "--algo", "sac", "--iterations", "2"], "--iterations: only for"),
    (["train", "pendulum"], "the following arguments are required: --algo"),
    (["lqr", "pendulum", "--q", "1"], "Q"),
    (["lqr", "pendulum", "--r", "-1"], "R"),
    (["plot", "/no/such/folder"], "run_dir: the folder '/no/such/folder' does not exist"),
]


@pytest.mark.parametrize(("argv", "expected"), BAD_ARGUMENTS, ids=lambda v: " ".join(v))
def test_every_bad_argument_is_one_line_on_stderr(argv, expected, capsys):
    try:
        status = main(argv)
    except SystemExit as stop:  # argparse exits itself
        status = stop.code
    captured = capsys.readouterr()
    assert status == 2
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1, captured.err
    assert expected in lines[0]
    assert "Traceback" not in captured.err


def _as_a_terminal_job() -> None:
    """Start the command with SIGINT at its default, as a terminal's foreground job has it. A
    job started in the background by a non-interactive shell (``pytest &``, a CI script run with
    ``nohup ... &``) inherits SIGINT *ignored*, so Python installs no KeyboardInterrupt handler,
    Ctrl-C cannot reach it, and the test would only measure the runs finishing on their own."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _differences(expected, found, path: str = "") -> list[str]:
    """The paths where two JSON values differ, with both values (what a failure shows)."""
    if isinstance(expected, dict) and isinstance(found, dict):
        keys = sorted(set(expected) | set(found))
        return [
            line
            for key in keys
            for line in (
                _differences(expected[key], found[key], f"{path}/{key}")
                if key in expected and key in found
                else [f"{path}/{key}: on one side only"]
            )
        ]
    if isinstance(expected, list) and isinstance(found, list) and len(expected) == len(found):
        return [
            line
            for index, pair in enumerate(zip(expected, found, strict=True))
            for line in _differences(*pair, f"{path}[{index}]")
        ]
    return [] if expected == found else [f"{path}: {expected!r:.80} != {found!r:.80}"]


def _alive_in_group(group: int) -> list[int]:
    alive = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if int(fields[2]) == group and fields[0] != "Z":
                alive.append(int(entry.name))
    return alive


@pytest.fixture
def uninterrupted(smoke_study) -> dict[str, dict]:
    """The smoke study's numbers, run once per session without interruption."""
    return smoke_study.uninterrupted()


@pytest.mark.slow
@pytest.mark.skipif(not Path("/proc").is_dir(), reason="reads the process table from /proc")
@pytest.mark.parametrize(
    "signum",
    # SIGTERM takes the same path after its handler; both share the uninterrupted study
    [signal.SIGINT, signal.SIGTERM],
)
def test_one_signal_stops_reproduce_cleanly_and_a_rerun_completes(
    tmp_path, uninterrupted, smoke_study, signum
):
    command = smoke_study.command(tmp_path)
    process = subprocess.Popen(
        command,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        start_new_session=True,
        text=True,
        preexec_fn=_as_a_terminal_job,
    )
    deadline = time.monotonic() + smoke_study.timeout_s
    # wait until the workers run (their logs appear), then interrupt as a terminal would:
    # SIGINT to the whole process group, SIGTERM to the main process only
    while not list(tmp_path.glob("runs/*/*/*/train.log")):
        assert time.monotonic() < deadline and process.poll() is None
        time.sleep(0.1)
    time.sleep(2.0)
    sent = time.monotonic()
    if signum == signal.SIGINT:
        os.killpg(process.pid, signum)
    else:
        process.send_signal(signum)
    stdout, stderr = process.communicate(timeout=60)
    assert time.monotonic() - sent < INTERRUPT_DEADLINE_S
    assert process.returncode == 128 + signum
    assert "Traceback" not in stderr, stderr
    assert "run the same command again to resume" in stderr
    time.sleep(0.5)
    assert _alive_in_group(process.pid) == []  # no worker, no resource tracker left behind
    for path in tmp_path.glob(f"runs/*/*/*/{EVALUATION_FILE}"):
        json.loads(path.read_text())  # whatever finished is whole
    # the stopped invocation is logged as interrupted (SIGTERM too: its handler raises an
    # exception, not KeyboardInterrupt)
    (stopped,) = json.loads((tmp_path / "meta.json").read_text())["invocations"]
    assert (stopped["ended"], stopped["interrupted"]) == ("interrupted", True)
    rerun = subprocess.run(command, capture_output=True, text=True, timeout=smoke_study.timeout_s)
    assert rerun.returncode == 0, rerun.stderr
    resumed = smoke_study.numbers(tmp_path)
    assert resumed == uninterrupted, _differences(uninterrupted, resumed)[:20]
    assert [
        item["ended"] for item in json.loads((tmp_path / "meta.json").read_text())["invocations"]
    ] == ["interrupted", "finished"]


@pytest.fixture(scope="module")
def finished_template(tmp_path_factory, linear_smoke) -> Path:
    """One finished linear-only reproduce folder; each test works on its own copy."""
    out = tmp_path_factory.mktemp("finished")
    linear_smoke(out)
    return out


def _finished_folder(template: Path, tmp_path: Path) -> Path:
    import shutil

    return Path(shutil.copytree(template, tmp_path / "out"))


@pytest.mark.slow
@pytest.mark.parametrize("damage", ["truncate", "garble", "delete"])
def test_a_damaged_evaluation_is_set_aside_and_redone(
    finished_template, tmp_path, damage, capsys, linear_smoke
):
    out = _finished_folder(finished_template, tmp_path)
    done = next(out.glob(f"runs/*/*/*/{EVALUATION_FILE}"))
    original = json.loads(done.read_text())
    if damage == "truncate":
        done.write_bytes(done.read_bytes()[:100])
    elif damage == "garble":
        done.write_text("not json at all")
    else:
        done.unlink()
    # leoc plot names the damaged file in one line (a deleted result just leaves the report)
    status = main(["plot", str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    if damage == "delete":
        assert status == 0
    else:
        assert status == 2 and len(err) == 1 and str(done) in err[0]
        assert "rerun the 'leoc reproduce' command of this folder" in err[0]
    messages: list[str] = []
    linear_smoke(out, echo=messages.append)
    if damage != "delete":
        assert any(str(done) in m and "set aside" in m for m in messages)
        assert len(list(done.parent.glob(f"{EVALUATION_FILE}.damaged-*"))) == 1
    again = json.loads(done.read_text())
    for key in ("wall_seconds", "train_wall_seconds"):
        again.pop(key), original.pop(key)
    assert again == original


@pytest.mark.slow
def test_a_damaged_meta_file_is_set_aside(finished_template, tmp_path, linear_smoke):
    out = _finished_folder(finished_template, tmp_path)
    (out / META_FILE).write_text("{")
    messages: list[str] = []
    linear_smoke(out, echo=messages.append)
    assert any("set aside" in m for m in messages)
    assert json.loads((out / META_FILE).read_text())["profile"] == "smoke"


@pytest.mark.slow
def test_rerun_with_other_seeds_reports_exactly_its_runs(tmp_path):
    reproduce(
        tmp_path, "smoke", controllers=["linear"], systems=["pendulum"], jobs=1, echo=lambda _: None
    )
    meta = json.loads((tmp_path / META_FILE).read_text())
    assert meta["seeds"] == [0] and meta["systems"] == ["pendulum"]
    report = (tmp_path / "report.md").read_text()
    assert "Runs aggregated in this report: pendulum/linear: seeds [0]." in report


@pytest.mark.slow
@pytest.mark.skipif(not Path("/proc").is_dir(), reason="reads the process table from /proc")
def test_sigkill_of_the_main_process_at_random_points_never_corrupts_results(
    tmp_path, uninterrupted, smoke_study
):
    import random

    command = smoke_study.command(tmp_path)
    chooser = random.Random(0)  # the kill times are seeded too
    for attempt in range(3):
        process = subprocess.Popen(
            command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True
        )
        time.sleep(chooser.uniform(5.0, 40.0))
        process.kill()  # the main process only: no clean-up runs in it
        process.wait()
        time.sleep(1.0)
        assert _alive_in_group(process.pid) == [], attempt  # workers die with their driver
        for path in tmp_path.glob(f"runs/*/*/*/{EVALUATION_FILE}"):
            json.loads(path.read_text())  # whatever finished is whole
    rerun = subprocess.run(command, capture_output=True, text=True, timeout=smoke_study.timeout_s)
    assert rerun.returncode == 0, rerun.stderr
    resumed = smoke_study.numbers(tmp_path)
    assert resumed == uninterrupted, _differences(uninterrupted, resumed)[:20]
