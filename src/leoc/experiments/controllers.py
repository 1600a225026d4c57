"""Load a trained controller from a run folder written by ``leoc train``."""

from __future__ import annotations

from pathlib import Path

import torch

PILCO_MARKER = "controller.pt"
DDPG_MARKER = "model.zip"


def load_trained_controller(run_dir: str | Path) -> torch.nn.Module:
    """The physical-units policy (float64 observations -> actions) saved in ``run_dir``.

    PILCO runs are recognised by ``controller.pt``, DDPG/TD3 runs by ``model.zip``.

    Raises
    ------
    FileNotFoundError
        If ``run_dir`` holds neither.
    """
    path = Path(run_dir)
    if (path / PILCO_MARKER).is_file():
        from leoc.pilco.train import load_pilco_controller

        return load_pilco_controller(path)
    if (path / DDPG_MARKER).is_file():
        from leoc.ddpg.train import load_ddpg_controller

        return load_ddpg_controller(path)
    raise FileNotFoundError(
        f"controller: expected 'linear' or a run folder holding {PILCO_MARKER} (PILCO) or "
        f"{DDPG_MARKER} (DDPG/TD3), found {str(path)!r}"
    )
