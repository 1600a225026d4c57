"""PILCO's settings: :class:`PilcoConfig`, validated, with the paper's per-system defaults."""

from __future__ import annotations

import dataclasses
import math
import typing
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

from leoc.control.lqr import DesignMethod
from leoc.pilco.gp import GPSettings
from leoc.policies.spec import (
    HybridSpec,
    as_hybrid_spec,
    legacy_hybrid_config,
    with_hybrid_overrides,
)

if TYPE_CHECKING:
    from leoc.systems.base import System


@dataclasses.dataclass
class PilcoConfig:
    r"""Settings of one PILCO run (defaults: the paper's appendix C and the original PILCO).

    Attributes
    ----------
    system : str
        A registered system name (``pendulum``, ``cartpole``, ``mountaincar``, ``acrobot``, or
        a user's).
    hybrid : HybridSpec or None
        Train the LEOC hybrid (RBF + LQR) this :class:`~leoc.policies.HybridSpec` describes
        (relevance design, its parameters, what is optimised with the RBF parameters; ``True``:
        the default spec) instead of the RBF baseline (None). The paper's relevance is held as
        :math:`\log\lambda` (``relevance_parametrisation="log_lambda"``); the ROA relevance
        is 1 on the certified region of attraction of the LQR at the controller's period
        (:func:`leoc.policies.roa_hybrid`).
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
        Simulator steps of each episode (evaluation episodes, and the real rollouts unless
        ``rollout_steps`` is set).
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
        ``quadrature``, or a heuristic with r frozen at the mean observation:
        ``constant_relevance`` (a fixed blend) or ``mixture`` (a two-component mixture); see
        :mod:`leoc.pilco.propagate`.
    gp : GPSettings
        GP fitting settings (sparse beyond ``gp.max_full_points`` data).
    num_threads : int or None
        ``torch.set_num_threads`` for the run (None: leave as is).
    stop_after_held : int
        Stop early once this many consecutive evaluations held the operating point in every
        episode (0: never; for multi-seed measurements).
    lqr_method : str
        ``method`` of :func:`leoc.control.design_lqr` for the hybrid's linear part, designed at
        ``action_repeat`` (default ``discrete``: dlqr on the held step map).
    cost_weights : tuple of float or None
        Diagonal weights W on the observation for the saturating cost
        ``1 - exp(-(o - t)^T W (o - t) / (2 cost_width^2))``, one per observation entry
        (factor ``diag(sqrt(W)) / cost_width``); None: the system's ``cost_factor()``.
    start_mean : tuple of float or None
        Mean of the predicted rollout's Gaussian start, in state coordinates; None: the
        system's ``swing_up_centre``.
    start_variance : tuple of float or None
        Diagonal covariance of that start, in state coordinates; None: the variance of the
        uniform swing-up start, ``start_spread^2 / 3``.
    rollout_steps : int or None
        Simulator steps of each real training rollout, the random ones included; None:
        ``episode_steps``.
    policy_restarts : tuple of int
        Extra policy optimisations per iteration, each from a freshly drawn RBF part (the
        hybrid keeps its linear part and relevance), keeping the lowest predicted cost: entry
        i for iteration i + 1, none beyond the tuple.
    deploy_action_repeat : int or None
        Control period, in simulator steps, of the controller evaluated, returned and saved;
        None: ``action_repeat`` (the period it was trained at). Training rollouts always hold
        each action ``action_repeat`` steps.
    select_best_from : int
        0 (leoc's rule, :mod:`leoc.training`): the run's controller is the final policy.
        k >= 1: the policy after the iteration >= k with the highest mean evaluation return
        (the earliest on ties), or the final one if the run stops before iteration k.
    step_rules : dict
        Fields of the :class:`~leoc.systems.StepRules` the real system steps under (empty:
        leoc's rules; the authors' variant sets theirs).
    training_perturbations : dict
        The perturbations of the real rollouts, the GP's data
        (:meth:`leoc.systems.TrainingPerturbations.as_dict`: fixed levels and randomised
        maxima, rollout ``k``'s plant drawn from the seed); empty: the nominal plant. The GP
        model and the evaluation episodes are not perturbed. Recorded by :meth:`to_dict` only
        when not empty.
    """

    system: str = "pendulum"
    hybrid: HybridSpec | None = None
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
    gp: GPSettings = dataclasses.field(default_factory=GPSettings)
    num_threads: int | None = None
    stop_after_held: int = 0
    lqr_method: str = "discrete"
    cost_weights: tuple[float, ...] | None = None
    start_mean: tuple[float, ...] | None = None
    start_variance: tuple[float, ...] | None = None
    rollout_steps: int | None = None
    policy_restarts: tuple[int, ...] = ()
    deploy_action_repeat: int | None = None
    select_best_from: int = 0
    step_rules: dict[str, Any] = dataclasses.field(default_factory=dict)
    training_perturbations: dict[str, Any] = dataclasses.field(default_factory=dict)

    @classmethod
    def for_system(cls, name: str, **overrides: Any) -> PilcoConfig:
        """Per-system defaults, then ``overrides`` (GP fields may be given as ``gp_<field>``).

        A registered system without paper defaults (a user's) starts from the class defaults.
        """
        from leoc.systems import system_names

        if name not in SYSTEM_DEFAULTS and name not in system_names():
            raise ValueError(f"system: expected one of {system_names()}, found {name!r}")
        overrides = dict(overrides)
        hybrid = with_hybrid_overrides(overrides.pop("hybrid", None), overrides)
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
        return cls(system=name, gp=gp, hybrid=hybrid, **{**SYSTEM_DEFAULTS.get(name, {}), **own})

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
        for name in ("rollout_steps", "deploy_action_repeat"):
            value = getattr(self, name)
            if value is not None and (
                isinstance(value, bool) or not isinstance(value, int) or value < 1
            ):
                raise ValueError(f"{name}: expected None or a positive integer, found {value!r}")
        for name in ("initial_rollouts", "seed", "stop_after_held", "select_best_from"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 0:
                raise ValueError(f"{name}: expected a non-negative integer, found {value!r}")
        for name in ("cost_width",):
            value = getattr(self, name)
            if not isinstance(value, (int, float)) or not 0 < value < math.inf:
                raise ValueError(f"{name}: expected a positive number, found {value!r}")
        from leoc.systems import StepRules

        if not isinstance(self.step_rules, dict):
            raise ValueError(f"step_rules: expected a dict, found {self.step_rules!r}")
        try:
            StepRules(**self.step_rules)
        except TypeError as error:
            raise ValueError(f"step_rules: {error}") from error
        self.hybrid = as_hybrid_spec(self.hybrid)
        if self.hybrid is not None:
            _check_pilco_hybrid(self.hybrid)
        methods = typing.get_args(DesignMethod)
        if self.lqr_method not in methods:
            raise ValueError(f"lqr_method: expected one of {methods}, found {self.lqr_method!r}")
        self.cost_weights = _optional_floats(self.cost_weights, "cost_weights", minimum=0.0)
        self.start_mean = _optional_floats(self.start_mean, "start_mean")
        self.start_variance = _optional_floats(self.start_variance, "start_variance", 0.0, True)
        self.policy_restarts = _counts(self.policy_restarts, "policy_restarts")
        from leoc.systems.perturbation_levels import training_setting

        self.training_perturbations = training_setting(
            self.training_perturbations, self.system, self.action_repeat
        )

    @property
    def training_rollout_steps(self) -> int:
        """Simulator steps of each real training rollout (``rollout_steps`` or
        ``episode_steps``)."""
        return self.episode_steps if self.rollout_steps is None else self.rollout_steps

    @property
    def controller_action_repeat(self) -> int:
        """Control period of the evaluated, returned and saved controller
        (``deploy_action_repeat`` or ``action_repeat``)."""
        return (
            self.action_repeat if self.deploy_action_repeat is None else self.deploy_action_repeat
        )

    def plant(self, system: System | None = None) -> System:
        """The system a run of these settings trains on: a copy of ``system`` (default: the
        registered system named ``self.system``) stepping under ``step_rules``, with
        ``episode_steps`` steps an episode. :func:`~leoc.pilco.train_pilco` and
        :func:`~leoc.pilco.load_pilco_run` build it here."""
        from leoc.systems import StepRules, make_system

        base = make_system(self.system) if system is None else system
        plant = base.with_rules(StepRules(**self.step_rules))
        plant.episode_steps = self.episode_steps
        return plant

    def to_dict(self) -> dict[str, Any]:
        """The settings as plain data (JSON-ready), nested ``gp`` and ``hybrid`` included
        (``training_perturbations`` only when not empty: a nominal run's config is as before)."""
        data = dataclasses.asdict(self)
        data["hybrid"] = None if self.hybrid is None else self.hybrid.to_dict()
        if not self.training_perturbations:
            del data["training_perturbations"]
        return data

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> PilcoConfig:
        """Inverse of :meth:`to_dict` (a config saved before :class:`~leoc.policies.HybridSpec`,
        with ``hybrid`` a bool and the hybrid's fields beside it, is read into its spec)."""
        data = legacy_hybrid_config(data)
        data["gp"] = GPSettings.from_dict(data["gp"])
        return cls(**data)


def _check_pilco_hybrid(spec: HybridSpec) -> None:
    r"""Refuse the :class:`~leoc.policies.HybridSpec` choices PILCO's hybrid does not implement
    (ValueError naming the field): the precision parametrisation, a relevance learning-rate
    scale (an SB3 optimiser group) and the Lyapunov relevance. The floor ``r_min`` it takes:
    the floored :math:`\Lambda` is a reparametrisation of the paper's relevance, whose moments
    the quadrature of :func:`~leoc.pilco.propagate.hybrid_quadrature_moments` takes as it
    takes any policy's; the floor is computed on the proved set of the LQR at PILCO's deployed
    period."""
    if spec.relevance_parametrisation != "log_lambda":
        raise ValueError(
            "relevance_parametrisation: PILCO's hybrid holds the paper's relevance as "
            f"log lambda; expected 'log_lambda', found {spec.relevance_parametrisation!r}"
        )
    if spec.relevance_lr_scale != 1:
        raise ValueError(
            "relevance_lr_scale: PILCO's L-BFGS optimises the controller's parameters as one "
            f"vector (no optimiser groups); expected 1, found {spec.relevance_lr_scale!r}"
        )
    if spec.relevance == "lyapunov":
        raise ValueError(
            "relevance: PILCO's hybrid has the paper's or the ROA relevance; expected one of "
            f"('paper', 'roa'), found {spec.relevance!r}"
        )


def _optional_floats(
    values: Sequence[float] | None, name: str, minimum: float | None = None, strict: bool = False
) -> tuple[float, ...] | None:
    """``values`` as a non-empty tuple of finite floats (None stays None), each ``>= minimum``
    (``> minimum`` if ``strict``)."""
    if values is None:
        return None
    if isinstance(values, (str, bytes)) or not isinstance(values, Sequence) or not values:
        raise ValueError(f"{name}: expected a non-empty sequence of numbers, found {values!r}")
    bound = "none" if minimum is None else f"{'>' if strict else '>='} {minimum}"
    floats = []
    for value in values:
        ok = isinstance(value, (int, float)) and not isinstance(value, bool)
        ok = ok and math.isfinite(value)
        if ok and minimum is not None:
            ok = value > minimum if strict else value >= minimum
        if not ok:
            raise ValueError(f"{name}: expected finite numbers (bound: {bound}), found {values!r}")
        floats.append(float(value))
    return tuple(floats)


def _counts(values: Sequence[int], name: str) -> tuple[int, ...]:
    """``values`` as a tuple of non-negative integers."""
    if isinstance(values, (str, bytes)) or not isinstance(values, Sequence):
        raise ValueError(f"{name}: expected a sequence of non-negative integers, found {values!r}")
    for value in values:
        if isinstance(value, bool) or not isinstance(value, int) or value < 0:
            raise ValueError(
                f"{name}: expected a sequence of non-negative integers, found {values!r}"
            )
    return tuple(values)


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


# --- The authors' PILCO (nrjc/LEOC) -------------------------------------------------------------
# The settings of the authors' PILCO runs, as PilcoConfig overrides: each value below follows the
# file of github.com/nrjc/LEOC named beside it (commits: dao/trainer.py 99ae86a, whose
# PILCOTrainer.train defaults are unchanged in every stored version; data/*_PILCO_*.gin 6050128,
# the version with Evaluator.model_path and pickle_dir; pilco/controllers.py and the gin files
# 70dc15f for the controllers). Only settings that change a number are here; what is not
# replicated, and why, is in AUTHORS_NOT_REPLICATED.

AUTHORS_SUBS = 3
"""Simulator steps each action is held (``PILCOTrainer.train(subs=3)``, dao/trainer.py), on
every system (leoc's pendulum uses 2)."""
AUTHORS_TIMESTEPS = 40
"""Decisions per training rollout and of the predicted horizon (``timesteps=40``)."""
AUTHORS_HORIZON = AUTHORS_TIMESTEPS - 1
"""leoc's ``horizon``: their ``PILCO.predict`` (pilco/models/pilco.py) adds the reward of the
predicted states 0, ..., timesteps - 1 (the start's is a constant of the policy), leoc's
:func:`~leoc.pilco.propagate.predict` the costs of states 1, ..., H: the same objective up to a
constant, hence the same optimisation, with H = timesteps - 1 = 39."""
AUTHORS_ROLLOUT_STEPS = AUTHORS_TIMESTEPS * AUTHORS_SUBS
"""Simulator steps of a training rollout (``utils.rollout``: 40 decisions of SUBS = 3 steps);
their evaluation episodes keep the environments' 200 steps (dao/envs/__init__.py)."""
AUTHORS_INITIAL_ROLLOUTS = 3
"""Random rollouts, uniform actions (``initial_num_rollout=3``; ``env.action_space.sample()``)."""
AUTHORS_POLICY_ITERATIONS = 50
"""Iterations of each policy optimisation (``max_iter_policy_train=50``, SciPy L-BFGS-B)."""
AUTHORS_POLICY_RESTARTS = (1, 1, 1, 1)
"""``policy_restarts = 1 if rollouts > 3 else 2`` (dao/trainer.py) with ``optimize_policy``
(pilco/models/pilco.py) running ``restarts - 1`` optimisations from a randomised controller
(``randomize()``: the RBF part only) and keeping the best: one extra in iterations 1-4."""
AUTHORS_NOISE_VAR = 1e-3
"""GP likelihood variance, fixed and never trained (``model.likelihood.variance.assign(0.001)``,
``set_trainable(..., False)``)."""
AUTHORS_EVAL_EPISODES = 3
"""Evaluation episodes after each iteration (``Evaluator.eval_num_episodes = 3``, the gin
files)."""
AUTHORS_DEPLOY_ACTION_REPEAT = 1
"""The trained controller runs every simulator step: their ``Evaluator`` (dao/trainer.py) and
the response metrics (plotting/compute_metrics.py, through ``Evaluator``) drive the saved
policy with tf-agents' ``DynamicEpisodeDriver``, one action per environment step, although it
was trained holding each action SUBS = 3 steps."""
AUTHORS_SELECT_AFTER_HALF = 2
"""Model selection: their ``Evaluator`` saves the policy whenever its mean evaluation return
beats the best so far, from loop index ``rollouts > int(num_rollouts / 2)`` on (dao/trainer.py),
and the saved policy is the one evaluated: with leoc's iteration = loop index + 1,
``select_best_from = num_rollouts // 2 + 2``."""
AUTHORS_HYBRID_METHOD = "mixture"
"""The hybrid's moment approximation (``HybridController.compute_action``, pilco/controllers.py):
r at the mean, mixture moments; see :func:`leoc.pilco.propagate.mixture_relevance_moments`."""
AUTHORS_LQR_METHOD = "authors"
"""The hybrid's linear part: ``HybridController.W = @load_weight_matrix()`` (the gin files), the
authors' continuous design (:func:`leoc.control.design_lqr` ``method="authors"``)."""
AUTHORS_LAMBDA_INIT = 1.0
"""``HybridController.S`` starts at ones, ``d = (x - a) diag(S) (x - a)``: Lambda = 1 / S = 1
(pilco/controllers.py at 70dc15f)."""

# Per system: data/<System>_PILCO_{Baseline,Hybrid}.gin (the same values in both).
# weights: PILCOTrainer.weights, the diagonal W of ExponentialReward exp(-(o - t)^T W (o - t) / 2)
#   (pilco/rewards.py) on the observation, t = env.target = o(a); leoc's cost is 1 minus it.
# m_init, S_init (observation coordinates, S_init a diagonal covariance) -> the state
#   coordinates leoc propagates: the angle's variance is the sin entry's (d sin / d theta = -1 at
#   theta = pi); the cos entry's 0.01 has no counterpart (cos is flat at pi).
# iterations: PILCOTrainer.num_rollouts. num_basis: the gin's num_basis_functions (pendulum 30),
#   else the controllers' default 60.
AUTHORS_SYSTEM_SETTINGS: dict[str, dict[str, Any]] = {
    "pendulum": {
        "cost_weights": (2.0, 2.0, 0.3),
        "start_mean": (math.pi, 0.0),  # m_init [-1, 0, 0]
        "start_variance": (0.05, 0.01),  # S_init [0.01, 0.05, 0.01]
        "iterations": 8,
        "num_basis": 30,
    },
    "cartpole": {
        "cost_weights": (2.0, 0.3, 2.0, 2.0, 0.3),
        "start_mean": (0.0, 0.0, math.pi, 0.0),  # m_init [0, 0, -1, 0, 0]
        "start_variance": (0.01, 0.01, 0.05, 0.01),  # S_init [0.01, 0.01, 0.01, 0.05, 0.01]
        "iterations": 10,
        "num_basis": 60,
    },
    "mountaincar": {
        "cost_weights": (2.0, 0.5),
        "start_mean": (-3.14, 0.0),  # m_init [-3.14, 0] (3.14, not pi)
        "start_variance": (0.01, 0.01),  # S_init [0.01, 0.01]
        "iterations": 8,
        "num_basis": 60,
    },
}

AUTHORS_NOT_REPLICATED = {
    "GP on observation differences": "their GPs predict o' - o (cos/sin differences); leoc's "
    "predict the state change from the observation, a structural choice of its moment code",
    "GP hyperparameter priors and restarts": "Gamma priors on length-scales (1.1, rate 0.1) and "
    "signal variance (1.5, rate 0.5), 2 restarts around 1 +/- 0.01; leoc keeps its hypCurb "
    "penalty, warm starts and 100 L-BFGS iterations",
    "RBF parametrisation and initial draw": "theirs a deterministic GP (pseudo-targets, signal "
    "variance 1, centres N(0, I), targets u_max/10 N(0, 1), length-scales 1, restarts "
    "1 + 0.1 N(0, 1)); leoc's weights directly, centres and length-scales from the data, "
    "weights 0.1 u_max N(0, 1) (the same scale)",
    "relevance bound": "S >= 1e-4 (Lambda <= 1e4); leoc's log Lambda is unbounded",
}
"""The authors' PILCO choices that :func:`authors_pilco_overrides` does not set, and why."""


def authors_pilco_overrides(system: str, hybrid: bool, budget: int | None = None) -> dict[str, Any]:
    """:class:`PilcoConfig` overrides that reproduce the authors' PILCO on ``system``.

    Parameters
    ----------
    system : {"pendulum", "cartpole", "mountaincar"}
        One of the paper's systems (the authors ran no other).
    hybrid : bool
        Add the hybrid's settings (its linear design and moment approximation).
    budget : int, optional
        Policy-learning iterations in place of the authors' ``num_rollouts``; their model
        selection (from after half of the iterations) follows it.

    Returns
    -------
    dict
        Field -> value, for ``PilcoConfig.for_system(system, hybrid=hybrid, **overrides)``;
        each value's source in nrjc/LEOC is documented beside its constant in this module.

    Raises
    ------
    ValueError
        If ``system`` is not one of the paper's systems.
    """
    if system not in AUTHORS_SYSTEM_SETTINGS:
        raise ValueError(
            f"system: the authors' PILCO settings exist for {sorted(AUTHORS_SYSTEM_SETTINGS)}, "
            f"found {system!r}"
        )
    settings = dict(AUTHORS_SYSTEM_SETTINGS[system])
    if budget is not None:
        settings["iterations"] = budget
    overrides: dict[str, Any] = {
        "action_repeat": AUTHORS_SUBS,
        "horizon": AUTHORS_HORIZON,
        "rollout_steps": AUTHORS_ROLLOUT_STEPS,
        "initial_rollouts": AUTHORS_INITIAL_ROLLOUTS,
        "policy_iterations": AUTHORS_POLICY_ITERATIONS,
        "policy_restarts": AUTHORS_POLICY_RESTARTS,
        "cost_width": 1.0,
        "eval_episodes": AUTHORS_EVAL_EPISODES,
        "gp_fixed_noise_var": AUTHORS_NOISE_VAR,
        "select_best_from": settings["iterations"] // 2 + AUTHORS_SELECT_AFTER_HALF,
        "deploy_action_repeat": AUTHORS_DEPLOY_ACTION_REPEAT,
        **settings,
    }
    if hybrid:
        overrides.update(
            lqr_method=AUTHORS_LQR_METHOD,
            hybrid_method=AUTHORS_HYBRID_METHOD,
            lambda_init=AUTHORS_LAMBDA_INIT,
            # the paper's relevance as the authors wrote it: r = (1 + d)^-2, Lambda unbounded
            r_min=None,
            relevance_power=1.0,
        )
    return overrides
