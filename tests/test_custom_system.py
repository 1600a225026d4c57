"""The how-to's worked example (docs/examples/damped_cart.py) runs end to end."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import numpy as np

from leoc.systems import make_system, system_names, unregister_system

EXAMPLE = Path(__file__).resolve().parents[1] / "docs" / "examples" / "damped_cart.py"
TINY_STEPS = 200


def _load_example():
    spec = importlib.util.spec_from_file_location("damped_cart_example", EXAMPLE)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up while being defined
    spec.loader.exec_module(module)
    return module


def test_the_how_to_example_runs_end_to_end(tmp_path) -> None:
    example = _load_example()
    try:
        peaks = example.main(steps=TINY_STEPS, run_dir=str(tmp_path / "run"))
        assert "damped_cart" in system_names()
        system = make_system("damped_cart", mass=2.0)
        assert system.params.mass == 2.0
        # the hybrid equals the LQR near the operating point: both recover from the impulse
        assert np.isfinite(peaks["lqr"]) and np.isfinite(peaks["hybrid"])
        assert (tmp_path / "run").is_dir()
    finally:
        if "damped_cart" in system_names():
            unregister_system("damped_cart")
