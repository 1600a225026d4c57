"""PILCO's settings: :class:`PilcoConfig`, validated, with the paper's per-system defaults."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

from leoc.pilco.gp import GPSettings
from leoc.policies.relevance import RELEVANCE_KINDS


@dataclasses.dataclass
class PilcoConfig:
    """Settings of one PILCO run (defaults: the paper's appendix C and the original PILCO).

    Attributes
    ----------
    system : str
        A registered system name (``pendulum``, ``cartpole``, ``mountaincar``, ``acrobot``, or
        a user's).
    hybrid : bool
        Train the LEOC hybrid (RBF + LQR) instead of the RBF baseline.
    seed : int
        Seeds the numpy and torch generators (everything random derives from it).
    iterations : int
        Policy-learning iterations after the random rollouts.
    horizon : int
        Prediction horizon H in controller decisions.
    action_repeat : int
        Simulator steps each action is held (the GP models this multi-step map); the control
        period is ``action_repeat * dt`` (pendulum: 2 x 0.05 s, see :data:`SYSTEM_DEFAULTS`).
    episode_steps : int
        Simulator steps of each real rollout.
    initial_rollouts : int
        Rollouts with uniform random actions before learning.
    num_basis : int
        RBF basis functions.
    policy_iterations : int
        L-BFGS iterations of each policy optimisation.
    cost_width : float
        Width of the saturating cost (distance at which the cost is 1 - exp(-1/2)).
    eval_episodes : int
        Deterministic evaluation episodes after every iteration (:mod:`leoc.training`).
    quadrature_order : int
        Gauss-Hermite nodes per state dimension for the hybrid's moment matching.
    hybrid_method : str
        ``quadrature`` or the ``constant_relevance`` heuristic (for comparison only).
    lambda_init : float
        Initial diagonal of the hybrid's Lambda (paper: identity).
    learn_lambda : bool
        Optimise Lambda (paper relevance) or the transition width (ROA relevance) with the RBF
        parameters.
    relevance : {"paper", "roa"}
        The hybrid's relevance: the paper's r(x) = 1 / (1 + d)^2, or exactly 1 on the certified
        region of attraction of the LQR at ``action_repeat`` (:func:`leoc.policies.roa_hybrid`).
    gp : GPSettings
        GP fitting settings (sparse beyond ``gp.max_full_points`` data).
    num_threads : int or None
        ``torch.set_num_threads`` for the run (None: leave as is).
    stop_after_held : int
        Stop early once this many consecutive evaluations held the operating point in every
        episode (0: never; for multi-seed measurements).
    """

    system: str = "pendulum"
    hybrid: bool = False
    seed: int = 0
    iterations: int = 10
    horizon: int = 40
    action_repeat: int = 3
    episode_steps: int = 200
    initial_rollouts: int = 3
    num_basis: int = 30
    policy_iterations: int = 75
    cost_width: float = 0.5
    eval_episodes: int = 5
    quadrature_order: int = 5
    hybrid_method: str = "quadrature"
    lambda_init: float = 1.0
    learn_lambda: bool = True
    relevance: str = "paper"
    gp: GPSettings = dataclasses.field(default_factory=GPSettings)
    num_threads: int | None = None
    stop_after_held: int = 0

    @classmethod
    def for_system(cls, name: str, **overrides: Any) -> PilcoConfig:
        """Per-system defaults, then ``overrides`` (GP fields may be given as ``gp_<field>``).

        A registered system without paper defaults (a user's) starts from the class defaults.
        """
        from leoc.systems import system_names

        if name not in SYSTEM_DEFAULTS and name not in system_names():
            raise ValueError(f"system: expected one of {system_names()}, found {name!r}")
        gp_fields = {f.name for f in dataclasses.fields(GPSettings)}
        gp_over = {k[3:]: v for k, v in overrides.items() if k.startswith("gp_")}
        unknown = set(gp_over) - gp_fields
        own = {k: v for k, v in overrides.items() if not k.startswith("gp_")}
        unknown |= set(own) - {f.name for f in dataclasses.fields(cls)}
        if unknown:
            raise ValueError(f"overrides: unknown PILCO settings {sorted(unknown)}")
        gp = own.pop("gp", None)
        if isinstance(gp, dict):
            gp = GPSettings(**gp)
        gp = dataclasses.replace(gp or GPSettings(), **gp_over)
        return cls(system=name, gp=gp, **{**SYSTEM_DEFAULTS.get(name, {}), **own})

    def __post_init__(self) -> None:
        for name in (
            "iterations",
            "horizon",
            "action_repeat",
            "episode_steps",
            "num_basis",
            "policy_iterations",
            "quadrature_order",
            "eval_episodes",
        ):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"{name}: expected a positive integer, found {value!r}")
        for name in ("initial_rollouts", "seed", "stop_after_held"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 0:
                raise ValueError(f"{name}: expected a non-negative integer, found {value!r}")
        for name in ("cost_width", "lambda_init"):
            value = getattr(self, name)
            if not isinstance(value, (int, float)) or not 0 < value < math.inf:
                raise ValueError(f"{name}: expected a positive number, found {value!r}")
        if self.relevance not in RELEVANCE_KINDS:
            raise ValueError(
                f"relevance: expected one of {RELEVANCE_KINDS}, found {self.relevance!r}"
            )

    def to_dict(self) -> dict[str, Any]:
        """The settings as plain data (JSON-ready), nested ``gp`` included."""
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> PilcoConfig:
        """Inverse of :meth:`to_dict`."""
        data = dict(data)
        data["gp"] = GPSettings(**data["gp"])
        return cls(**data)


# Per-system settings over the class defaults. Control periods: the pendulum decides every
# 2 x 0.05 s = 0.1 s (the original PILCO pendulum's period); the cart-pole and mountain car every
# 3 x 0.02 s = 0.06 s. At 3 x 0.05 s = 0.15 s the pendulum's period is long next to the inverted
# rod's time constant sqrt(2 l / 3 g) = 0.26 s: measured over seeds (benchmarks/
# bench_pilco_seeds.py), the hybrid then learnt on 1 of 3 seeds and the RBF baseline on 0 of 2,
# against every seed tried at 0.1 s.
#: Per-system PILCO settings that differ from the :class:`PilcoConfig` defaults.
SYSTEM_DEFAULTS: dict[str, dict[str, Any]] = {
    "pendulum": {"num_basis": 30, "cost_width": 0.5, "action_repeat": 2},
    "cartpole": {"num_basis": 60, "cost_width": 0.5, "quadrature_order": 4},
    "mountaincar": {"num_basis": 60, "cost_width": 1.0},
}
