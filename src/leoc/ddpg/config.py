"""Typed configuration of a DDPG/TD3 run, with the paper's settings as defaults.

The defaults follow Zhang & Capel (L4DC 2021), appendix C (table "Framework hyperparameters"):
Adam, actor learning rate 5e-4, critic learning rate 1e-3, discount 0.995, minibatch 64,
replay buffer 1e5, soft target updates with factor 0.05 every 5 updates, Lambda initialised to
the identity, 10k-15k interaction steps; the actor and critic are 400-300 MLPs as in the
original DDPG experiments (Lillicrap et al., 2016), explored with Ornstein-Uhlenbeck noise.

Reading of the appendix where it is terse (documented choices, all overridable):

* "Target update factor 0.05" is the Polyak coefficient and "target update rate 5" the number
  of gradient updates between two soft target updates (``DDPGConfig.target_update_interval``).
* "Number of iterations 10000-15000" are environment steps: 10k for the pendulum and the
  mountain car, 15k for the cart-pole.
* Exploration noise is the Ornstein-Uhlenbeck process of Lillicrap et al. (theta 0.15,
  sigma 0.2, unit time step) on the normalised action in [-1, 1].
"""

from __future__ import annotations

import dataclasses
from typing import Any, Literal

from leoc.policies.relevance import DEFAULT_ROA_WIDTH, RELEVANCE_KINDS

#: Model-free learners: Stable-Baselines3's DDPG and TD3.
ALGOS = ("ddpg", "td3")
Algo = Literal["ddpg", "td3"]

# Environment steps per run (appendix C: 10000-15000 iterations).
DEFAULT_TOTAL_STEPS = 10_000
#: Environment steps per run for each of the paper's systems (appendix C).
TOTAL_STEPS_BY_SYSTEM = {"pendulum": 10_000, "cartpole": 15_000, "mountaincar": 10_000}
# Hold band of the "reached and held the operating point" test, in the units of
# ``System.main_coordinate`` (degrees for the pendulum and cart-pole angles, metres for the car).
PAPER_HIDDEN_SIZES = (400, 300)


@dataclasses.dataclass(frozen=True)
class DDPGConfig:
    """Settings of one DDPG/TD3 training run (baseline or LEOC hybrid).

    Attributes
    ----------
    system : str
        System name (``pendulum``, ``cartpole``, ``mountaincar``).
    algo : {"ddpg", "td3"}
        Stable-Baselines3 algorithm. DDPG is SB3's TD3 with ``policy_delay=1``, no target
        policy smoothing and a single critic.
    hybrid : bool
        Whether the actor is the LEOC hybrid ``sat(r G + (1 - r) H)`` or the plain MLP ``H``.
    total_steps : int
        Environment steps (interaction time ``total_steps * dt`` seconds).
    actor_learning_rate, critic_learning_rate : float
        Adam step sizes (appendix C: 5e-4 and 1e-3).
    discount : float
        Discount factor gamma (appendix C: 0.995).
    batch_size : int
        Minibatch size (64).
    buffer_size : int
        Replay buffer capacity (1e5).
    polyak : float
        Soft target update coefficient: ``target <- (1 - polyak) target + polyak online`` (0.05).
    target_update_interval : int
        Gradient updates between two soft target updates (appendix C "target update rate": 5).
    learning_starts : int
        Uniformly random actions before the first update (one episode by default).
    train_freq, gradient_steps : int
        Update every ``train_freq`` environment steps with ``gradient_steps`` gradient steps.
    actor_hidden, critic_hidden : tuple of int
        Hidden widths of the actor MLP H and of the critic (400-300).
    ou_theta, ou_sigma : float
        Ornstein-Uhlenbeck mean reversion and scale, on the normalised action in [-1, 1].
    td3_policy_delay, td3_target_noise, td3_target_noise_clip : float
        TD3's delayed actor updates and target policy smoothing (SB3 defaults; unused by DDPG).
    lambda_init : float
        Initial diagonal of Lambda (the paper: identity).
    learn_lambda : bool
        Train ``log_lambda`` with the actor (False: frozen buffer).
    lqr_method : {"discrete", "continuous"}
        LQR design used for G (see :func:`leoc.control.design_lqr`).
    relevance : {"paper", "roa"}
        The hybrid's relevance: the paper's :math:`(1 + d)^{-2}` (``lambda_init``,
        ``learn_lambda``), or :class:`~leoc.policies.ROARelevance`, exactly 1 on the LQR's
        certified region of attraction (``roa_rho_fraction``, ``roa_width``, ``learn_width``).
    roa_rho_fraction : float in (0, 1]
        Flat top level as a fraction of the certified rho (``relevance="roa"``).
    roa_width : float
        Initial width of the ROA relevance's transition band.
    learn_width : bool
        Train the band width with the actor (False: frozen).
    eval_interval : int
        Environment steps between two evaluations.
    eval_episodes : int
        Deterministic swing-up episodes per evaluation, on a separate environment instance.
    """

    system: str
    algo: str = "ddpg"
    hybrid: bool = False
    total_steps: int = DEFAULT_TOTAL_STEPS
    actor_learning_rate: float = 5e-4
    critic_learning_rate: float = 1e-3
    discount: float = 0.995
    batch_size: int = 64
    buffer_size: int = 100_000
    polyak: float = 0.05
    target_update_interval: int = 5
    learning_starts: int = 200
    train_freq: int = 1
    gradient_steps: int = 1
    actor_hidden: tuple[int, ...] = PAPER_HIDDEN_SIZES
    critic_hidden: tuple[int, ...] = PAPER_HIDDEN_SIZES
    ou_theta: float = 0.15
    ou_sigma: float = 0.2
    td3_policy_delay: int = 2
    td3_target_noise: float = 0.2
    td3_target_noise_clip: float = 0.5
    lambda_init: float = 1.0
    learn_lambda: bool = True
    lqr_method: str = "discrete"
    relevance: str = "paper"
    roa_rho_fraction: float = 1.0
    roa_width: float = DEFAULT_ROA_WIDTH
    learn_width: bool = True
    eval_interval: int = 1_000
    eval_episodes: int = 5

    def __post_init__(self) -> None:
        from leoc.systems import system_names

        if self.system not in system_names():
            raise ValueError(f"system: expected one of {system_names()}, found {self.system!r}")
        if self.algo not in ALGOS:
            raise ValueError(f"algo: expected one of {ALGOS}, found {self.algo!r}")
        positive_ints = (
            "total_steps",
            "batch_size",
            "buffer_size",
            "target_update_interval",
            "train_freq",
            "gradient_steps",
            "td3_policy_delay",
            "eval_interval",
            "eval_episodes",
        )
        for name in positive_ints:
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value <= 0:
                raise ValueError(f"{name}: expected a positive int, found {value!r}")
        positive_floats = (
            "actor_learning_rate",
            "critic_learning_rate",
            "discount",
            "polyak",
            "lambda_init",
        )
        for name in positive_floats:
            value = getattr(self, name)
            if not isinstance(value, (int, float)) or not value > 0:
                raise ValueError(f"{name}: expected a positive number, found {value!r}")
        if not self.discount <= 1.0 or not self.polyak <= 1.0:
            raise ValueError(
                f"discount, polyak: expected values in (0, 1], found {self.discount}, {self.polyak}"
            )
        if self.relevance not in RELEVANCE_KINDS:
            raise ValueError(
                f"relevance: expected one of {RELEVANCE_KINDS}, found {self.relevance!r}"
            )
        if not 0.0 < self.roa_rho_fraction <= 1.0:
            raise ValueError(
                f"roa_rho_fraction: expected a number in (0, 1], found {self.roa_rho_fraction!r}"
            )
        if not isinstance(self.roa_width, (int, float)) or not self.roa_width > 0:
            raise ValueError(f"roa_width: expected a positive number, found {self.roa_width!r}")
        if self.learning_starts < 0:
            raise ValueError(f"learning_starts: expected >= 0, found {self.learning_starts}")

    @classmethod
    def for_system(cls, name: str, algo: str = "ddpg", **overrides: Any) -> DDPGConfig:
        """The paper's defaults for system ``name`` and ``algo``, with ``overrides`` applied.

        Per-system default: ``total_steps`` (15k for the cart-pole, 10k otherwise). The hold
        test is the system's own (``System.hold_step``).

        Raises
        ------
        ValueError
            On an unknown system, algorithm or override name, or an invalid value.
        """
        fields = {field.name for field in dataclasses.fields(cls)}
        unknown = set(overrides) - fields
        if unknown:
            raise ValueError(
                f"overrides: unknown DDPGConfig fields {sorted(unknown)}; "
                f"expected some of {sorted(fields - {'system', 'algo'})}"
            )
        values: dict[str, Any] = {
            "total_steps": TOTAL_STEPS_BY_SYSTEM.get(name, DEFAULT_TOTAL_STEPS),
        }
        values.update(overrides)
        for key in ("actor_hidden", "critic_hidden"):
            if key in values:
                values[key] = tuple(int(width) for width in values[key])
        return cls(system=name, algo=algo, **values)

    def as_dict(self) -> dict[str, Any]:
        """JSON-friendly dict (tuples become lists)."""
        data = dataclasses.asdict(self)
        for key, value in data.items():
            if isinstance(value, tuple):
                data[key] = list(value)
        return data

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> DDPGConfig:
        """Inverse of :meth:`as_dict` (unknown keys such as ``seed`` are ignored)."""
        fields = {field.name for field in dataclasses.fields(cls)}
        values = {key: value for key, value in data.items() if key in fields}
        for key in ("actor_hidden", "critic_hidden"):
            if key in values:
                values[key] = tuple(values[key])
        return cls(**values)
