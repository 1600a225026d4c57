"""Tests of the atomic writers and of package-level conventions."""

from __future__ import annotations

import os
import stat
import subprocess
import sys

import pytest

from leoc.io import write_json_atomic, write_text_atomic


@pytest.mark.parametrize("umask", [0o022, 0o077])
def test_atomic_files_get_ordinary_permissions_under_the_umask(tmp_path, umask):
    previous = os.umask(umask)
    try:
        path = write_text_atomic(tmp_path / "a.txt", "x")
        json_path = write_json_atomic(tmp_path / "b.json", {"a": 1})
    finally:
        os.umask(previous)
    for written in (path, json_path):
        assert stat.S_IMODE(written.stat().st_mode) == 0o666 & ~umask
    assert not list(tmp_path.glob(".*.tmp"))


@pytest.mark.slow
@pytest.mark.parametrize(
    "imports", ["import gymnasium as gym, leoc", "import leoc\nimport gymnasium as gym"]
)
def test_importing_leoc_registers_the_gymnasium_environments(imports):
    """Before or after gymnasium: ``import leoc`` defers the registration until gymnasium is
    imported (so the ``leoc`` command starts without it)."""
    script = (
        f"{imports}\n"
        "env = gym.make('leoc/PendulumSwingUp-v0')\n"
        "print(env.spec.id, type(env.unwrapped).__name__)\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, check=True, timeout=120
    )
    assert out.stdout.strip() == "leoc/PendulumSwingUp-v0 PendulumSwingUpEnv"
