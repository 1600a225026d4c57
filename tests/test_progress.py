"""Tests of the trainers' progress (leoc.progress): live on a terminal, changed plain lines
elsewhere, an ETA for PILCO runs too, and nothing that depends on the machine's speed."""

from __future__ import annotations

import io
import re
import time

import pytest

from leoc.experiments.eta import trainer_progress
from leoc.progress import (
    MAX_PLAIN_CHARS,
    ProgressLine,
    evaluation_text,
    iterations_line,
    steps_line,
)

PILCO_TINY = dict(
    horizon=4,
    policy_iterations=2,
    num_basis=4,
    episode_steps=24,
    initial_rollouts=2,
    gp_train_iterations=3,
    eval_episodes=2,
)
STEPS_LINE = re.compile(
    r"^\[ddpg\] step 2500/10000 \(25%\), [\d.]+ steps/s, ETA (\d+h\d\dm|\d+m\d\ds|\d+s), "
    r"last evaluation: return -812\.3, held 0%$"
)


class FakeClock:
    """Seconds that move only when the test says."""

    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


@pytest.mark.parametrize("elapsed", [0.13, 25.0, 1e5])
def test_a_progress_line_has_the_same_form_on_any_machine(elapsed: float) -> None:
    """tests/test_ddpg.py wanted "..., 10" steps/s and failed when the machine stalled 0.13 s:
    the form of the line is tested here, never a rate's value."""
    evaluation = evaluation_text(-812.34, 0.0)
    line = steps_line("ddpg", 2500, 10_000, elapsed, evaluation)
    assert STEPS_LINE.match(line), line
    assert trainer_progress(line) == 0.25 and len(line) <= MAX_PLAIN_CHARS
    assert steps_line("ddpg", 0, 10_000, elapsed) == "[ddpg] step 0/10000 (0%)"


def test_plain_lines_come_when_something_changed_and_never_twice() -> None:
    clock, out = FakeClock(), io.StringIO()
    shown = ProgressLine(100, "step", "ddpg", live=False, stream=out, interval_s=10.0, clock=clock)
    shown.update(0, "line at 0")
    shown.update(0, "line at 0")  # unchanged: nothing
    clock.now = 20.0
    shown.update(0, "line at 0")  # due, but unchanged: nothing
    clock.now = 25.0
    shown.update(50, "line at 50")  # changed and due
    clock.now = 26.0
    shown.update(60, "line at 60")  # changed, not due: waits
    shown.update(60, "line at 60, evaluated", evaluation_text(-1.0, 1.0))  # a new evaluation
    clock.now = 40.0
    shown.update(70, "line at 70, evaluated", evaluation_text(-1.0, 1.0))
    assert out.getvalue().splitlines() == [
        "line at 0",
        "line at 50",
        "line at 60, evaluated",
        "line at 70, evaluated",
    ]


def test_a_live_line_on_a_terminal_is_one_bar() -> None:
    out = io.StringIO()
    shown = ProgressLine(4, "iter", "pilco", live=True, stream=out)
    for done in range(5):
        shown.update(done, f"iter {done}", evaluation_text(-10.0 * done, 0.5))
    shown.close()
    text = out.getvalue()
    assert "\n" not in text.rstrip("\n")  # one line, rewritten in place
    assert "4/4" in text and "last evaluation: return -40.0, held 50%" in text


def test_pilco_progress_without_a_terminal_has_an_eta_and_no_repeated_line(
    tmp_path, capsys
) -> None:
    from leoc.pilco.train import train_pilco

    train_pilco("pendulum", seed=0, run_dir=tmp_path, iterations=2, **PILCO_TINY)
    lines = capsys.readouterr().out.splitlines()
    assert [line.split(",")[0] for line in lines] == [
        "[pilco] iter 0/2",
        "[pilco] iter 1/2",
        "[pilco] iter 2/2",
    ]
    assert all(a != b for a, b in zip(lines, lines[1:], strict=False))
    assert all(len(line) <= MAX_PLAIN_CHARS for line in lines)
    # from the time per iteration so far: none before the first iteration
    assert "ETA" not in lines[0]
    for line in lines[1:]:
        assert re.search(r", \d+\.\d s/iter so far, ETA \d+(m\d\d)?s, last evaluation: ", line)
    assert lines[-1].split(", ")[2] == "ETA 0s"
    # a resumed run picks up where it was
    train_pilco("pendulum", seed=0, run_dir=tmp_path, iterations=3, **PILCO_TINY)
    resumed = capsys.readouterr().out.splitlines()
    assert [line.split(",")[0] for line in resumed] == ["[pilco] iter 2/3", "[pilco] iter 3/3"]


def test_iterations_line_reads_the_mean_time_per_iteration() -> None:
    line = iterations_line("pilco", 3, 10, 9.8, evaluation_text(-330.39, 1.0))
    # 7 iterations left at 9.8 s each
    assert line == (
        "[pilco] iter 3/10, 9.8 s/iter so far, ETA 1m09s, last evaluation: return -330.4, held 100%"
    )
    assert trainer_progress(line) is None  # PILCO's lines do not measure the sweep's progress


def test_a_sweep_report_shows_a_run_s_log_line_only_when_it_changed(tmp_path) -> None:
    """`leoc reproduce` printed every running run's last log line every 15 s, unchanged (a PILCO
    iteration lasts longer than that)."""
    from leoc.experiments.sweep import sweep

    messages: list[str] = []
    sweep(["slow"], _quiet_runner, tmp_path, jobs=1, progress_interval_s=0.2, echo=messages.append)
    reports = [m for m in messages if " running, " in m]
    shown = [m for m in messages if m.startswith("  slow (")]
    assert len(reports) >= 4  # a report every 0.2 s over the run's 1.2 s
    logged = [m.split(": ", 1)[1] for m in shown]
    assert "iteration 1" in logged and len(logged) == len(set(logged)) <= 3, logged


def _quiet_runner(spec: str, out_dir) -> dict[str, object]:
    from leoc.experiments.sweep import default_run_dir

    run_dir = default_run_dir(out_dir, spec)
    run_dir.mkdir(parents=True, exist_ok=True)
    with open(run_dir / "train.log", "a", buffering=1) as log:
        for iteration in (1, 2):
            log.write(f"iteration {iteration}\n")
            time.sleep(0.6)
    return {"spec": spec}
