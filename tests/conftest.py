"""Shared test set-up."""

from __future__ import annotations

import pytest


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
