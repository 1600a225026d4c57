"""Sweeps of independent runs, on this machine or on a Ray cluster, resumable and retried.

A sweep is a list of run specifications and a runner: ``runner(spec, out_dir)`` does one run,
may write anything into its run folder ``run_dir(out_dir, spec)``, and returns a JSON-ready
mapping. The driver (the process that calls :func:`sweep`) writes that mapping atomically to
``RUN_DIR/done_file``: its presence marks the run finished, on any backend, so a finished run is
never redone and an interrupted sweep resumes by being called again.

Backends
--------
``local``
    ``jobs`` spawned worker processes, each doing one run after another. A worker that dies
    (killed, out of memory) costs only the run it was doing, which is started again on a fresh
    worker.
``ray``
    One Ray task per run, requesting ``cpus_per_run`` CPUs, on a new local Ray instance or on
    an existing cluster (``address``). A worker or node that dies costs only its run, which is
    resubmitted. If the workers see the driver's ``out_dir`` (one machine, or a shared file
    system) the runner writes there directly, so a retried run resumes from its own
    checkpoints; otherwise it runs in a scratch folder on its node and the task returns the
    run folder's files, which the driver writes under ``out_dir``.

On both, a runner that raises is not retried (the error would recur); its traceback is appended
to the run's log and the sweep goes on with the other runs.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import math
import os
import shutil
import signal
import sys
import tempfile
import textwrap
import time
import traceback
import uuid
from collections import deque
from collections.abc import Callable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import IO, Any, NamedTuple

from leoc.experiments.eta import Finished, Queued, Running, estimate_remaining
from leoc.experiments.layout import LOG_FILE
from leoc.io import read_json_object, write_bytes_atomic, write_json_atomic, write_text_atomic
from leoc.names import BACKEND_NAMES
from leoc.progress import format_duration as format_seconds
from leoc.progress import is_terminal

BACKENDS = BACKEND_NAMES
DONE_FILE = "evaluation.json"
PROGRESS_INTERVAL_S = 15.0
DEFAULT_MAX_RETRIES = 2
"""Times a run is started again after its worker died (a runner's own error is not retried)."""
LOG_TAIL_BYTES = 2048
LOG_LINE_CHARS = 400
"""Longest log line shown (progress lines are wrapped to the terminal, not cut)."""
DEFAULT_TERMINAL_COLUMNS = 100
"""Width of the progress lines when the output is not a terminal."""
WRAP_INDENT = "      "
LIVE_REFRESH_S = 1.0
"""Seconds between redraws of the live status line (a terminal's: it does not scroll)."""
LIVE_BAR_CHARS = 10
"""Width of the live line's bar."""
LIVE_MIN_DETAIL_CHARS = 12
"""Fewest characters of a run's log line worth showing on the live line (else none)."""
LIVE_SEPARATOR = " · "
"""Between the live line's counts and the latest run's log line."""
TERMINATE_GRACE_S = 5.0
"""Seconds a local worker gets to exit after SIGTERM before it is killed."""
SHARE_TOKEN_FILE = ".sweep-token"
"""Written by the driver into ``out_dir``; a Ray worker that reads the same token sees the
driver's folder (same machine or shared file system) and writes its run there."""
INTERRUPTED_EXIT_CODE = 130

Runner = Callable[[Any, Path], Mapping[str, Any]]
RunDir = Callable[[Path, Any], Path]


class BackendUnavailableError(ValueError):
    """The backend asked for cannot run here (e.g. Ray is not installed)."""


class SweepResult(NamedTuple):
    """What one call of :func:`sweep` did.

    Attributes
    ----------
    results : dict key -> mapping
        The results of the runs finished in this call.
    skipped : tuple of str
        Keys of the runs already finished before this call (not run again).
    failed : dict key -> str
        Runs whose runner raised, or whose worker died more than ``max_retries`` times.
    retried : dict key -> int
        Runs started again after their worker died, and how many times.
    wall_seconds : float
    """

    results: dict[str, Mapping[str, Any]]
    skipped: tuple[str, ...]
    failed: dict[str, str]
    retried: dict[str, int]
    wall_seconds: float


class _Outcome(NamedTuple):
    """How an attempt ended: ``kind`` is "ok", "error" (runner raised) or "died" (worker)."""

    kind: str
    result: Mapping[str, Any] | None = None
    files: dict[str, bytes] | None = None
    message: str = ""
    detail: str = ""


class _Attempt(NamedTuple):
    spec: Any
    key: str
    number: int
    started: float
    resumed: bool = False  # it starts from an earlier attempt's files (its wall time is partial)


# ----------------------------------------------------------------------------------- helpers
def run_key(spec: Any) -> str:
    """The key of a run: ``spec.key`` if it has one, else ``spec`` itself if a string."""
    key = getattr(spec, "key", spec)
    if not isinstance(key, str) or not key:
        raise ValueError(
            f"specs: expected strings or objects with a non-empty string 'key', found {spec!r}"
        )
    parts = Path(key).parts
    if Path(key).is_absolute() or ".." in parts:
        raise ValueError(f"specs: a run key must be a relative path inside out_dir, found {key!r}")
    return key


def default_run_dir(out_dir: Path, spec: Any) -> Path:
    """``out_dir/runs/KEY`` (a key ``a/b/seed0`` nests folders)."""
    return Path(out_dir) / "runs" / run_key(spec)


def last_log_line(path: Path, default: str = "starting") -> str:
    """The last non-empty line of a log (carriage-return progress bars count as lines)."""
    try:
        with open(path, "rb") as handle:
            handle.seek(0, os.SEEK_END)
            handle.seek(max(0, handle.tell() - LOG_TAIL_BYTES))
            text = handle.read().decode(errors="replace")
    except OSError:
        return default
    lines = [line.strip() for line in text.replace("\r", "\n").splitlines() if line.strip()]
    return lines[-1][:LOG_LINE_CHARS] if lines else default


def terminal_columns() -> int:
    """Columns of the terminal the progress goes to (``DEFAULT_TERMINAL_COLUMNS`` if none)."""
    return shutil.get_terminal_size((DEFAULT_TERMINAL_COLUMNS, 24)).columns


def fit_lines(text: str, width: int) -> list[str]:
    """``text`` as lines of at most ``width`` characters, wrapped at spaces (continuations
    indented), runs of spaces collapsed: a narrow terminal gets more lines, never fewer
    numbers."""
    indent = len(text) - len(text.lstrip(" "))
    words = " ".join(text.split())
    return textwrap.wrap(
        words,
        width=max(width, len(WRAP_INDENT) + 20),
        initial_indent=" " * indent,
        subsequent_indent=WRAP_INDENT,
        break_long_words=False,
        break_on_hyphens=False,
    ) or [text]


def _check_options(
    backend: str, address: str | None, jobs: int | None, cpus_per_run: float, max_retries: int
) -> None:
    check_backend(backend, address)
    if jobs is not None and (isinstance(jobs, bool) or int(jobs) != jobs or jobs < 1):
        raise ValueError(f"jobs: expected a positive integer, found {jobs!r}")
    if not (math.isfinite(cpus_per_run) and cpus_per_run > 0):
        raise ValueError(f"cpus_per_run: expected a positive number, found {cpus_per_run!r}")
    if int(max_retries) != max_retries or max_retries < 0:
        raise ValueError(f"max_retries: expected a non-negative integer, found {max_retries!r}")


def _import_ray() -> Any:
    try:
        import ray
    except ImportError:
        raise BackendUnavailableError(
            "backend: 'ray' needs the ray package, which is not installed here; "
            "install it with: pip install 'leoc[ray]'"
        ) from None
    return ray


def check_backend(backend: str, address: str | None = None) -> None:
    """Raise a one-line error if ``backend`` is unknown, is ``"ray"`` without Ray installed, or
    an ``address`` comes with a backend that has no use for it."""
    if backend not in BACKENDS:
        raise ValueError(f"backend: expected one of {', '.join(BACKENDS)}, found {backend!r}")
    if address is not None and backend != "ray":
        raise ValueError(f"address: only used by the 'ray' backend, found backend {backend!r}")
    if backend == "ray":
        _import_ray()


def _finished(done: Path, echo: Callable[[str], None]) -> bool:
    """Whether ``done`` holds a run's result; a damaged one is set aside with a message naming
    it and the run counts as not done (:func:`leoc.io.read_json_object`)."""
    return read_json_object(done, echo, "result") is not None


def _describe(error: BaseException) -> str:
    return f"{type(error).__name__}: {error}".splitlines()[0]


# ------------------------------------------------------------------------------ local backend
def _run_once(runner: Runner, spec: Any, out_dir: Path) -> _Outcome:
    try:
        return _Outcome("ok", result=runner(spec, out_dir))
    except KeyboardInterrupt:
        raise
    except Exception as error:
        return _Outcome("error", message=_describe(error), detail=traceback.format_exc())


def _leave(code: int) -> None:
    """Leave a worker process at once: the interpreter's own shutdown (unloading torch and the
    rest) takes seconds, and every file of a run is closed by the time it reports."""
    for stream in (sys.stdout, sys.stderr):
        stream.flush()
    os._exit(code)


PR_SET_PDEATHSIG = 1  # prctl option (Linux): a signal sent to this process when its parent dies


def _die_with_the_driver() -> None:
    """On Linux, have the kernel SIGKILL this worker when the driver dies, however it dies
    (even SIGKILL, which runs no clean-up): an orphaned worker would otherwise finish its run
    and write into a folder that a rerun is already using. Elsewhere a no-op."""
    if not sys.platform.startswith("linux"):
        return
    import ctypes

    with contextlib.suppress(OSError, AttributeError):
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)


@contextlib.contextmanager
def _interrupts_ignored_by_new_workers() -> Iterator[None]:
    """Start worker processes with Ctrl-C ignored (POSIX, from the driver's main thread): a
    spawned child inherits an ignored SIGINT across exec, so a Ctrl-C that reaches the process
    group while it still starts (importing torch takes seconds) cannot end it with a traceback
    of its own; it takes Ctrl-C back once it runs (:func:`_take_interrupts_back`: one held by
    an inherited mask then ends it quietly, else the driver, which got the Ctrl-C, stops it).
    The driver's own Ctrl-C is held meanwhile (blocked: on Linux a blocked signal stays
    pending even while ignored) and arrives as the block is lifted."""
    import threading

    if not hasattr(signal, "pthread_sigmask") or (
        threading.current_thread() is not threading.main_thread()
    ):
        yield
        return
    signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, signal.default_int_handler if previous is None else previous)
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})


def _take_interrupts_back() -> None:
    """Ctrl-C in a worker that started with it ignored (and, where the signal mask is
    inherited, blocked: :func:`_interrupts_ignored_by_new_workers`) raises KeyboardInterrupt
    again; one that came while it started, held by the mask, arrives now."""
    signal.signal(signal.SIGINT, signal.default_int_handler)
    if hasattr(signal, "pthread_sigmask"):
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})


def _local_worker(runner: Runner, out_dir: Path, connection: Any) -> None:
    """Body of a local worker process: receive specs, run each, send back its outcome.

    ``None`` (or the driver gone) ends it. Runs share the process one after the other, so the
    imports (torch, leoc: seconds per process) are paid once per worker, as in a process pool.
    """
    _die_with_the_driver()
    try:
        _take_interrupts_back()
        while True:
            try:
                spec = connection.recv()
            except (EOFError, OSError):
                spec = None
            if spec is None:
                _leave(0)
            outcome = _run_once(runner, spec, out_dir)
            try:
                connection.send(outcome)
            except Exception as error:  # pickling fails before anything is sent
                message = f"runner: expected a picklable result, {_describe(error)}"
                connection.send(_Outcome("error", message=message, detail=traceback.format_exc()))
    except KeyboardInterrupt:
        # Ctrl-C reaches the whole process group: the driver stops the sweep, the worker just
        # leaves, without a traceback of its own
        _leave(INTERRUPTED_EXIT_CODE)


class _LocalBackend:
    """Up to ``jobs`` worker processes (spawned), reused from run to run; a worker that dies
    costs only the run it was doing, and a fresh one takes its place."""

    def __init__(self, runner: Runner, out_dir: Path, jobs: int) -> None:
        import multiprocessing

        self._context = multiprocessing.get_context("spawn")
        self._runner, self._out_dir, self._jobs = runner, out_dir, jobs
        self._busy: dict[Any, Any] = {}  # driver's end of the pipe -> process
        self._idle: list[tuple[Any, Any]] = []

    def describe(self) -> str:
        return f"{self._jobs} local worker processes"

    def slots(self) -> int:
        return self._jobs

    def _spawn(self) -> tuple[Any, Any]:
        connection, child_end = self._context.Pipe()
        process = self._context.Process(
            target=_local_worker, args=(self._runner, self._out_dir, child_end)
        )
        try:
            with _interrupts_ignored_by_new_workers():
                process.start()
        except BaseException:  # the driver's own Ctrl-C, held during the start: no orphan
            if process.pid is not None:
                process.kill()
                process.join()
            raise
        child_end.close()  # the child holds the only other end: its death reads as end of file
        return connection, process

    def submit(self, spec: Any) -> Any:
        connection, process = self._idle.pop() if self._idle else self._spawn()
        connection.send(spec)
        self._busy[connection] = process
        return connection  # one run at a time per worker: the pipe names the run

    def wait(self, timeout: float) -> list[tuple[Any, _Outcome]]:
        from multiprocessing.connection import wait

        finished = []
        for connection in wait(list(self._busy), timeout):
            process = self._busy.pop(connection)
            try:
                outcome = connection.recv()
            except (EOFError, OSError):
                process.join(TERMINATE_GRACE_S)
                connection.close()
                code = process.exitcode
                outcome = _Outcome("died", message=f"worker process died (exit code {code})")
            else:
                self._idle.append((connection, process))
            finished.append((connection, outcome))
        return finished

    def stop(self) -> None:
        workers = list(self._busy.items()) + self._idle
        self._busy, self._idle = {}, []
        for _, process in workers:
            if process.is_alive():
                process.terminate()
        deadline = time.monotonic() + TERMINATE_GRACE_S
        for connection, process in workers:
            process.join(max(0.0, deadline - time.monotonic()))
            if process.is_alive():
                process.kill()
                process.join()
            connection.close()

    def close(self) -> None:
        for connection, _ in self._idle:
            with contextlib.suppress(OSError):
                connection.send(None)
        deadline = time.monotonic() + TERMINATE_GRACE_S
        for _, process in self._idle:
            process.join(max(0.0, deadline - time.monotonic()))
        self.stop()  # whatever did not leave, and any still busy


# -------------------------------------------------------------------------------- Ray backend
def _sees_driver_folder(out_dir: Path, token: str) -> bool:
    try:
        return (out_dir / SHARE_TOKEN_FILE).read_text() == token
    except OSError:
        return False


def _folder_files(folder: Path) -> dict[str, bytes]:
    return {
        path.relative_to(folder).as_posix(): path.read_bytes()
        for path in sorted(folder.rglob("*"))
        if path.is_file()
    }


def _ray_task(
    runner: Runner, spec: Any, out_dir: str, run_dir: RunDir, token: str | None
) -> dict[str, Any]:
    """Body of a Ray task: the run in the driver's folder if visible (``token`` found there),
    else in a scratch folder whose run folder is shipped back. A runner's error comes back as
    a value, with its traceback, exactly as from a local worker."""
    out = Path(out_dir)
    try:
        if token is not None and _sees_driver_folder(out, token):
            return {"result": runner(spec, out), "files": None}
        with tempfile.TemporaryDirectory(prefix="leoc-sweep-") as scratch:
            result = runner(spec, Path(scratch))
            files = _folder_files(run_dir(Path(scratch), spec))
        return {"result": result, "files": files}
    except Exception as error:
        return {"error": _describe(error), "detail": traceback.format_exc()}


class _RayBackend:
    """One Ray task per run, ``cpus_per_run`` CPUs each; worker deaths are reported, not
    retried by Ray, so the driver counts and reports them."""

    def __init__(
        self,
        runner: Runner,
        out_dir: Path,
        run_dir: RunDir,
        jobs: int | None,
        cpus_per_run: float,
        address: str | None,
        shared_out_dir: bool | None,
    ) -> None:
        ray = _import_ray()
        self._ray = ray
        self._started = not ray.is_initialized()
        if self._started:
            if address is None:  # a private instance on this machine, sized by jobs
                cpus = None if jobs is None else max(1, math.ceil(jobs * cpus_per_run))
                ray.init(
                    address="local", num_cpus=cpus, include_dashboard=False, log_to_driver=False
                )
            else:
                ray.init(address=address, log_to_driver=False)
        self._token: str | None = None
        if shared_out_dir is not False:
            self._token = uuid.uuid4().hex
            try:
                write_text_atomic(out_dir / SHARE_TOKEN_FILE, self._token)
            except BaseException:
                if self._started:
                    ray.shutdown()
                raise
        self._task = ray.remote(_ray_task).options(num_cpus=cpus_per_run, max_retries=0)
        self._runner, self._out_dir, self._run_dir = runner, out_dir, run_dir
        self._jobs, self._cpus_per_run = jobs, cpus_per_run
        self._refs: set[Any] = set()

    def describe(self) -> str:
        cpus = self._ray.cluster_resources().get("CPU", 0)
        return f"a Ray cluster of {cpus:g} CPUs ({self._cpus_per_run:g} per run)"

    def slots(self) -> int:
        if self._jobs is not None:
            return self._jobs
        # asked again at each step: nodes that join the cluster while it runs are used
        cpus = self._ray.cluster_resources().get("CPU", 0)
        return max(1, int(cpus // self._cpus_per_run))

    def submit(self, spec: Any) -> Any:
        ref = self._task.remote(self._runner, spec, str(self._out_dir), self._run_dir, self._token)
        self._refs.add(ref)
        return ref

    def _outcome(self, ref: Any) -> _Outcome:
        exceptions = self._ray.exceptions
        try:
            value = self._ray.get(ref)
        except exceptions.RayTaskError as error:  # failed outside the runner (e.g. imports)
            cause = getattr(error, "cause", None) or error
            return _Outcome("error", message=_describe(cause), detail=str(error))
        except exceptions.RayError as error:  # the worker or its node died
            return _Outcome("died", message=_describe(error))
        if "error" in value:
            return _Outcome("error", message=value["error"], detail=value["detail"])
        return _Outcome("ok", result=value["result"], files=value["files"])

    def wait(self, timeout: float) -> list[tuple[Any, _Outcome]]:
        if not self._refs:
            time.sleep(timeout)
            return []
        ready, _ = self._ray.wait(list(self._refs), num_returns=1, timeout=timeout)
        if ready:  # collect every other one already finished too
            rest = [ref for ref in self._refs if ref not in ready]
            more, _ = self._ray.wait(rest, num_returns=len(rest), timeout=0) if rest else ([], [])
            ready = list(ready) + list(more)
        finished = []
        for ref in ready:
            self._refs.discard(ref)
            finished.append((ref, self._outcome(ref)))
        return finished

    def stop(self) -> None:
        for ref in self._refs:
            self._ray.cancel(ref, force=True)
        self._refs.clear()

    def close(self) -> None:
        self.stop()
        if self._token is not None:
            (self._out_dir / SHARE_TOKEN_FILE).unlink(missing_ok=True)
        if self._started:
            self._ray.shutdown()


# -------------------------------------------------------------------------------- live line


def _is_builtin_print(echo: Any) -> bool:
    """Whether ``echo`` is Python's ``print``, by name: not ``echo is print``, since some
    libraries replace ``builtins.print`` once imported (Ray's tqdm does), after the callers'
    defaults took the original."""
    return getattr(echo, "__module__", None) == "builtins" and (
        getattr(echo, "__name__", None) == "print"
    )


def shorten(text: str, width: int) -> str:
    """``text`` with runs of spaces collapsed, cut to ``width`` characters with an ellipsis."""
    words = " ".join(text.split())
    return words if len(words) <= width else words[: max(0, width - 1)] + "…"


def _live_columns() -> int:
    """The live line's width: the terminal's less one column (a line that fills the last
    column wraps on some terminals, and a wrapped line is no longer redrawn in place)."""
    return terminal_columns() - 1


class _LiveStatus:
    """The sweep's one live line on a terminal: a tqdm bar over the runs to do, its description
    the counts, the ETA and the latest run's log line, redrawn in place; finished and failed
    runs are written above it (:meth:`write`), so they stay in the scrollback.

    ``N/TOTAL done |####      | [ELAPSED] R running, Q queued, ETA T · KEY (AGE): LOG LINE``
    """

    def __init__(self, total: int, stream: IO[str]) -> None:
        from tqdm import tqdm

        self.stream = stream
        self._bar: Any = tqdm(
            total=total,
            file=stream,
            bar_format=f"{{n_fmt}}/{{total_fmt}} done |{{bar:{LIVE_BAR_CHARS}}}| {{desc}}",
            ncols=_live_columns(),
            mininterval=0,  # the driver sets the pace (LIVE_REFRESH_S)
            leave=True,
        )

    def write(self, line: str) -> None:
        """A permanent line above the bar (tqdm clears the bar, writes, redraws it)."""
        if self._bar is None:
            print(line, file=self.stream, flush=True)
        else:
            self._bar.write(line, file=self.stream)

    def show(self, done: int, status: str, detail: str = "") -> None:
        """Redraw: ``done`` runs, ``status`` whole, then ``detail`` shortened to what the
        terminal's width leaves (dropped if under ``LIVE_MIN_DETAIL_CHARS``)."""
        if self._bar is None:
            return
        width = _live_columns()
        fixed = len(f"{done}/{self._bar.total} done |") + LIVE_BAR_CHARS + len("| ")
        room = width - fixed - len(status) - len(LIVE_SEPARATOR)
        text = status
        if detail and room >= LIVE_MIN_DETAIL_CHARS:
            text += LIVE_SEPARATOR + shorten(detail, room)
        self._bar.ncols = width  # tqdm cuts what is still too long (a narrow terminal)
        self._bar.n = done
        self._bar.set_description_str(text, refresh=False)
        self._bar.refresh()

    def close(self) -> None:
        """Leave the bar drawn as it stands and end its line (idempotent): what follows, an
        "interrupted" message included, starts on a line of its own."""
        if self._bar is not None:
            self._bar.close()
            self._bar = None


# ------------------------------------------------------------------------------------ driver
class _Driver:
    """Keeps the slots busy, records outcomes, retries dead workers, prints progress."""

    def __init__(
        self,
        backend: Any,
        out_dir: Path,
        run_dir: RunDir,
        done_file: str,
        log_file: str | None,
        max_retries: int,
        echo: Callable[[str], None],
        expected_seconds: Callable[[Any], float] | None = None,
        progress_of: Callable[[str], float | None] | None = None,
        on_finished: Callable[[str], None] | None = None,
        kind_of: Callable[[Any], str] | None = None,
    ) -> None:
        self.expected_seconds, self.progress_of = expected_seconds, progress_of
        self.kind_of = kind_of or (lambda spec: "")
        self.on_finished = on_finished
        self.finished: list[Finished] = []
        self.backend, self.out_dir, self.run_dir = backend, out_dir, run_dir
        self.done_file, self.log_file, self.max_retries, self.echo = (
            done_file,
            log_file,
            max_retries,
            echo,
        )
        self.results: dict[str, Mapping[str, Any]] = {}
        self.failed: dict[str, str] = {}
        self.retried: dict[str, int] = {}
        self.durations: list[float] = []
        self.running: dict[Any, _Attempt] = {}
        self._shown: dict[tuple[str, int], str] = {}  # each attempt's log line last shown
        self._changed_at: dict[tuple[str, int], float] = {}  # when that line last changed
        self.live: _LiveStatus | None = None  # the live line on a terminal, else plain lines

    def _done_path(self, spec: Any) -> Path:
        return self.run_dir(self.out_dir, spec) / self.done_file

    def _write(self, run_dir: Path, outcome: _Outcome) -> _Outcome:
        """Write a run's shipped files, then its result (last: it marks the run done)."""
        if not isinstance(outcome.result, Mapping):
            found = type(outcome.result).__name__
            return _Outcome("error", message=f"runner: expected a mapping, found {found}")
        for name, data in (outcome.files or {}).items():
            if name != self.done_file:
                write_bytes_atomic(run_dir / name, data)
        try:
            write_json_atomic(run_dir / self.done_file, dict(outcome.result))
        except (TypeError, ValueError) as error:
            message = f"runner: expected a JSON-serialisable mapping, {_describe(error)}"
            return _Outcome("error", message=message)
        return outcome

    def _record(self, attempt: _Attempt, outcome: _Outcome, total: int) -> _Attempt | None:
        """Write a finished run; returns the next attempt when the run is to be retried."""
        run_dir = self.run_dir(self.out_dir, attempt.spec)
        wall = time.monotonic() - attempt.started
        if outcome.kind == "ok":
            outcome = self._write(run_dir, outcome)
        if outcome.kind == "ok":
            self.results[attempt.key] = outcome.result
            expected = self._expected(attempt.spec)
            if not attempt.resumed:  # a resumed run's wall time is only part of its work
                self.durations.append(wall)
                if expected is not None:
                    self.finished.append(Finished(expected, wall, self.kind_of(attempt.spec)))
            self.echo(f"[{len(self.results)}/{total}] {attempt.key} done ({wall:.0f} s)")
            if self.on_finished is not None:
                self.on_finished(attempt.key)
            return None
        if outcome.kind == "died" and attempt.number <= self.max_retries:
            self.retried[attempt.key] = attempt.number
            self.echo(
                f"  {attempt.key}: {outcome.message}; retrying "
                f"(attempt {attempt.number + 1} of {self.max_retries + 1})"
            )
            return attempt._replace(number=attempt.number + 1, resumed=True)
        self.failed[attempt.key] = outcome.message
        self.echo(f"  {attempt.key} FAILED: {outcome.message}")
        if self.log_file is not None:
            log = run_dir / self.log_file
            run_dir.mkdir(parents=True, exist_ok=True)
            with open(log, "a") as handle:
                handle.write(f"\n== sweep: the run failed\n{outcome.detail or outcome.message}\n")
            self.echo(f"  see {log}")
        return None

    def _expected(self, spec: Any) -> float | None:
        """A run's expected wall time: the caller's cost model, else the mean wall time of the
        runs finished so far (None before the first)."""
        if self.expected_seconds is not None:
            return float(self.expected_seconds(spec))
        return sum(self.durations) / len(self.durations) if self.durations else None

    def _log_line(self, attempt: _Attempt) -> str:
        if self.log_file is None:
            return "running"
        log = self.run_dir(self.out_dir, attempt.spec) / self.log_file
        return last_log_line(log, default="running")

    def _eta(self, now: float, pending: Sequence[_Attempt], lines: dict[str, str]) -> str:
        costs = [(self._expected(attempt.spec), self.kind_of(attempt.spec)) for attempt in pending]
        running = []
        for attempt in self.running.values():
            expected = self._expected(attempt.spec)
            fraction = self.progress_of(lines[attempt.key]) if self.progress_of else None
            kind = self.kind_of(attempt.spec)
            elapsed = now - attempt.started
            running.append(
                (expected, Running(expected or 0.0, elapsed, fraction, kind, not attempt.resumed))
            )
        if any(cost is None for cost, _ in costs) or any(e is None for e, _ in running):
            return "ETA after the first run"
        queued = [Queued(cost, kind) for cost, kind in costs]  # type: ignore[arg-type]
        remaining = estimate_remaining(
            self.finished, [run for _, run in running], queued, self.backend.slots()
        )
        return f"ETA {format_seconds(remaining)}"

    def _latest(self, now: float, lines: dict[str, str]) -> str:
        """``KEY (AGE): LOG LINE`` of the running run whose log line changed last (the first
        key of those that changed together); empty when none runs."""
        latest, latest_at = "", -math.inf
        for attempt in sorted(self.running.values(), key=lambda a: a.key):
            shown = (attempt.key, attempt.number)
            if self._shown.get(shown) != lines[attempt.key]:
                self._shown[shown], self._changed_at[shown] = lines[attempt.key], now
            if self._changed_at[shown] > latest_at:
                age = format_seconds(now - attempt.started)
                latest = f"{attempt.key} ({age}): {lines[attempt.key]}"
                latest_at = self._changed_at[shown]
        return latest

    def _live_progress(
        self, live: _LiveStatus, started: float, pending: Sequence[_Attempt]
    ) -> None:
        now = time.monotonic()
        lines = {attempt.key: self._log_line(attempt) for attempt in self.running.values()}
        failed = f", {len(self.failed)} failed" if self.failed else ""
        status = (
            f"[{format_seconds(now - started)}] {len(self.running)} running, "
            f"{len(pending)} queued{failed}, {self._eta(now, pending, lines)}"
        )
        live.show(len(self.results), status, self._latest(now, lines))

    def _progress(self, started: float, pending: Sequence[_Attempt]) -> None:
        if self.live is not None:
            self._live_progress(self.live, started, pending)
            return
        now = time.monotonic()
        lines = {attempt.key: self._log_line(attempt) for attempt in self.running.values()}
        width = terminal_columns()
        header = (
            f"[{format_seconds(now - started)}] {len(self.results)} done, "
            f"{len(self.running)} running, {len(pending)} queued; "
            f"{self._eta(now, pending, lines)}"
        )
        for line in fit_lines(header, width):
            self.echo(line)
        for attempt in sorted(self.running.values(), key=lambda a: a.key):
            shown = (attempt.key, attempt.number)
            if self._shown.get(shown) == lines[attempt.key]:
                continue  # its log has not moved since the last report: no repeated line
            self._shown[shown] = lines[attempt.key]
            age = format_seconds(now - attempt.started)
            for line in fit_lines(f"  {attempt.key} ({age}): {lines[attempt.key]}", width):
                self.echo(line)

    def run(self, pending: deque[_Attempt], progress_interval_s: float) -> None:
        started = time.monotonic()
        total = len(pending)
        if self.live is not None:  # a live line costs no scrollback: redraw it often
            progress_interval_s = min(progress_interval_s, LIVE_REFRESH_S)
        next_progress = started  # the first report (and ETA) as soon as the first runs start
        while pending or self.running:
            while pending and len(self.running) < self.backend.slots():
                attempt = pending.popleft()
                if self._done_path(attempt.spec).is_file():  # finished meanwhile elsewhere
                    continue
                attempt = attempt._replace(started=time.monotonic())
                self.running[self.backend.submit(attempt.spec)] = attempt
            timeout = max(0.0, next_progress - time.monotonic())
            for handle, outcome in self.backend.wait(timeout):
                retry = self._record(self.running.pop(handle), outcome, total)
                if retry is not None:
                    pending.appendleft(retry)
                if self.live is not None:
                    next_progress = time.monotonic()  # the count on the live line, at once
            if time.monotonic() >= next_progress and (pending or self.running):
                self._progress(started, pending)
                next_progress = time.monotonic() + progress_interval_s
        if self.live is not None:
            failed = f", {len(self.failed)} failed" if self.failed else ""
            elapsed = format_seconds(time.monotonic() - started)
            self.live.show(len(self.results), f"finished in {elapsed}{failed}")


@dataclasses.dataclass(frozen=True)
class Sweep:
    """A sweep's runner, folder, backend and reporting: :func:`sweep` takes these fields as
    keyword arguments, with the same defaults.

    Attributes
    ----------
    runner : callable ``(spec, out_dir) -> mapping``
        Does one run. It may write into ``run_dir(out_dir, spec)`` (and should log progress to
        ``log_file`` there) and returns a JSON-ready mapping, which the driver writes to
        ``done_file``. It must pickle (a module-level function or class instance). On the Ray
        backend without a shared file system, ``out_dir`` is a scratch folder on the worker.
    out_dir : path
        The sweep's folder (``out_dir/runs/KEY`` by default, see ``run_dir``).
    backend : {"local", "ray"}
    jobs : int, optional
        Runs at a time. Default: local, the CPU count divided by ``cpus_per_run``; Ray, as many
        as the cluster's CPUs allow, re-read while the sweep runs (nodes may join).
    address : str, optional
        Ray only: ``None`` starts a private Ray instance on this machine (stopped at the end);
        ``"auto"`` joins the cluster this machine belongs to (``ray start``), ``"HOST:PORT"`` the
        cluster of that head node. Ignored if Ray is already initialised in this process.
    cpus_per_run : float
        CPUs requested by each run's Ray task (default 1).
    shared_out_dir : bool, optional
        Ray only: whether workers write into ``out_dir`` itself. ``None`` (default) finds out
        (the driver leaves a token in ``out_dir`` that a worker on the same machine or on a
        shared file system reads back); ``False`` always runs in a scratch folder on the
        worker's node and ships the run folder back (e.g. to keep training I/O off a slow
        network file system). A retried run resumes from its checkpoints only when shared.
    run_dir : callable ``(out_dir, spec) -> Path``
        A run's folder (default ``out_dir/runs/KEY``). Must pickle.
    done_file, log_file : str
        Names inside the run folder: the result (its presence marks a finished run) and the
        runner's log, whose last line the progress shows (``None``: no log).
    max_retries : int
        Times a run is started again after its worker process, Ray worker or node died.
    progress_interval_s : float
        Seconds between progress reports (done / running / queued, elapsed, ETA, and each
        running run's last log line when it changed since the last report); the first comes as
        soon as the first runs start.
    echo : callable
        Receives every progress line (default ``print``); lines are wrapped to the terminal's
        width. With the default, the lines go to ``stream``, and if that is a terminal the
        progress is one live status line instead (a tqdm bar over the runs to do: counts,
        elapsed, ETA and the log line of the run that moved last, cut to the terminal's
        width), with each finished or failed run's line written above it.
    stream : file, optional
        Where the default ``echo`` writes (default: ``sys.stdout`` at the time of the call);
        ignored with another ``echo``.
    expected_seconds : callable ``spec -> float``, optional
        Expected wall time of a run on one worker (e.g. the profile's measured costs); the ETA
        is then shown from the first report and refined as runs progress
        (:mod:`leoc.experiments.eta`). Default: the mean wall time of the finished runs, so no
        ETA before the first one finishes.
    progress_of : callable ``log line -> fraction or None``, optional
        Reads how far a running run is from its last log line
        (:func:`leoc.experiments.eta.trainer_progress`).
    on_finished : callable ``key -> None``, optional
        Called in the driver after each run's result is written (e.g. to keep a log of the
        invocation current, so that a machine lost mid-sweep loses at most the runs in flight).
    kind_of : callable ``spec -> str``, optional
        The kind of a run: runs of one kind share their speed factor in the ETA (e.g. the
        learner; :func:`leoc.experiments.eta.kind_factors`). Default: one kind for all.


    Raises
    ------
    BackendUnavailableError
        From :meth:`run`: ``backend="ray"`` without Ray installed (one line saying how to
        install it).
    ValueError
        From :meth:`run`: an option out of range, or a run key that is not unique.
    """

    runner: Runner
    out_dir: str | Path
    backend: str = "local"
    jobs: int | None = None
    address: str | None = None
    cpus_per_run: float = 1.0
    shared_out_dir: bool | None = None
    run_dir: RunDir = default_run_dir
    done_file: str = DONE_FILE
    log_file: str | None = LOG_FILE
    max_retries: int = DEFAULT_MAX_RETRIES
    progress_interval_s: float = PROGRESS_INTERVAL_S
    echo: Callable[[str], None] = print
    stream: IO[str] | None = None
    expected_seconds: Callable[[Any], float] | None = None
    progress_of: Callable[[str], float | None] | None = None
    on_finished: Callable[[str], None] | None = None
    kind_of: Callable[[Any], str] | None = None

    def run(self, specs: Sequence[Any]) -> SweepResult:
        """Run every spec of ``specs`` not finished yet (see :func:`sweep`)."""
        _check_options(self.backend, self.address, self.jobs, self.cpus_per_run, self.max_retries)
        out = Path(self.out_dir)
        keys = _unique_keys(specs)
        begun = time.monotonic()
        echo, terminal = self._echo()
        pending: deque[_Attempt] = deque()
        skipped: list[str] = []
        for spec, key in zip(specs, keys, strict=True):
            if _finished(self.run_dir(out, spec) / self.done_file, echo):
                skipped.append(key)
            else:
                started = _has_files(self.run_dir(out, spec))
                pending.append(_Attempt(spec, key, 1, 0.0, started))
        out.mkdir(parents=True, exist_ok=True)
        if not pending:
            echo(f"{len(keys)} runs: {len(skipped)} already done, 0 to run")
            return SweepResult({}, tuple(skipped), {}, {}, time.monotonic() - begun)
        engine = self._engine(out)
        driver = _Driver(
            engine,
            out,
            self.run_dir,
            self.done_file,
            self.log_file,
            self.max_retries,
            echo,
            self.expected_seconds,
            self.progress_of,
            self.on_finished,
            self.kind_of,
        )
        counts = f"{len(keys)} runs: {len(skipped)} already done, {len(pending)} to run"
        resumed = sum(attempt.resumed for attempt in pending)
        if resumed:
            counts += f" ({resumed} begun by an earlier invocation: the ETA is not timed on them)"
        _drive(driver, engine, pending, self.progress_interval_s, terminal, counts)
        return SweepResult(
            driver.results, tuple(skipped), driver.failed, driver.retried, time.monotonic() - begun
        )

    def _echo(self) -> tuple[Callable[[str], None], IO[str] | None]:
        """The progress lines' writer, and the terminal of a live status line (or None): the
        default ``echo`` writes to ``stream`` (``sys.stdout`` now), live if a terminal."""
        if not _is_builtin_print(self.echo):
            return self.echo, None
        target = sys.stdout if self.stream is None else self.stream
        terminal = target if is_terminal(target) else None
        return functools.partial(print, file=target, flush=True), terminal

    def _engine(self, out: Path) -> Any:
        """The backend that runs the attempts."""
        if self.backend == "local":
            slots = self.jobs or max(1, int((os.cpu_count() or 1) // self.cpus_per_run))
            return _LocalBackend(self.runner, out, slots)
        return _RayBackend(
            self.runner,
            out,
            self.run_dir,
            self.jobs,
            self.cpus_per_run,
            self.address,
            self.shared_out_dir,
        )


def _has_files(run_dir: Path) -> bool:
    """Whether a run's folder holds anything yet (an earlier invocation began the run)."""
    return run_dir.is_dir() and any(run_dir.iterdir())


def _unique_keys(specs: Sequence[Any]) -> list[str]:
    """The specs' run keys; raises ValueError naming any that is not unique."""
    keys = [run_key(spec) for spec in specs]
    duplicates = sorted({key for key in keys if keys.count(key) > 1})
    if duplicates:
        raise ValueError(f"specs: expected unique run keys, found {duplicates} more than once")
    return keys


def _drive(
    driver: _Driver,
    engine: Any,
    pending: deque[_Attempt],
    progress_interval_s: float,
    terminal: IO[str] | None,
    counts: str,
) -> None:
    """Say ``counts`` and where the runs run, run the pending attempts to the end (live on
    ``terminal`` if given); on Ctrl-C stop the workers and re-raise; close the backend either
    way."""
    try:
        driver.echo(f"{counts} on {engine.describe()}")
        if terminal is not None:
            driver.live = _LiveStatus(len(pending), terminal)
            driver.echo = driver.live.write
        try:
            driver.run(pending, progress_interval_s)
        finally:
            if driver.live is not None:
                # the bar's line ends before anything else is said (Ctrl-C's "interrupted"
                # included) and before the workers are stopped, which may take seconds
                driver.live.close()
    except KeyboardInterrupt:
        # the caller says it was interrupted (the leoc command prints one line with how to
        # resume); a second line here would repeat it
        engine.stop()
        raise
    finally:
        engine.close()


def sweep(specs: Sequence[Any], runner: Runner, out_dir: str | Path, **options: Any) -> SweepResult:
    """Run every spec not finished yet, on this machine or on a Ray cluster:
    ``Sweep(runner, out_dir, **options).run(specs)``.

    Parameters
    ----------
    specs : sequence
        Run specifications: strings, or objects with a string ``key`` (e.g.
        :class:`leoc.experiments.profiles.RunSpec`); keys are unique relative paths. A spec is
        passed to the runner as is (it must pickle).
    runner : callable ``(spec, out_dir) -> mapping``
        Does one run (:class:`Sweep`).
    out_dir : path
    **options
        The keyword options of :class:`Sweep` (backend, jobs, address, cpus_per_run,
        shared_out_dir, run_dir, done_file, log_file, max_retries, progress_interval_s, echo,
        stream, expected_seconds, progress_of, on_finished, kind_of), same defaults.

    Returns
    -------
    SweepResult

    Raises
    ------
    BackendUnavailableError
        ``backend="ray"`` without Ray installed (one line saying how to install it).
    ValueError
        An option out of range, or a run key that is not unique.
    """
    return Sweep(runner, out_dir, **options).run(specs)
