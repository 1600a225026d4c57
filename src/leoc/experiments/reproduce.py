"""``leoc reproduce``: train (or design) and evaluate every controller of the paper, in parallel
worker processes, resumable, and write the report.

The layout of an output folder is :mod:`leoc.experiments.layout`. A run whose
``evaluation.json`` exists is skipped on rerun; an interrupted run is started again
(PILCO resumes from its own checkpoint). Nothing is ever half-written: every file goes through a
temporary file and ``os.replace``.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import platform
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np
import torch

from leoc.experiments.eta import trainer_progress
from leoc.experiments.evaluators import evaluate_controller
from leoc.experiments.layout import EVALUATION_FILE, LOG_FILE, META_FILE, run_dir_of
from leoc.experiments.profiles import (
    DEFAULT_CONTROLLERS,
    Profile,
    RunSpec,
    get_profile,
    run_specs,
)
from leoc.experiments.sweep import check_backend, sweep
from leoc.experiments.variants import LEOC, Variant, get_variant
from leoc.io import read_json_object, write_json_atomic
from leoc.learners import get_learner
from leoc.systems import SYSTEM_NAMES
from leoc.systems.base import System

WORKER_THREADS = 1


def versions() -> dict[str, str]:
    """Versions of Python and of the libraries that shape the numbers."""
    import gymnasium

    import leoc

    found = {"python": platform.python_version(), "leoc": leoc.__version__}
    found.update({"numpy": np.__version__, "torch": torch.__version__})
    found["gymnasium"] = gymnasium.__version__
    for module in ("scipy", "control", "stable_baselines3"):
        with contextlib.suppress(ImportError):
            found[module] = __import__(module).__version__
    commit = code_commit()
    if commit is not None:
        found["leoc_commit"] = commit
    return found


def machine() -> dict[str, Any]:
    """The machine an invocation runs on (with Ray: the driver's; the workers may differ): OS,
    architecture, CPU model, logical CPUs, memory, and the vector kernels torch runs (PILCO's
    outcome on a seed can change with them: AVX2 against AVX-512, see the PILCO guide)."""
    found: dict[str, Any] = {
        "platform": platform.platform(),
        "architecture": platform.machine(),
        "cpu": platform.processor() or "unknown",
        "logical_cpus": os.cpu_count(),
        "torch_cpu_capability": torch.backends.cpu.get_cpu_capability(),
    }
    with contextlib.suppress(OSError):
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                found["cpu"] = line.partition(":")[2].strip()
                break
    with contextlib.suppress(ValueError, OSError, AttributeError):
        pages, size = os.sysconf("SC_PHYS_PAGES"), os.sysconf("SC_PAGE_SIZE")
        found["memory_gib"] = round(pages * size / 2**30, 1)
    return found


def code_commit() -> str | None:
    """The git commit of the leoc source that runs (``+dirty`` when tracked files differ from
    it), or None outside a git checkout: runs of one study that span several invocations can
    then be checked to come from one code version."""
    import leoc

    source = Path(leoc.__file__).resolve().parent
    try:
        head = subprocess.run(
            ["git", "-C", str(source), "rev-parse", "--short=12", "HEAD"],
            capture_output=True,
            text=True,
            timeout=10,
            check=True,
        ).stdout.strip()
        changed = subprocess.run(
            ["git", "-C", str(source), "status", "--porcelain", "--untracked-files=no", "."],
            capture_output=True,
            text=True,
            timeout=10,
            check=True,
        ).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return None
    return f"{head}+dirty" if changed else head


# ---------------------------------------------------------------------------------- training
def _curve(rows: Sequence[dict[str, Any]], summary: dict[str, Any]) -> dict[str, Any]:
    """Return against interaction seconds of a learning curve (the trainer contract's rows),
    and the model selection the trainer recorded (its summary's ``model_selection``)."""
    return {
        "seconds": [float(row["interaction_seconds"]) for row in rows],
        "returns": [float(row["mean_return"]) for row in rows],
        "held_fraction": [float(row["held_fraction"]) for row in rows],
        "model_selection": summary.get("model_selection"),
    }


def pilco_action_repeat(profile: Profile, system: str, variant: Variant = LEOC) -> int:
    """The control period PILCO's controllers run at on ``system`` under ``profile`` and
    ``variant`` (the period they are deployed at: the authors train holding each action 3 steps
    but deploy every step)."""
    from leoc.pilco.config import PilcoConfig

    settings = {**variant.training_settings("pilco", system, True), **profile.pilco_overrides}
    return PilcoConfig.for_system(system, **settings).controller_action_repeat


def train_controller(
    spec: RunSpec,
    profile: Profile,
    train_dir: Path,
    variant: Variant = LEOC,
    system: System | None = None,
) -> tuple[torch.nn.Module, dict[str, Any] | None]:
    """Design (linear) or train one controller under ``variant``; returns it (at its control
    period) and its learning curve. ``system``: the run's system, built once by the caller
    (default: ``variant.system(spec.system)``); trained by the learner its controller names
    (:func:`leoc.learners.get_learner`)."""
    system = variant.system(spec.system) if system is None else system
    controller = spec.controller_spec
    if controller.linear:
        repeat = 1
        if controller.period_of is not None:
            repeat = pilco_action_repeat(profile, spec.system, variant)
        return variant.linear_controller(system, repeat), None
    # the variant's settings, then the profile's budgets and overrides; SAC runs at DDPG's
    # budgets and with the profile's DDPG overrides
    settings = profile.training_settings(variant, controller, spec.system)
    learner = get_learner(controller.learner)
    result = learner.train(system, controller, spec.seed, train_dir, settings)
    return result.policy, _curve(result.curve, result.summary)


def execute_run(
    spec: RunSpec, profile: Profile, out_dir: Path, variant: Variant = LEOC
) -> dict[str, Any]:
    """Worker body: train/design, evaluate, write ``evaluation.json``; returns its contents.

    The worker's stdout and stderr go to ``train.log`` in the run folder.
    """
    run_dir = run_dir_of(out_dir, spec)
    done = run_dir / EVALUATION_FILE
    if done.is_file():
        return json.loads(done.read_text())
    run_dir.mkdir(parents=True, exist_ok=True)
    torch.set_num_threads(WORKER_THREADS)
    started = time.perf_counter()
    with (
        open(run_dir / LOG_FILE, "a", buffering=1) as log,
        contextlib.redirect_stdout(log),
        contextlib.redirect_stderr(log),
    ):
        print(f"== {spec.key} ({profile.name} profile, {variant.name} variant)", flush=True)
        system = variant.system(spec.system)  # built once, for training and evaluation
        controller, curve = train_controller(spec, profile, run_dir / "train", variant, system)
        trained = time.perf_counter() - started
        print(f"trained in {trained:.1f} s; evaluating", flush=True)
        evaluation = evaluate_controller(spec, controller, variant, system, profile.evaluation)
    evaluation.update(
        spec=spec._asdict(),
        variant=variant.name,
        curve=curve,
        train_wall_seconds=trained,
        wall_seconds=time.perf_counter() - started,
        versions=versions(),
    )
    write_json_atomic(done, evaluation)
    return evaluation


def read_meta(path: Path, echo: Callable[[str], None] = print) -> dict[str, Any]:
    """The folder's ``meta.json`` ({} when absent); a damaged one is set aside with a message
    (it only describes the last invocation, which this one rewrites)."""
    return read_json_object(path, echo, "metadata") or {}


@dataclasses.dataclass(frozen=True)
class ProfileRunner:
    """The sweep's unit of work for a profile: ``runner(spec, out_dir)`` calls
    :func:`execute_run` (a picklable callable for worker processes and Ray tasks)."""

    profile: Profile
    variant: str = "leoc"

    def __call__(self, spec: RunSpec, out_dir: Path) -> dict[str, Any]:
        return execute_run(spec, self.profile, out_dir, get_variant(self.variant))


def reproduce(
    out_dir: str | Path,
    profile_name: str = "quick",
    jobs: int | None = None,
    seeds: int | None = None,
    systems: Sequence[str] = SYSTEM_NAMES,
    controllers: Sequence[str] = DEFAULT_CONTROLLERS,
    echo: Callable[[str], None] = print,
    backend: str = "local",
    address: str | None = None,
    variant: str = "leoc",
) -> Path:
    """Run (or resume) a profile and write the report; returns the path of ``report.md``.

    ``variant``: leoc's implementation or the authors' (:mod:`leoc.experiments.variants`); one
    folder holds runs of one variant.

    ``jobs`` runs at a time (default: the CPU count locally, the cluster's CPUs on Ray);
    ``backend`` ``"local"`` (worker processes) or ``"ray"``, ``address`` the Ray cluster to join
    (``None``: a private Ray instance on this machine; ``"auto"``: the cluster this machine
    belongs to). See :func:`leoc.experiments.sweep.sweep`.
    """
    from leoc.experiments.report import write_report

    out = Path(out_dir)
    profile = get_profile(profile_name, seeds)
    chosen = get_variant(variant)
    profile = profile.for_variant(chosen.name)  # its runs' measured costs (the ETA's)
    if jobs is not None and (int(jobs) != jobs or jobs < 1):
        raise ValueError(f"jobs: expected a positive integer, found {jobs}")
    check_backend(backend, address)  # before anything is written
    meta = _folder_meta(out, profile, chosen, echo)
    specs = run_specs(profile, tuple(systems), tuple(controllers))
    # a rerun with other seeds, systems or controllers extends the folder: earlier runs stay on
    # disk, and the report aggregates exactly the runs of this invocation (and lists them)
    meta.update(_study_meta(profile, chosen, systems, controllers))
    runner = ProfileRunner(profile, chosen.name)
    if not any(_pending(out, spec, echo) for spec in specs):
        # nothing to run: the report is rewritten, and the record of the invocations that ran
        # (their wall times, machine, versions, workers) stays as they left it
        write_json_atomic(out / META_FILE, meta)
        sweep(specs, runner, out, run_dir=run_dir_of, echo=echo)
        return write_report(out)
    meta.update(
        # the report says "on JOBS workers"
        jobs=jobs or ((os.cpu_count() or 1) if backend == "local" else "Ray cluster"),
        backend=backend,
        address=address,
        versions=versions(),
        machine=machine(),
        command=" ".join(sys.argv),
    )
    write_json_atomic(out / META_FILE, meta)
    options = {"backend": backend, "jobs": jobs, "address": address, "echo": echo}
    _run_sweep(specs, runner, out, meta, profile, options)
    return write_report(out)


def _folder_meta(
    out: Path, profile: Profile, variant: Variant, echo: Callable[[str], None]
) -> dict[str, Any]:
    """The folder's ``meta.json`` (empty for a new folder), refused when it holds runs of
    another profile or variant."""
    meta = read_meta(out / META_FILE, echo)
    if meta and meta.get("profile") != profile.name:
        raise ValueError(
            f"out: {out} holds a {meta.get('profile')!r} run; use another folder for "
            f"the {profile.name!r} profile"
        )
    if meta and meta.get("variant", LEOC.name) != variant.name:
        raise ValueError(
            f"out: {out} holds runs of the {meta.get('variant', LEOC.name)!r} variant; use "
            f"another folder for the {variant.name!r} variant"
        )
    return meta


def _study_meta(
    profile: Profile, variant: Variant, systems: Sequence[str], controllers: Sequence[str]
) -> dict[str, Any]:
    """What ``meta.json`` records of the study an invocation runs."""
    return {
        "profile": profile.name,
        "variant": variant.name,
        "variant_settings": variant.summary(),
        "description": profile.description,
        "seeds": list(profile.seeds),
        "settings": {
            "pilco_iterations": profile.pilco_iterations,
            "ddpg_steps": profile.ddpg_steps,
            "pilco_overrides": profile.pilco_overrides,
            "ddpg_overrides": profile.ddpg_overrides,
            "evaluation": dataclasses.asdict(profile.evaluation),
        },
        "systems": list(systems),
        "controllers": list(controllers),
    }


def _run_sweep(
    specs: Sequence[RunSpec],
    runner: ProfileRunner,
    out: Path,
    meta: dict[str, Any],
    profile: Profile,
    options: dict[str, Any],
) -> None:
    """Run ``specs`` through the sweep, recording each invocation's end in ``meta.json``."""
    log = InvocationLog(out / META_FILE, meta, out, specs)
    try:
        result = sweep(
            specs,
            runner,
            out,
            run_dir=run_dir_of,
            done_file=EVALUATION_FILE,
            log_file=LOG_FILE,
            expected_seconds=profile.cost_model,
            progress_of=trainer_progress,
            on_finished=lambda _key: log.write(RUNNING),
            kind_of=lambda spec: spec.framework,  # each learner's own speed (leoc.experiments.eta)
            **options,
        )
    except BaseException:
        # Ctrl-C, SIGTERM (the command raises it as an exception) or an error: a study resumed
        # over several sessions (or machines) then reports the wall time of each invocation
        log.write(INTERRUPTED)
        raise
    if result.failed:
        options["echo"](f"{len(result.failed)} run(s) failed: {', '.join(sorted(result.failed))}")
    meta["wall_seconds_last_invocation"] = time.perf_counter() - log.started
    log.write(FINISHED)


# How an invocation in ``meta.json``'s ``invocations`` ended.
RUNNING = "running"  # as written while it runs (after each finished run)
FINISHED = "finished"
INTERRUPTED = "interrupted"  # Ctrl-C, SIGTERM or an error
LOST = "lost"  # still "running" when the next invocation began: killed, or its machine lost


class InvocationLog:
    """This invocation's entry in ``meta.json``'s ``invocations``: when it started (UTC), its
    wall seconds, the runs it finished, how it ended and the leoc commit.

    The entry is written when the invocation starts and again after each finished run, so an
    invocation that ends without a word (SIGKILL, a machine lost between sessions) keeps its
    record up to its last finished run; the next invocation marks it ``lost``.
    """

    def __init__(
        self, meta_path: Path, meta: dict[str, Any], out: Path, specs: Sequence[RunSpec]
    ) -> None:
        self.meta_path, self.meta, self.out, self.specs = meta_path, meta, out, specs
        self.started = time.perf_counter()
        self.finished_before = _finished_runs(out, specs)
        invocations = meta.setdefault("invocations", [])
        for item in invocations:
            if item.get("ended") == RUNNING:
                item.update(ended=LOST, interrupted=True)
        self.entry: dict[str, Any] = {
            "started_utc": datetime.now(timezone.utc).isoformat(timespec="seconds"),
            "leoc_commit": meta.get("versions", {}).get("leoc_commit"),
        }
        invocations.append(self.entry)
        self.write(RUNNING)

    def write(self, ended: str) -> None:
        """Bring the entry up to date (``ended``: one of RUNNING, FINISHED, INTERRUPTED) and
        write ``meta.json`` atomically."""
        self.entry.update(
            wall_seconds=round(time.perf_counter() - self.started, 1),
            runs_finished=_finished_runs(self.out, self.specs) - self.finished_before,
            ended=ended,
            interrupted=ended != FINISHED,
        )
        write_json_atomic(self.meta_path, self.meta)


def _pending(out: Path, spec: RunSpec, echo: Callable[[str], None]) -> bool:
    """Whether ``spec`` is still to run: no readable ``evaluation.json`` (a damaged one is set
    aside with a message, as the sweep does)."""
    return read_json_object(run_dir_of(out, spec) / EVALUATION_FILE, echo, "result") is None


def _finished_runs(out: Path, specs: Sequence[RunSpec]) -> int:
    return sum((run_dir_of(out, spec) / EVALUATION_FILE).is_file() for spec in specs)
