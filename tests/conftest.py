"""Shared test set-up."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

CACHE_DIR_VARIABLE = "LEOC_CACHE_DIR"
_session_cache: list[str] = []  # the folder this process made, removed at its end


def pytest_configure(config) -> None:
    """LQR certificates computed by the tests go to one temporary folder per run, not to the
    user's ``~/.cache/leoc``, unless ``LEOC_CACHE_DIR`` is set already. Set in the process that
    starts pytest, before xdist starts its workers, so they inherit it and share the folder."""
    if os.environ.get(CACHE_DIR_VARIABLE) or os.environ.get("PYTEST_XDIST_WORKER"):
        return
    folder = tempfile.mkdtemp(prefix="leoc-test-cache-")
    _session_cache.append(folder)
    os.environ[CACHE_DIR_VARIABLE] = folder


def pytest_unconfigure(config) -> None:
    """Remove the run's certificate folder (only in the process that made it)."""
    while _session_cache:
        folder = _session_cache.pop()
        if os.environ.get(CACHE_DIR_VARIABLE) == folder:
            del os.environ[CACHE_DIR_VARIABLE]
        shutil.rmtree(folder, ignore_errors=True)


@pytest.fixture(autouse=True)
def _sb3_logs_in_the_test_folder(tmp_path_factory, monkeypatch):
    """SB3 models built directly by a test (not through ``train_ddpg``, which sets its own
    logger) create an ``SB3-<date>`` folder in the system temp folder on ``learn``; point them
    at pytest's temporary folder instead."""
    monkeypatch.setenv("SB3_LOGDIR", str(tmp_path_factory.getbasetemp() / "sb3-logs"))


@pytest.fixture
def single_thread():
    """torch on one thread for the test, restored after. A module asks for it with
    ``pytestmark = pytest.mark.usefixtures("single_thread")``."""
    import torch

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


@pytest.fixture
def train_refusal(tmp_path, capsys):
    """``refused(arguments)``: run ``leoc train pendulum --out RUN --quiet ARGUMENTS``, check it
    is refused with exit status 2 in one line on stderr and writes no run folder, and return
    that line."""
    from leoc.cli import main

    def refused(arguments: list[str]) -> str:
        run = tmp_path / "run"
        try:
            code = main(["train", "pendulum", "--out", str(run), "--quiet", *arguments])
        except SystemExit as stop:  # argparse's own errors
            code = stop.code
        err = capsys.readouterr().err
        assert code == 2 and len(err.strip().splitlines()) == 1, err
        assert not run.exists()
        return err

    return refused


class SmokeStudy:
    """One smoke study several slow tests compare with: ``leoc reproduce --profile smoke`` of
    the pendulum's LQR, DDPG hybrid and PILCO hybrid on two jobs (:meth:`command`), the
    evaluations' numbers without wall times (:meth:`numbers`), and that study run once, without
    interruption, on the local backend (:meth:`uninterrupted`)."""

    controllers = ("linear", "ddpg_hybrid", "pilco_hybrid")
    timeout_s = 600

    def __init__(self, shared: Path) -> None:
        self.shared = shared

    def command(self, out: Path) -> list[str]:
        """The study's ``leoc reproduce`` command line writing to ``out``."""
        options = ["--profile", "smoke", "--systems", "pendulum", "--jobs", "2"]
        controllers = ["--controllers", *self.controllers]
        return [sys.executable, "-m", "leoc.cli", "reproduce", *options, *controllers] + [
            "--out",
            str(out),
        ]

    @staticmethod
    def numbers(out: Path) -> dict[str, dict]:
        """Every run's evaluation in ``out`` without its wall times (the only fields allowed to
        differ between two runs of the study), by path relative to ``out``."""
        found = {}
        for path in sorted(out.glob("runs/*/*/*/evaluation.json")):
            data = json.loads(path.read_text())
            for key in ("wall_seconds", "train_wall_seconds"):
                data.pop(key, None)
            if isinstance(data.get("proved_region"), dict):
                data["proved_region"].pop("seconds", None)  # the proof's wall time
            found[str(path.relative_to(out))] = data
        return found

    def uninterrupted(self) -> dict[str, dict]:
        """The numbers of the study run once per test session: under pytest-xdist the first
        worker to take the file lock in the session's shared temporary folder runs it and
        saves them, the others wait and read them."""
        import fcntl

        saved = self.shared / "smoke-study-numbers.json"
        with open(self.shared / "smoke-study.lock", "w") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)
            if not saved.exists():
                out = self.shared / "smoke-study"
                run = subprocess.run(
                    self.command(out), capture_output=True, text=True, timeout=self.timeout_s
                )
                assert run.returncode == 0, run.stderr
                assert json.loads((out / "meta.json").read_text())["backend"] == "local"
                saved.write_text(json.dumps(self.numbers(out)))
            return json.loads(saved.read_text())


@pytest.fixture(scope="session")
def smoke_study(tmp_path_factory) -> SmokeStudy:
    """The :class:`SmokeStudy` of this test session."""
    base = tmp_path_factory.getbasetemp()
    # under xdist each worker's folder sits in the session's (shared by the workers); alone,
    # the session's own folder (its parent outlives the session)
    return SmokeStudy(base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base)


@pytest.fixture(scope="session")
def linear_smoke():
    """``linear_smoke(out, systems=None, echo=quiet)``: a linear-only ``reproduce`` on the
    smoke profile, one job (the study folder's mechanics: rerun, resume, damage, the invocation
    log, without training anything); ``echo=None`` keeps the library's default printing."""
    from leoc.experiments.reproduce import reproduce

    def run(out, systems=None, echo=lambda _: None):
        extra = {} if echo is None else {"echo": echo}
        systems = systems or ["pendulum"]
        return reproduce(
            out, profile_name="smoke", controllers=["linear"], systems=systems, jobs=1, **extra
        )

    return run


@pytest.fixture(scope="session")
def tiny_pilco_settings():
    """Settings of the smallest PILCO run (``leoc.pilco.train_pilco``) that fits a GP and
    optimises a policy in one iteration. The cost is wide enough (width 2) that the policy
    optimisation moves every parameter from the swing-up start: with the pendulum's default
    width the predicted cost sits at its maximum, every gradient is at most about 1e-6, L-BFGS
    stops after one evaluation, and a saved policy equals the trained one trivially. Read-only:
    a test changes what it needs on a copy, ``{**tiny_pilco_settings, ...}``."""
    from types import MappingProxyType

    return MappingProxyType(
        {
            "horizon": 4,
            "policy_iterations": 2,
            "num_basis": 4,
            "episode_steps": 24,
            "initial_rollouts": 2,
            "gp_train_iterations": 3,
            "eval_episodes": 2,
            "cost_width": 2.0,
        }
    )


@pytest.fixture(scope="session")
def tiny_gym_settings() -> dict:
    """Settings of a ``leoc.sb3.train_gym`` run small enough for the test suite: tiny
    networks, 60-step episodes, two evaluation episodes, a coarse sampled region, a checkpoint
    every 100 steps. A test changes what it needs on a copy: ``{**tiny_gym_settings, ...}``."""
    return {
        "env_kwargs": {"max_episode_steps": 60},
        "eval_interval": 200,
        "eval_episodes": 2,
        "roa_samples": 4,
        "roa_steps": 150,
        "actor_hidden": (16, 16),
        "critic_hidden": (16, 16),
        "batch_size": 32,
        "learning_starts": 100,
        "checkpoint_interval": 100,
        "progress": False,
    }


def pytest_collection_modifyitems(config, items) -> None:
    """Modules holding a ``heavy`` test run first, each module's tests kept together and in
    order (their module-scoped fixtures are set up once): a worker of ``pytest -n`` that meets a
    minutes-long test at the end of the run finishes minutes after the others."""
    heavy_modules = {item.module for item in items if item.get_closest_marker("heavy")}
    items.sort(key=lambda item: item.module not in heavy_modules)
