"""Shared test set-up."""

from __future__ import annotations

import pytest


@pytest.fixture(autouse=True)
def _sb3_logs_in_the_test_folder(tmp_path_factory, monkeypatch):
    """SB3 models built directly by a test (not through ``train_ddpg``, which sets its own
    logger) create an ``SB3-<date>`` folder in the system temp folder on ``learn``; point them
    at pytest's temporary folder instead."""
    monkeypatch.setenv("SB3_LOGDIR", str(tmp_path_factory.getbasetemp() / "sb3-logs"))
