"""The progress of a training run: one live status line on a terminal, plain lines otherwise.

On a terminal (the stream's ``isatty()``) a tqdm bar is the one live line: done/total, rate,
ETA (tqdm's, from the rate so far) and the last evaluation. Elsewhere (a log file, a pipe, the
``train.log`` of ``leoc reproduce``) a plain line is printed when something changed (the count
done or the last evaluation) and then at most every ``interval_s`` seconds, unless the last
evaluation changed, which is printed at once; a line never repeats the one before it, and is
at most ``MAX_PLAIN_CHARS`` long:

``[ddpg] step 2500/10000 (25%), 98 steps/s, ETA 1m17s, last evaluation: return -812.3, held 0%``

The ETA is the work left at the mean rate so far (DDPG/TD3/SAC: steps per second; PILCO:
seconds per iteration, whose iterations do not cost alike, so its ETA is the mean time per
iteration so far times the iterations left, and says so).
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from typing import IO, Any

PLAIN_INTERVAL_S = 10.0
"""Seconds between plain lines whose only change is the count done."""
MAX_PLAIN_CHARS = 100
"""Longest plain line of the trainers' (the tests hold them to it: no line wraps on a
100-column terminal)."""


def format_duration(seconds: float) -> str:
    """``75`` -> ``1m15s``; ``3700`` -> ``1h01m``."""
    seconds = max(0, int(round(seconds)))
    if seconds < 60:
        return f"{seconds}s"
    if seconds < 3600:
        return f"{seconds // 60}m{seconds % 60:02d}s"
    return f"{seconds // 3600}h{seconds % 3600 // 60:02d}m"


def evaluation_text(mean_return: float | None, held_fraction: float | None) -> str:
    """``last evaluation: return -812.3, held 0%`` (empty before the first evaluation)."""
    if mean_return is None or held_fraction is None:
        return ""
    return f"last evaluation: return {mean_return:.1f}, held {held_fraction:.0%}"


def steps_line(
    label: str,
    done: int,
    total: int,
    elapsed_s: float,
    evaluation: str = "",
    done_at_start: int = 0,
) -> str:
    """``[LABEL] step K/N (P%), R steps/s, ETA T, EVALUATION`` at the mean rate of the
    ``elapsed_s`` seconds since step ``done_at_start`` (a resumed run's; no rate or ETA before a
    step is done)."""
    share = done / total if total else 0.0
    text = f"[{label}] step {done}/{total} ({share:.0%})"
    if done > done_at_start and elapsed_s > 0:
        rate = (done - done_at_start) / elapsed_s
        shown = f"{rate:.0f}" if rate >= 10 else f"{rate:.2g}"
        text += f", {shown} steps/s, ETA {format_duration((total - done) / rate)}"
    return f"{text}, {evaluation}" if evaluation else text


def iterations_line(
    label: str, done: int, total: int, seconds_per_iteration: float | None, evaluation: str = ""
) -> str:
    """``[LABEL] iter K/N, S s/iter so far, ETA T, EVALUATION``: the ETA is the iterations
    left at ``seconds_per_iteration`` (the mean so far; none before the first iteration)."""
    text = f"[{label}] iter {done}/{total}"
    if seconds_per_iteration is not None:
        left = max(total - done, 0) * seconds_per_iteration
        text += f", {seconds_per_iteration:.1f} s/iter so far, ETA {format_duration(left)}"
    return f"{text}, {evaluation}" if evaluation else text


class ProgressLine:
    """One run's progress: a tqdm bar on a terminal, changed lines at most every
    ``interval_s`` seconds elsewhere (see the module docstring).

    Parameters
    ----------
    total : int
        Work to do (steps, iterations).
    unit : str
        tqdm's unit (``"step"``, ``"iter"``).
    label : str
        The bar's description (``"ddpg"``, ``"pilco"``).
    initial : int
        Work already done (a resumed run).
    live : bool, optional
        A live bar; default: whether ``stream`` is a terminal.
    stream : file, optional
        Where the output goes (default: ``sys.stdout`` for plain lines, ``sys.stderr`` for the
        bar, tqdm's default).
    interval_s : float
        Seconds between plain lines whose only change is the count.
    clock : callable
        Seconds, monotonic (tests pass a fake one).
    """

    def __init__(
        self,
        total: int,
        unit: str,
        label: str,
        initial: int = 0,
        live: bool | None = None,
        stream: IO[str] | None = None,
        interval_s: float = PLAIN_INTERVAL_S,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.stream = stream
        self.live = is_terminal(stream or sys.stderr) if live is None else live
        self.interval_s, self.clock = interval_s, clock
        self._bar: Any = None
        self._last_line = ""
        self._last_evaluation = ""
        self._last_printed = -float("inf")
        if self.live:
            from tqdm.auto import tqdm

            self._bar = tqdm(
                total=total, initial=initial, unit=unit, desc=label, leave=True, file=stream
            )

    def update(self, done: int, line: str, evaluation: str = "", force: bool = False) -> None:
        """Show ``done`` (live) or print ``line`` (plain) if due: ``evaluation`` (its text)
        changed, or ``interval_s`` passed since the last line, or ``force``; never the same
        line twice in a row."""
        if self._bar is not None:
            self._bar.update(done - self._bar.n)
            if evaluation and evaluation != self._last_evaluation:
                self._bar.set_postfix_str(evaluation)
            self._last_evaluation = evaluation
            return
        now = self.clock()
        fresh = evaluation != self._last_evaluation
        due = force or fresh or now - self._last_printed >= self.interval_s
        if due and line != self._last_line:
            print(line, file=self.stream or sys.stdout, flush=True)
            self._last_line, self._last_printed = line, now
        self._last_evaluation = evaluation

    def close(self) -> None:
        """End the live bar (nothing to do for plain lines)."""
        if self._bar is not None:
            self._bar.close()
            self._bar = None


def is_terminal(stream: Any) -> bool:
    """Whether ``stream`` is a terminal (False for one without ``isatty`` or closed)."""
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):  # no such method, or a closed stream
        return False
