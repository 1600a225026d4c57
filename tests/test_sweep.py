"""Sweeps on the local and Ray backends: results, resume, retries after a worker dies, progress,
and the reproduce smoke profile giving the same numbers on both backends."""

from __future__ import annotations

import io
import json
import os
import re
import signal
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from leoc.cli import main
from leoc.experiments import sweep as sweep_module
from leoc.experiments.sweep import (
    WRAP_INDENT,
    BackendUnavailableError,
    default_run_dir,
    fit_lines,
    format_seconds,
    last_log_line,
    sweep,
)

CALLS_FILE = "calls.txt"
PID_FILE = "pid"
VICTIM = "victim"
KILL_TIMEOUT_S = 60.0
QUICK_RUN_S = 0.3


def quiet(_: str) -> None:
    """An echo that drops the progress lines."""


# ------------------------------------------------------------------------- runners (pickled)
def counting_runner(spec: str, out_dir: Path) -> dict[str, object]:
    """Records each call in the run folder, logs, sleeps a little, returns a known result."""
    run_dir = default_run_dir(out_dir, spec)
    run_dir.mkdir(parents=True, exist_ok=True)
    with open(run_dir / CALLS_FILE, "a") as calls:
        calls.write(f"{os.getpid()}\n")
    attempt = len((run_dir / CALLS_FILE).read_text().splitlines())
    with open(run_dir / "train.log", "a") as log:
        log.write(f"{spec}: attempt {attempt} working\n")
    if spec == VICTIM and attempt == 1:
        # the first attempt waits to be killed from outside, mid-run
        (run_dir / PID_FILE).write_text(str(os.getpid()))
        deadline = time.monotonic() + KILL_TIMEOUT_S
        while time.monotonic() < deadline:
            time.sleep(0.05)
        raise TimeoutError("the victim's worker was not killed")
    time.sleep(QUICK_RUN_S)
    return {"spec": spec, "square": len(spec) ** 2, "attempt": attempt}


def failing_runner(spec: str, out_dir: Path) -> dict[str, object]:
    if spec == "bad":
        raise ArithmeticError("bad run: no numbers")
    return counting_runner(spec, out_dir)


def not_a_mapping_runner(spec: str, out_dir: Path) -> list[int]:
    return [1, 2]


def not_json_runner(spec: str, out_dir: Path) -> dict[str, object]:
    return {"value": {1, 2}}  # a set pickles, but is no JSON


def calls_of(out_dir: Path, key: str) -> int:
    path = default_run_dir(out_dir, key) / CALLS_FILE
    return len(path.read_text().splitlines()) if path.is_file() else 0


def done_result(out_dir: Path, key: str) -> dict[str, object]:
    return json.loads((default_run_dir(out_dir, key) / "evaluation.json").read_text())


@pytest.fixture(scope="module")
def ray_instance() -> Iterator[object]:
    """One small local Ray instance (2 CPUs) for the module; always shut down."""
    ray = pytest.importorskip("ray")
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    # the test runners live in this module, which Ray's workers cannot import: send by value
    ray.cloudpickle.register_pickle_by_value(sys.modules[__name__])
    try:
        yield ray
    finally:
        ray.cloudpickle.unregister_pickle_by_value(sys.modules[__name__])
        ray.shutdown()


@pytest.fixture(params=["local", "ray"])
def backend(request: pytest.FixtureRequest) -> str:
    if request.param == "ray":
        request.getfixturevalue("ray_instance")
    return request.param


# ------------------------------------------------------------------------------------- sweeps
@pytest.mark.slow
def test_a_sweep_writes_every_result_and_a_rerun_redoes_nothing(tmp_path, backend) -> None:
    specs = ["a", "bb", "nested/ccc"]
    result = sweep(specs, counting_runner, tmp_path, backend=backend, jobs=2, echo=quiet)
    assert set(result.results) == set(specs) and not result.failed and not result.retried
    for key in specs:
        assert done_result(tmp_path, key) == {"spec": key, "square": len(key) ** 2, "attempt": 1}
        assert calls_of(tmp_path, key) == 1
    assert not (tmp_path / sweep_module.SHARE_TOKEN_FILE).exists()
    stamps = {key: (default_run_dir(tmp_path, key) / "evaluation.json").stat() for key in specs}
    messages: list[str] = []
    again = sweep(specs + ["d"], counting_runner, tmp_path, backend=backend, echo=messages.append)
    assert again.skipped == tuple(specs) and set(again.results) == {"d"}
    assert messages[0].startswith("4 runs: 3 already done, 1 to run on ")
    for key in specs:
        assert calls_of(tmp_path, key) == 1
        path = default_run_dir(tmp_path, key) / "evaluation.json"
        assert path.stat().st_mtime_ns == stamps[key].st_mtime_ns


def _kill_the_victim(out_dir: Path, killed: list[int]) -> None:
    pid_file = default_run_dir(out_dir, VICTIM) / PID_FILE
    deadline = time.monotonic() + KILL_TIMEOUT_S
    while not pid_file.is_file() and time.monotonic() < deadline:
        time.sleep(0.02)
    time.sleep(0.2)  # mid-run: the runner is well inside its work
    pid = int(pid_file.read_text())
    os.kill(pid, signal.SIGKILL)
    killed.append(pid)


def test_a_killed_worker_costs_only_its_run_which_is_retried(tmp_path, backend) -> None:
    finished_before = default_run_dir(tmp_path, "old") / "evaluation.json"
    finished_before.parent.mkdir(parents=True)
    finished_before.write_text('{"kept": true}')
    specs = [VICTIM, "a", "b", "c", "old"]
    killed: list[int] = []
    killer = threading.Thread(target=_kill_the_victim, args=(tmp_path, killed), daemon=True)
    killer.start()
    messages: list[str] = []
    result = sweep(specs, counting_runner, tmp_path, backend=backend, jobs=2, echo=messages.append)
    killer.join()
    assert killed, "the victim never started"
    assert result.retried == {VICTIM: 1} and not result.failed
    assert result.skipped == ("old",)
    assert calls_of(tmp_path, VICTIM) == 2
    assert done_result(tmp_path, VICTIM)["attempt"] == 2
    for key in ("a", "b", "c"):
        assert calls_of(tmp_path, key) == 1, key  # nothing else is redone
    assert json.loads(finished_before.read_text()) == {"kept": True}
    assert calls_of(tmp_path, "old") == 0
    assert any(f"{VICTIM}: " in m and "retrying (attempt 2 of 3)" in m for m in messages)


@pytest.mark.slow
def test_a_runner_error_is_reported_not_retried_and_the_rest_finish(tmp_path, backend) -> None:
    messages: list[str] = []
    specs = ["bad", "good"]
    result = sweep(specs, failing_runner, tmp_path, backend=backend, jobs=2, echo=messages.append)
    assert set(result.results) == {"good"} and not result.retried
    assert result.failed == {"bad": "ArithmeticError: bad run: no numbers"}
    assert not (default_run_dir(tmp_path, "bad") / "evaluation.json").exists()
    log = (default_run_dir(tmp_path, "bad") / "train.log").read_text()
    assert "ArithmeticError: bad run: no numbers" in log and "Traceback" in log
    assert any("bad FAILED: ArithmeticError" in m for m in messages)
    # a result that is not a mapping is an error too, named as such
    other = sweep(["x"], not_a_mapping_runner, tmp_path / "other", backend=backend, echo=quiet)
    assert other.failed == {"x": "runner: expected a mapping, found list"}
    odd = sweep(["y"], not_json_runner, tmp_path / "odd", backend=backend, echo=quiet)
    assert odd.failed["y"].startswith("runner: expected a JSON-serialisable mapping, TypeError")
    assert not (default_run_dir(tmp_path / "odd", "y") / "evaluation.json").exists()


def test_ray_without_a_shared_folder_ships_the_run_folder_back(tmp_path, ray_instance) -> None:
    result = sweep(
        ["a", "b/c"],
        counting_runner,
        tmp_path,
        backend="ray",
        shared_out_dir=False,
        echo=quiet,
    )
    assert set(result.results) == {"a", "b/c"}
    for key in ("a", "b/c"):
        run_dir = default_run_dir(tmp_path, key)
        # the runner wrote in a scratch folder on its node; the driver wrote the files here
        assert calls_of(tmp_path, key) == 1
        assert "attempt 1 working" in (run_dir / "train.log").read_text()
        assert done_result(tmp_path, key)["spec"] == key
    assert not (tmp_path / sweep_module.SHARE_TOKEN_FILE).exists()


def test_progress_lines_show_counts_eta_and_last_log_lines(tmp_path) -> None:
    messages: list[str] = []
    sweep(
        ["first", "a", "b", "c"],
        slow_runner,
        tmp_path,
        jobs=1,
        progress_interval_s=0.4,
        echo=messages.append,
    )
    progress = [m for m in messages if " running, " in m]
    assert progress, messages
    assert "0 done, 1 running, 3 queued; ETA after the first run" in progress[0]
    assert any("1 done, 1 running, 2 queued; ETA " in m and "first" not in m for m in progress)
    assert any(m.startswith("  a (") and m.endswith("step 1 of 2") for m in messages)


def slow_runner(spec: str, out_dir: Path) -> dict[str, object]:
    run_dir = default_run_dir(out_dir, spec)
    run_dir.mkdir(parents=True, exist_ok=True)
    with open(run_dir / "train.log", "a", buffering=1) as log:
        for step in (1, 2):
            log.write(f"step {step} of 2\n")
            time.sleep(0.6)
    return {"spec": spec}


# --------------------------------------------------------------------------- helpers, errors
def test_time_format() -> None:
    assert [format_seconds(s) for s in (0, 59.6, 75, 3700)] == ["0s", "1m00s", "1m15s", "1h01m"]


def test_progress_lines_wrap_to_the_terminal_without_losing_a_number() -> None:
    line = (
        "  cartpole/pilco_hybrid/seed0 (1m15s): [pilco] iter  9/10 predicted cost   6.199 "
        "rollout return    -52.95 eval return    -56.56 held 100% data  642 interaction  "
        "39.00 s wall   40.9 s"
    )
    lines = fit_lines(line, 80)
    assert len(lines) == 3 and all(len(text) <= 80 for text in lines)
    assert lines[0].startswith("  cartpole/pilco_hybrid/seed0 (1m15s): [pilco] iter 9/10")
    assert lines[1].startswith(WRAP_INDENT) and not lines[1].startswith(WRAP_INDENT + " ")
    numbers = ["9/10", "6.199", "-52.95", "-56.56", "100%", "642", "39.00", "40.9"]
    assert all(number in " ".join(lines).split() for number in numbers)
    assert fit_lines("  short", 80) == ["  short"]


def test_the_eta_comes_from_the_expected_costs_from_the_first_report(tmp_path) -> None:
    messages: list[str] = []
    sweep(
        ["first", "a", "b", "c"],
        slow_runner,
        tmp_path,
        jobs=1,
        progress_interval_s=5.0,
        echo=messages.append,
        expected_seconds=lambda spec: 1.2,
        progress_of=lambda line: 0.5 if "step 1 of 2" in line else None,
    )
    first = next(m for m in messages if " running, " in m)
    # reported as the first run starts: 1.2 s for it and 3 x 1.2 s queued, on one worker
    assert "[0s] 0 done, 1 running, 3 queued; ETA 5s" in first


def resuming_runner(spec: str, out_dir: Path) -> dict[str, object]:
    """``resumed`` only has its last step left (it returns at once); the others run."""
    return {"spec": spec} if spec == "resumed" else slow_runner(spec, out_dir)


def test_a_run_begun_before_does_not_time_the_eta(tmp_path) -> None:
    """A run whose folder an earlier invocation began finishes in a fraction of its expected
    1000 s; the ETA of the next run, on the same worker, must not take that for speed: it
    stays near its expected 1000 s (timed on it, the factor would be about 60/1060 and the ETA
    about a minute)."""
    begun = default_run_dir(tmp_path, "resumed")
    begun.mkdir(parents=True)
    (begun / "checkpoint.pt").write_bytes(b"an earlier invocation's work")
    messages: list[str] = []
    sweep(
        ["resumed", "a"],
        resuming_runner,
        tmp_path,
        jobs=1,
        progress_interval_s=0.3,
        echo=messages.append,
        expected_seconds=lambda spec: 1000.0,
    )
    assert any("1 begun by an earlier invocation" in m for m in messages)
    lines = [m for m in messages if "1 done, 1 running, 0 queued; ETA " in m]
    assert lines, messages
    eta = lines[-1].split("ETA ")[1]
    assert eta.startswith("16m") or eta.startswith("15m"), eta


def test_last_log_line_reads_progress_bars_and_missing_files(tmp_path) -> None:
    log = tmp_path / "train.log"
    assert last_log_line(log) == "starting"
    log.write_bytes(b"first\n 10%|#   |\r 20%|##  |\r\n\n")
    assert last_log_line(log) == "20%|##  |"


def test_option_errors_name_the_argument(tmp_path, monkeypatch) -> None:
    with pytest.raises(ValueError, match="backend: expected one of local, ray, found 'dask'"):
        sweep(["a"], counting_runner, tmp_path, backend="dask")
    with pytest.raises(ValueError, match="jobs: expected a positive integer, found 0"):
        sweep(["a"], counting_runner, tmp_path, jobs=0)
    with pytest.raises(ValueError, match="cpus_per_run: expected a positive number"):
        sweep(["a"], counting_runner, tmp_path, cpus_per_run=0)
    with pytest.raises(ValueError, match=r"specs: expected unique run keys, found \['a'\]"):
        sweep(["a", "b", "a"], counting_runner, tmp_path)
    with pytest.raises(ValueError, match="specs: a run key must be a relative path"):
        sweep(["../escape"], counting_runner, tmp_path)
    with pytest.raises(ValueError, match="specs: expected strings or objects with"):
        sweep([3], counting_runner, tmp_path)
    with pytest.raises(ValueError, match="address: only used by the 'ray' backend"):
        sweep(["a"], counting_runner, tmp_path, address="auto")
    monkeypatch.setitem(sys.modules, "ray", None)  # what an environment without Ray sees
    with pytest.raises(BackendUnavailableError) as caught:
        sweep(["a"], counting_runner, tmp_path / "ray", backend="ray")
    message = str(caught.value)
    assert "\n" not in message and "pip install 'leoc[ray]'" in message
    assert not (tmp_path / "ray").exists()  # nothing written before the error


def test_cli_without_ray_says_so_in_one_line(tmp_path, monkeypatch, capsys) -> None:
    monkeypatch.setitem(sys.modules, "ray", None)
    out = tmp_path / "out"
    status = main(["reproduce", "--backend", "ray", "--controllers", "linear", "--out", str(out)])
    error = capsys.readouterr().err
    assert status == 2 and error.count("\n") == 1
    assert error.startswith("leoc reproduce: error: backend: 'ray' needs the ray package")
    assert not out.exists()


@pytest.mark.skipif(not hasattr(signal, "pthread_sigmask"), reason="POSIX signals")
@pytest.mark.parametrize("delay", [0.0, 0.5])
def test_ctrl_c_while_a_worker_starts_leaves_it_to_the_driver(tmp_path, capfd, delay) -> None:
    """A Ctrl-C reaches the whole process group and can land while a worker still starts
    (at once: before Python handles SIGINT, which killed it; 0.5 s: while it imports, which
    printed a traceback from its bootstrap, as reproduce's SIGINT test met under load). The
    starting worker holds it and leaves quietly once it runs (where the signal mask passes
    to the child), or ignores it and the driver, which got it, stops it."""
    from leoc.experiments.sweep import INTERRUPTED_EXIT_CODE, _LocalBackend

    backend = _LocalBackend(counting_runner, tmp_path, 1)
    connection, process = backend._spawn()
    time.sleep(delay)
    os.kill(process.pid, signal.SIGINT)
    process.join(10.0)
    backend._idle.append((connection, process))
    backend.stop()
    assert process.exitcode in (INTERRUPTED_EXIT_CODE, -signal.SIGTERM)
    assert "Traceback" not in capfd.readouterr().err


@pytest.mark.skipif(not hasattr(signal, "pthread_sigmask"), reason="POSIX signals")
def test_a_running_worker_leaves_on_ctrl_c_with_the_interrupted_code(tmp_path, capfd) -> None:
    from leoc.experiments.sweep import INTERRUPTED_EXIT_CODE, _LocalBackend

    backend = _LocalBackend(counting_runner, tmp_path, 1)
    connection = backend.submit("quick")
    assert [outcome.kind for _, outcome in backend.wait(60.0)] == ["ok"]
    (_, process), *_ = backend._idle
    os.kill(process.pid, signal.SIGINT)
    process.join(30)
    connection.close()
    assert process.exitcode == INTERRUPTED_EXIT_CODE
    assert "Traceback" not in capfd.readouterr().err


# ------------------------------------------------------------------------ the smoke profile
@pytest.mark.slow
def test_smoke_profile_on_ray_equals_the_local_backend(tmp_path, ray_instance, smoke_study) -> None:
    """The smoke study on Ray equals, bit for bit, the session's smoke study on the local
    backend (``leoc reproduce``'s default, run once and shared with the interrupt tests)."""
    from leoc.experiments.reproduce import reproduce

    out = tmp_path / "ray"
    reproduce(
        out,
        profile_name="smoke",
        systems=["pendulum"],
        controllers=list(smoke_study.controllers),
        jobs=2,
        backend="ray",
        echo=quiet,
    )
    assert json.loads((out / "meta.json").read_text())["backend"] == "ray"
    on_ray, local = smoke_study.numbers(out), smoke_study.uninterrupted()
    assert sorted(on_ray) == sorted(local) and len(local) == len(smoke_study.controllers)
    for run, numbers in local.items():
        assert on_ray[run] == numbers, run  # bit-for-bit the same numbers


# ------------------------------------------------------------------------------------- ETA
def test_eta_deals_the_queue_to_the_first_free_worker() -> None:
    from leoc.experiments.eta import PRIOR_WEIGHT_S, Finished, Running, estimate_remaining

    # on schedule so far: 2 workers, one with 50 s left of a 100 s run (half done per its log),
    # 60 s and 10 s queued: the 60 s run goes to the free worker, the 10 s one to the worker
    # free at 50 s: max(50 + 10, 60) = 60 s
    assert estimate_remaining([], [Running(100.0, 50.0, 0.5)], [60.0, 10.0], 2) == 60.0
    assert estimate_remaining([], [Running(100.0, 50.0, 0.5)], [60.0, 30.0], 2) == 80.0
    # two short runs last do not stretch the ETA: the long running run sets it
    assert estimate_remaining([], [Running(300.0, 100.0)], [5.0, 5.0], 2) == 200.0
    # runs so far twice as slow as expected (with the prior's weight): everything scales
    finished = [Finished(100.0, 200.0)]
    factor = (200.0 + PRIOR_WEIGHT_S) / (100.0 + PRIOR_WEIGHT_S)
    assert estimate_remaining(finished, [], [50.0], 1) == pytest.approx(50.0 * factor)
    # a running run past its expectation keeps a second, not a negative time
    assert estimate_remaining([], [Running(10.0, 30.0)], [], 1) == 1.0


def test_trainer_progress_reads_ddpg_lines_and_not_pilco_lines() -> None:
    from leoc.experiments.eta import trainer_progress

    line = "[ddpg] step 2500/10000 (25%), 98 steps/s, last evaluation: return -812.3, held 0%"
    assert trainer_progress(line) == 0.25
    # PILCO's iterations do not cost alike: its line is no measure of the time done
    assert trainer_progress("[pilco] iter  2/4 predicted cost 7.1") is None
    assert trainer_progress("== pendulum/linear/seed0 (quick profile)") is None


# -------------------------------------------------------------------------- the live line
class FakeTerminal(io.StringIO):
    """What the sweep writes to, seen as a terminal."""

    def isatty(self) -> bool:
        return True


LIVE_COLUMNS = 90
BAR_LINE = re.compile(r"\d+/\d+ done \|[ #0-9]{10}\| ")


def long_log_runner(spec: str, out_dir: Path) -> dict[str, object]:
    """Logs a line longer than any terminal's, then works a little."""
    run_dir = default_run_dir(out_dir, spec)
    run_dir.mkdir(parents=True, exist_ok=True)
    (run_dir / "train.log").write_text(f"{spec}: " + "word " * 40 + "\n")
    time.sleep(QUICK_RUN_S)
    return {"spec": spec}


def screen_segments(text: str) -> list[str]:
    """Every line as drawn, carriage-return redraws apart."""
    return [part for line in text.split("\n") for part in line.split("\r")]


def test_a_terminal_gets_one_live_line_and_each_done_line_once(tmp_path, monkeypatch) -> None:
    monkeypatch.setenv("COLUMNS", str(LIVE_COLUMNS))
    terminal = FakeTerminal()
    specs = ["a", "b", "c/with/a/long/key"]
    result = sweep(
        specs,
        long_log_runner,
        tmp_path,
        jobs=2,
        progress_interval_s=0.05,
        stream=terminal,
        expected_seconds=lambda spec: QUICK_RUN_S,
    )
    assert set(result.results) == set(specs)
    text = terminal.getvalue()
    assert text.endswith("\n")  # the bar's line ended
    done = [part for part in screen_segments(text) if " done (" in part]
    assert sorted(line.split()[1] for line in done) == sorted(specs)  # once each
    assert {line.split()[0] for line in done} == {"[1/3]", "[2/3]", "[3/3]"}
    bars = []
    for part in screen_segments(text):
        if part in done or not part.strip() or part.startswith("3 runs: 0 already done"):
            continue
        assert BAR_LINE.match(part), part  # no header or run lines of the plain format
        assert len(part) < LIVE_COLUMNS, part  # cut to the terminal, never wrapped
        bars.append(part)
    assert any(" running, " in bar and "queued" in bar and "ETA" in bar for bar in bars)
    assert any(" · " in bar and bar.endswith("…") for bar in bars)  # a long log line, cut
    assert text.rstrip("\n").split("\n")[-1].split("\r")[-1].startswith("3/3 done |")
    assert "finished in" in text.rstrip("\n").split("\n")[-1]


def interrupt(_key: str) -> None:
    raise KeyboardInterrupt


def test_ctrl_c_ends_the_live_line_before_it_is_raised(tmp_path) -> None:
    terminal = FakeTerminal()
    try:
        sweep(["a", "b"], counting_runner, tmp_path, jobs=1, stream=terminal, on_finished=interrupt)
    except KeyboardInterrupt:
        # read while the exception is handled, as the command's "interrupted" is printed: the
        # traceback still holds the sweep's frame, so no garbage collection closed the bar
        text = terminal.getvalue()
    else:
        pytest.fail("the sweep swallowed the KeyboardInterrupt")
    # the caller's "interrupted" starts on a line of its own, below the bar as it stood
    assert text.endswith("\n")
    assert BAR_LINE.match(text.rstrip("\n").split("\n")[-1].split("\r")[-1])
    assert "[1/2] a done" in text


def test_without_a_terminal_the_lines_are_the_plain_ones(tmp_path, capsys) -> None:
    sweep(["first", "a"], slow_runner, tmp_path, jobs=1, progress_interval_s=0.4)
    lines = capsys.readouterr().out.splitlines()  # sys.stdout, not a terminal here
    assert lines[0] == "2 runs: 0 already done, 2 to run on 1 local worker processes"
    assert "[0s] 0 done, 1 running, 1 queued; ETA after the first run" in lines
    assert any(line.startswith("[1/2] first done (") for line in lines)
    assert any(line.startswith("  a (") and line.endswith("step 1 of 2") for line in lines)
    assert not any("\r" in line or " · " in line for line in lines)
    piped = io.StringIO()  # a stream given, not a terminal: the same plain lines there
    sweep(["b"], counting_runner, tmp_path, jobs=1, stream=piped)
    lines = piped.getvalue().splitlines()
    assert lines[0] == "1 runs: 0 already done, 1 to run on 1 local worker processes"
    assert "[0s] 0 done, 1 running, 0 queued; ETA after the first run" in lines
    assert lines[-1].startswith("[1/1] b done (") and "\r" not in piped.getvalue()
    assert capsys.readouterr().out == ""  # nothing went to stdout
