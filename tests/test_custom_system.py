"""The how-to's worked example (docs/examples/damped_cart.py) runs end to end."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

from leoc.systems import make_system, register_system, system_names, unregister_system

DOCS = Path(__file__).resolve().parents[1] / "docs"
EXAMPLE = DOCS / "examples" / "damped_cart.py"
GUIDE = DOCS / "user_guide" / "custom_system.md"
TINY_STEPS = 200


def _load_example():
    spec = importlib.util.spec_from_file_location("damped_cart_example", EXAMPLE)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up while being defined
    spec.loader.exec_module(module)
    return module


@pytest.mark.slow
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


def test_the_guide_prints_the_complete_file() -> None:
    """GitHub shows no Sphinx include: the page's last block is the example file, verbatim."""
    page = GUIDE.read_text(encoding="utf-8")
    section = page.split("\n## The complete file\n", 1)[1]
    block = section.split("```python\n", 1)[1].rsplit("```", 1)[0]
    assert block == EXAMPLE.read_text(encoding="utf-8")


@pytest.mark.parametrize("method", ["step_fn", "reward_fn", "out_of_bounds"])
def test_a_stub_method_is_refused_in_one_line_naming_it(method) -> None:
    """A method left as ``...`` (the guide's elided ``reward_fn``) returns None: registration
    refuses it with one line naming the system, the method, the expectation and ``None``."""
    example = _load_example()
    stub = type("StubCart", (example.DampedCart,), {method: lambda self, *args: None})
    with pytest.raises(ValueError) as error:
        register_system("damped_cart", stub)
    message = str(error.value)
    assert "\n" not in message
    assert message.startswith(f"system 'damped_cart': {method}: expected a (B")
    assert "found None" in message
    assert "damped_cart" not in system_names()


def test_the_guide_quotes_the_stub_error_as_raised() -> None:
    example = _load_example()
    stub = type("StubCart", (example.DampedCart,), {"reward_fn": lambda self, *args: None})
    with pytest.raises(ValueError) as error:
        register_system("damped_cart", stub)
    assert f"    ValueError: {error.value}\n" in GUIDE.read_text(encoding="utf-8")
