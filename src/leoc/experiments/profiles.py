"""Typed settings of the paper's experiments: controllers, profiles and run specifications."""

from __future__ import annotations

import dataclasses
from typing import Any, NamedTuple

from leoc.learners import ControllerSpec, get_learner
from leoc.names import (
    CONTROLLERS,
    DEFAULT_CONTROLLERS,
    ROBUSTNESS_EPISODES,
    ROBUSTNESS_LEVELS,
    controller_framework,
    parse_controller,
)
from leoc.systems import SYSTEM_NAMES, system_names

# Every controller, in report order, and the default set (the paper's controllers and the two
# linear references; the ROA- and Lyapunov-relevance hybrids and SAC's controllers are added on
# request) live in leoc.names, where the command line reads them without importing torch.
LINEAR_CONTROLLERS = ("linear", "linear_pilco")
TRAINED_CONTROLLERS = tuple(name for name in CONTROLLERS if name not in LINEAR_CONTROLLERS)
# The linear reference of each framework: the LQR designed and run at that framework's control
# period (DDPG and SAC act every simulator step, PILCO holds each action for ``action_repeat``
# steps).
LINEAR_REFERENCE = {"ddpg": "linear", "td3": "linear", "sac": "linear", "pilco": "linear_pilco"}
CONTROLLER_LABELS = {
    "linear": "linear (LQR at dt)",
    "linear_pilco": "linear (LQR at PILCO's period)",
    "ddpg_baseline": "DDPG baseline",
    "ddpg_hybrid": "DDPG hybrid",
    "ddpg_hybrid_roa": "DDPG hybrid (ROA relevance)",
    "ddpg_hybrid_lyapunov": "DDPG hybrid (Lyapunov relevance)",
    "sac_baseline": "SAC baseline",
    "sac_hybrid": "SAC hybrid",
    "sac_hybrid_roa": "SAC hybrid (ROA relevance)",
    "sac_hybrid_lyapunov": "SAC hybrid (Lyapunov relevance)",
    "td3_baseline": "TD3 baseline",
    "td3_hybrid": "TD3 hybrid",
    "td3_hybrid_roa": "TD3 hybrid (ROA relevance)",
    "td3_hybrid_lyapunov": "TD3 hybrid (Lyapunov relevance)",
    "pilco_baseline": "PILCO baseline",
    "pilco_hybrid": "PILCO hybrid",
    "pilco_hybrid_roa": "PILCO hybrid (ROA relevance)",
}


PROOF_SECONDS = 480.0
"""The paper profile's proof budget [s]: ``leoc roa --proof-seconds``' default
(:data:`leoc.control.proof.MAX_SECONDS`, not imported here: this module imports no torch)."""
PROOF_BOXES = 3_000_000
"""The paper profile's box budget per candidate V: the proof engine's default
(:data:`leoc.control.proof.MAX_BOXES`)."""


def _check_count(value: Any, name: str, least: int) -> None:
    """Raise naming ``name`` unless ``value`` is an integer >= ``least``."""
    if isinstance(value, bool) or not isinstance(value, int) or value < least:
        raise ValueError(
            f"EvaluationBudget.{name}: expected an integer >= {least}, found {value!r}"
        )


@dataclasses.dataclass(frozen=True)
class EvaluationBudget:
    """How large a profile's costliest evaluations are (:mod:`leoc.experiments.evaluators`):
    the trained controllers' own proofs, the robustness protocol, the robustness sweep and the
    hybrids' impulse sweep. The defaults are the paper profile's, each evaluation's own default;
    the ``quick`` profile proves and runs the protocol on shorter budgets, the ``smoke``
    profile, a pipeline check, evaluates everything on fewer points.

    Attributes
    ----------
    proof_seconds : float
        Wall-clock budget [s] of one controller's box searches (``proved_region``;
        :func:`leoc.control.certify_controller`'s ``max_seconds``, shared by its candidate V);
        past it the level proved so far is kept, limited by ``budget``.
    protocol_levels : int
        Levels per category of the robustness protocol (``robustness_protocol``), >= 2
        (:func:`leoc.evaluation.robustness_protocol.run_protocol`'s ``levels``).
    protocol_episodes : int
        Episodes per level and start kind of the robustness protocol, >= 1.
    proof_boxes : int
        Box budget of each candidate V's search (``max_boxes``): unlike the wall-clock budget
        it gives the same level on every machine and every rerun, so the small profiles bound
        their proofs by boxes and keep the seconds as a safety valve.
    robustness_scales : tuple of float or None
        Factors on the mass and on g of the robustness sweep (``robustness``; None: every
        factor of :data:`leoc.evaluation.robustness.SCALE_FACTORS`, 0.5 ... 5.0 in steps of
        0.5).
    impulse_sweep_points : int or None
        Sizes of the hybrids' impulse sweep against their LQR (``hybrid_claims``; None:
        :data:`leoc.evaluation.impulse_sweep.SWEEP_POINTS`), >= 2: the paper's size and the
        LQR's failure size at least.
    """

    proof_seconds: float = PROOF_SECONDS
    protocol_levels: int = ROBUSTNESS_LEVELS
    protocol_episodes: int = ROBUSTNESS_EPISODES
    proof_boxes: int = PROOF_BOXES
    robustness_scales: tuple[float, ...] | None = None
    impulse_sweep_points: int | None = None

    def __post_init__(self) -> None:
        seconds = self.proof_seconds
        if isinstance(seconds, bool) or not isinstance(seconds, (int, float)) or not seconds > 0:
            raise ValueError(
                f"EvaluationBudget.proof_seconds: expected a positive number, found {seconds!r}"
            )
        _check_count(self.proof_boxes, "proof_boxes", 1)
        _check_count(self.protocol_levels, "protocol_levels", 2)
        _check_count(self.protocol_episodes, "protocol_episodes", 1)
        scales = self.robustness_scales
        if scales is not None and (
            not isinstance(scales, tuple)
            or not scales
            or not all(
                isinstance(s, (int, float)) and not isinstance(s, bool) and s > 0 for s in scales
            )
        ):
            raise ValueError(
                "EvaluationBudget.robustness_scales: expected None or a non-empty tuple of "
                f"positive numbers, found {scales!r}"
            )
        points = self.impulse_sweep_points
        if points is not None and (
            isinstance(points, bool) or not isinstance(points, int) or points < 2
        ):
            raise ValueError(
                "EvaluationBudget.impulse_sweep_points: expected None or an integer >= 2, "
                f"found {points!r}"
            )

    def describe(self) -> str:
        """Where the budget reduces the evaluations, in words, for the report ("" for the
        paper profile's)."""
        parts = []
        if self.robustness_scales is not None:
            scales = ", ".join(f"{s:g}x" for s in self.robustness_scales)
            parts.append(f"robustness at {scales} only")
        if self.impulse_sweep_points is not None:
            parts.append(f"{self.impulse_sweep_points} impulse-sweep sizes")
        if self.proof_boxes != PROOF_BOXES:
            parts.append(f"proofs of {self.proof_boxes} boxes per candidate V")
        if (self.protocol_levels, self.protocol_episodes) != (
            ROBUSTNESS_LEVELS,
            ROBUSTNESS_EPISODES,
        ):
            parts.append(
                f"robustness protocol at {self.protocol_levels} levels x "
                f"{self.protocol_episodes} episode{'s' if self.protocol_episodes != 1 else ''}"
            )
        return "; ".join(parts)


@dataclasses.dataclass(frozen=True)
class Profile:
    """Budgets of one ``leoc reproduce`` profile.

    Attributes
    ----------
    name : str
    seeds : tuple of int
        Training seeds; every controller of every system is trained once per seed.
    pilco_iterations : dict system -> int
        PILCO iterations after the random rollouts (None entries: the PILCO default).
    ddpg_steps : dict system -> int
        DDPG environment steps (None entries: the DDPG default, 10k / 21k / 20k); SAC's
        runs get the same budgets.
    default_pilco_iterations, default_ddpg_steps : int or None
        The budgets of a system missing from the dicts (a user's registered system).
    pilco_overrides, ddpg_overrides : dict
        Further keyword settings passed to the trainers (``ddpg_overrides`` to SAC's too).
    run_seconds : dict ``"system/controller"`` -> float
        Measured wall time of one run of that kind on one worker (the ETA's expected costs,
        :mod:`leoc.experiments.eta`) under leoc's variant; kinds not listed: see
        :meth:`expected_seconds`.
    variant_run_seconds : dict variant -> dict ``"system/controller"`` -> float
        The same measured under another variant (``authors``), where it costs otherwise; see
        :meth:`for_variant`.
    evaluation : EvaluationBudget
        How large the costliest evaluations of each run are (default: every evaluation's own
        default).
    evaluation_seconds : dict ``"system/learner"`` -> float
        Expected wall time [s] that :attr:`evaluation`'s proof and protocol add to one run of
        that system and learner (``linear`` for the LQRs), beyond :attr:`run_seconds`, which
        were measured before those evaluations existed; see :meth:`expected_seconds`.
    training_perturbations : dict
        The perturbations every trained run of the profile is trained under
        (:meth:`leoc.systems.TrainingPerturbations.as_dict`: fixed levels, randomised maxima);
        empty (every built-in profile): the nominal plant. ``leoc train --perturb`` and
        ``--randomise`` replace it.
    """

    name: str
    seeds: tuple[int, ...]
    pilco_iterations: dict[str, int | None]
    ddpg_steps: dict[str, int | None]
    default_pilco_iterations: int | None = None
    default_ddpg_steps: int | None = None
    pilco_overrides: dict[str, Any] = dataclasses.field(default_factory=dict)
    ddpg_overrides: dict[str, Any] = dataclasses.field(default_factory=dict)
    description: str = ""
    run_seconds: dict[str, float] = dataclasses.field(default_factory=dict)
    variant_run_seconds: dict[str, dict[str, float]] = dataclasses.field(default_factory=dict)
    evaluation: EvaluationBudget = EvaluationBudget()
    evaluation_seconds: dict[str, float] = dataclasses.field(default_factory=dict)
    training_perturbations: dict[str, Any] = dataclasses.field(default_factory=dict)

    def for_variant(self, variant: str) -> Profile:
        """This profile costed as it runs under ``variant`` (a name of
        :mod:`leoc.experiments.variants`): its :attr:`variant_run_seconds` in place of leoc's,
        kind by kind; the kinds that variant's study did not run keep leoc's costs."""
        measured = self.variant_run_seconds.get(variant)
        if not measured:
            return self
        return dataclasses.replace(self, run_seconds={**self.run_seconds, **measured})

    def expected_seconds(self, spec: RunSpec) -> float:
        """Expected wall time of ``spec`` on one worker: :meth:`training_seconds` plus
        :meth:`evaluation_cost` (see :attr:`cost_model` for a profile with no measurements at
        all)."""
        return self.training_seconds(spec) + self.evaluation_cost(spec)

    def training_seconds(self, spec: RunSpec) -> float:
        """Expected wall time of ``spec``'s training and of the evaluations the measured
        studies ran (all but the proof and the protocol): its kind's :attr:`run_seconds`, else
        the mean of the measured runs of its controller on other systems, else the framework's
        fallback."""
        known = self.run_seconds.get(f"{spec.system}/{spec.controller}")
        if known is not None:
            return known
        same = [v for k, v in self.run_seconds.items() if k.endswith(f"/{spec.controller}")]
        if same:
            return sum(same) / len(same)
        if spec.framework in FALLBACK_RUN_SECONDS:
            return FALLBACK_RUN_SECONDS[spec.framework]
        # a learner with no study of its own (TD3) costs as the one whose settings it takes
        return FALLBACK_RUN_SECONDS[get_learner(spec.framework).settings_of]

    def evaluation_cost(self, spec: RunSpec) -> float:
        """What the proof and the protocol add to ``spec`` [s]: :attr:`evaluation_seconds` of
        its system and learner, else the mean of that learner's on other systems, else 0."""
        known = self.evaluation_seconds.get(f"{spec.system}/{spec.framework}")
        if known is not None:
            return known
        same = [v for k, v in self.evaluation_seconds.items() if k.endswith(f"/{spec.framework}")]
        return sum(same) / len(same) if same else 0.0

    @property
    def cost_model(self):
        """:meth:`expected_seconds` for the sweep's ETA, or None when the profile has no
        measured costs (the sweep then estimates from the runs that finish)."""
        return self.expected_seconds if self.run_seconds else None

    def iterations_for(self, system: str) -> int | None:
        """PILCO iterations of ``system`` (None: the PILCO default)."""
        return self.pilco_iterations.get(system, self.default_pilco_iterations)

    def steps_for(self, system: str) -> int | None:
        """DDPG (and SAC) steps of ``system`` (None: the DDPG default)."""
        return self.ddpg_steps.get(system, self.default_ddpg_steps)

    def training_settings(
        self, variant: Any, controller: ControllerSpec, system: str, budget: int | None = None
    ) -> dict[str, Any]:
        """Config fields of one run of ``controller`` under this profile: the variant's
        settings (:meth:`~leoc.experiments.variants.Variant.training_settings`) at this
        profile's budget, or ``budget`` where given, then this profile's overrides. The one
        assembly ``leoc reproduce`` and ``leoc train`` share. The learner's ``settings_of``
        says whose settings it takes (TD3 DDPG's); its ``budget_unit`` which budget (PILCO's
        iterations, or the others' environment steps). The hybrid itself is
        ``controller.hybrid``, which these fields may refine (the authors' Lambda). A profile's
        :attr:`training_perturbations` is added when it has any."""
        learner = get_learner(controller.learner)
        iterations = learner.budget_unit == "iterations"
        if budget is None:
            budget = self.iterations_for(system) if iterations else self.steps_for(system)
        overrides = self.pilco_overrides if iterations else self.ddpg_overrides
        hybrid = controller.hybrid is not None
        settings = {**variant.training_settings(learner.settings_of, system, hybrid, budget)}
        settings.update(overrides)
        # the relevance design is the controller's own (its name says which): a variant's or a
        # profile's settings refine the hybrid's parameters, never switch its design
        settings.pop("relevance", None)
        if self.training_perturbations:
            settings["training_perturbations"] = dict(self.training_perturbations)
        return settings


# Measured run costs [s], the ETA's expected costs (leoc.experiments.eta): the median over seeds
# of each kind's wall time (training and evaluation on one worker, evaluation.json's
# wall_seconds) in the published studies, both run at leoc commit b22ddf0 at today's budgets,
# 2 workers on a 2-core AMD EPYC (torch's AVX2 kernels). Printed by
# benchmarks/bench_eta_costs.py (leoc.experiments.eta.measured_run_seconds); not typed by hand:
# tests/test_eta_costs.py checks each table still equals what the function gives on results/.
# leoc's variant: results/paper (141 runs, seeds 0-4).
PAPER_RUN_SECONDS = {
    "pendulum/linear": 0.9,
    "pendulum/linear_pilco": 1.3,
    "pendulum/ddpg_baseline": 46.3,
    "pendulum/ddpg_hybrid": 52.2,
    "pendulum/ddpg_hybrid_roa": 55.3,
    "pendulum/sac_baseline": 168.1,
    "pendulum/sac_hybrid": 181.2,
    "pendulum/sac_hybrid_roa": 190.5,
    "pendulum/pilco_baseline": 86.1,
    "pendulum/pilco_hybrid": 90.3,
    "pendulum/pilco_hybrid_roa": 107.1,
    "cartpole/linear": 1.3,
    "cartpole/linear_pilco": 1.2,
    "cartpole/ddpg_baseline": 94.2,
    "cartpole/ddpg_hybrid": 101.2,
    "cartpole/ddpg_hybrid_roa": 106.7,
    "cartpole/sac_baseline": 360.1,
    "cartpole/sac_hybrid": 396.8,
    "cartpole/sac_hybrid_roa": 579.2,
    "cartpole/pilco_baseline": 164.6,
    "cartpole/pilco_hybrid": 176.2,
    "cartpole/pilco_hybrid_roa": 172.8,
    "mountaincar/linear": 0.9,
    "mountaincar/linear_pilco": 0.9,
    "mountaincar/ddpg_baseline": 86.8,
    "mountaincar/ddpg_hybrid": 99.1,
    "mountaincar/ddpg_hybrid_roa": 96.5,
    "mountaincar/sac_baseline": 359.3,
    "mountaincar/sac_hybrid": 387.2,
    "mountaincar/sac_hybrid_roa": 398.3,
    "mountaincar/pilco_baseline": 98.0,
    "mountaincar/pilco_hybrid": 102.6,
    "mountaincar/pilco_hybrid_roa": 100.7,
}
# The authors' variant (``--variant authors``): results/paper-authors (42 runs, seeds 0-2), on
# the same machine: its runs take 0.55-1.2x leoc's of the same kind (costed with leoc's former
# table, its first ETA was 182% high). It has no SAC or ROA-relevance hybrid runs: those kinds
# keep leoc's costs (Profile.for_variant).
AUTHORS_RUN_SECONDS = {
    "pendulum/linear": 1.2,
    "pendulum/linear_pilco": 1.1,
    "pendulum/ddpg_baseline": 49.6,
    "pendulum/ddpg_hybrid": 56.1,
    "pendulum/pilco_baseline": 98.8,
    "pendulum/pilco_hybrid": 108.7,
    "cartpole/linear": 1.5,
    "cartpole/linear_pilco": 1.5,
    "cartpole/ddpg_baseline": 70.3,
    "cartpole/ddpg_hybrid": 78.0,
    "cartpole/pilco_baseline": 131.7,
    "cartpole/pilco_hybrid": 156.1,
    "mountaincar/linear": 1.0,
    "mountaincar/linear_pilco": 1.2,
    "mountaincar/ddpg_baseline": 48.0,
    "mountaincar/ddpg_hybrid": 53.1,
    "mountaincar/pilco_baseline": 87.7,
    "mountaincar/pilco_hybrid": 106.3,
}
FALLBACK_RUN_SECONDS = {"linear": 1.1, "ddpg": 92.1, "sac": 364.7, "pilco": 102.6}
"""Expected wall time [s] of a run whose controller a profile has no measurement for (a user's
system's runs take their controller's mean over the measured systems first): the median of
each learner's runs in results/paper (:func:`leoc.experiments.eta.measured_learner_seconds`),
as the tables above."""
# The quick profile's run costs [s] (not re-measured with the tables above: no quick study is
# published under results/): each default run's wall time in one invocation on an idle
# 2-core AMD EPYC (`leoc reproduce --profile quick --jobs 2`, leoc commit e66f953, 522 s in
# all); the ROA hybrids, which the quick profile does not run by default, are their paper-
# relevance hybrid's time scaled by the ratio of the two in the paper profile.
QUICK_RUN_SECONDS = {
    "pendulum/linear": 4.0,
    "pendulum/linear_pilco": 4.0,
    "pendulum/ddpg_baseline": 66.0,
    "pendulum/ddpg_hybrid": 79.0,
    "pendulum/ddpg_hybrid_roa": 88.0,
    "pendulum/pilco_baseline": 103.0,
    "pendulum/pilco_hybrid": 132.0,
    "pendulum/pilco_hybrid_roa": 128.0,
    "cartpole/linear": 8.0,
    "cartpole/linear_pilco": 10.0,
    "cartpole/ddpg_baseline": 101.0,
    "cartpole/ddpg_hybrid": 93.0,
    "cartpole/ddpg_hybrid_roa": 111.0,
    "cartpole/pilco_baseline": 79.0,
    "cartpole/pilco_hybrid": 109.0,
    "cartpole/pilco_hybrid_roa": 112.0,
    "mountaincar/linear": 4.0,
    "mountaincar/linear_pilco": 4.0,
    "mountaincar/ddpg_baseline": 77.0,
    "mountaincar/ddpg_hybrid": 74.0,
    "mountaincar/ddpg_hybrid_roa": 86.0,
    "mountaincar/pilco_baseline": 50.0,
    "mountaincar/pilco_hybrid": 44.0,
    "mountaincar/pilco_hybrid_roa": 44.0,
}
# What the proof and the protocol add to a run [s] (Profile.evaluation_seconds): the tables
# above were measured before they existed. The LQR's protocol at the paper's budget on one core
# of the same machine (docs/user_guide/robustness_protocol.md's table); a learned controller's
# protocol costs a factor more per episode (measured side by side on one loaded core, CPU time:
# a DDPG actor 2.0x the LQR, a PILCO RBF policy at its period 1.4x; TD3's and SAC's actors are
# DDPG's MLP);
# the quick budget's 5 levels x 2 episodes run 0.3x the paper's settings (CPU time, measured).
# A trained controller's proof: 25 s on the 2-D systems (benchmarks/bench_controller_proof.py:
# trained pendulum controllers 18-25 s with both V; a mountain-car hybrid 10 s on a loaded
# core), the cart-pole's its whole budget (its LQR alone takes 168 s, docs/user_guide/roa.md).
PROTOCOL_LQR_SECONDS = {"pendulum": 15.0, "cartpole": 16.0, "mountaincar": 31.0}
"""The LQR's robustness protocol at the paper's budget [s] per system (one core)."""
PROTOCOL_LEARNER_FACTOR = {"linear": 1.0, "ddpg": 2.0, "td3": 2.0, "sac": 2.0, "pilco": 1.4}
"""A learner's controller's protocol time over the LQR's (measured side by side)."""
QUICK_PROTOCOL_SHARE = 0.3
"""The quick budget's protocol time over the paper's (measured)."""
TRAINED_PROOF_SECONDS = {"pendulum": 25.0, "cartpole": PROOF_SECONDS, "mountaincar": 25.0}
"""A trained controller's proof [s] per system, without a budget cut (the cart-pole's: the
paper's whole budget)."""


def evaluation_costs(protocol_share: float, proof_seconds: float) -> dict[str, float]:
    """Expected seconds the proof and the protocol add to a run, by ``"system/learner"``:
    the protocol at ``protocol_share`` of the paper's settings, and a trained controller's
    proof cut at ``proof_seconds`` (the tables and their sources are in the comment above)."""
    costs = {}
    for system, protocol in PROTOCOL_LQR_SECONDS.items():
        for learner, factor in PROTOCOL_LEARNER_FACTOR.items():
            proof = (
                0.0 if learner == "linear" else min(TRAINED_PROOF_SECONDS[system], proof_seconds)
            )
            costs[f"{system}/{learner}"] = round(protocol * factor * protocol_share + proof, 1)
    return costs


QUICK_EVALUATION_SECONDS = evaluation_costs(QUICK_PROTOCOL_SHARE, 30.0)
"""The quick profile's :attr:`Profile.evaluation_seconds` (30 s proofs, 5 levels x 2 episodes)."""
PAPER_EVALUATION_SECONDS = evaluation_costs(1.0, PROOF_SECONDS)
"""The paper profile's :attr:`Profile.evaluation_seconds` (480 s proofs, 21 levels x 5
episodes)."""

SMOKE_EVALUATION = EvaluationBudget(
    robustness_scales=(0.5, 1.0, 5.0),
    impulse_sweep_points=2,
    proof_seconds=60.0,
    proof_boxes=2_000,
    protocol_levels=3,
    protocol_episodes=1,
)
"""The smoke profile's evaluation budget: the robustness sweep at the smallest, the nominal and
the largest scale, the impulse sweep at the paper's size and the LQR's failure size, each
trained controller's proof bounded by 2000 boxes per candidate V (a box budget proves the same
level on every machine and every rerun; the 60 s are a safety valve), the robustness protocol
at 3 levels and 1 episode. Every evaluation still runs, on fewer points."""

#: The ``leoc reproduce`` profiles by name: ``quick`` (default), ``smoke`` and ``paper``.
PROFILES: dict[str, Profile] = {
    "quick": Profile(
        name="quick",
        seeds=(0,),
        pilco_iterations={"pendulum": 5, "cartpole": 4, "mountaincar": 3},
        ddpg_steps={"pendulum": 5000, "cartpole": 8000, "mountaincar": 6000},
        pilco_overrides={"policy_iterations": 40},
        description=(
            "quick profile: one seed and reduced training budgets (real training, not the "
            "paper's budgets); numbers are indicative, not a reproduction of the paper's"
        ),
        run_seconds=QUICK_RUN_SECONDS,
        evaluation=EvaluationBudget(proof_seconds=30.0, protocol_levels=5, protocol_episodes=2),
        evaluation_seconds=QUICK_EVALUATION_SECONDS,
    ),
    "smoke": Profile(
        name="smoke",
        seeds=(0,),
        pilco_iterations={name: 1 for name in SYSTEM_NAMES},
        ddpg_steps={name: 400 for name in SYSTEM_NAMES},
        default_pilco_iterations=1,
        default_ddpg_steps=400,
        pilco_overrides={
            "horizon": 10,
            "num_basis": 5,
            "policy_iterations": 3,
            "initial_rollouts": 1,
        },
        ddpg_overrides={
            "learning_starts": 100,
            "eval_interval": 200,
            "eval_episodes": 1,
            "actor_hidden": (32, 32),
            "critic_hidden": (32, 32),
        },
        description=(
            "smoke profile: a tiny end-to-end check of the pipeline (a few hundred steps of "
            f"training; evaluated on a reduced grid: {SMOKE_EVALUATION.describe()}); its "
            "controllers are not trained and its numbers mean nothing"
        ),
        evaluation=SMOKE_EVALUATION,
    ),
    "paper": Profile(
        name="paper",
        seeds=(0, 1, 2, 3, 4),
        pilco_iterations={name: None for name in SYSTEM_NAMES},
        ddpg_steps={name: None for name in SYSTEM_NAMES},
        description=(
            "paper profile: the paper's PILCO budgets (appendix C) and leoc's DDPG/SAC budgets "
            "(10k steps on the pendulum, 21k on the cart-pole, 20k on the mountain car, where "
            "the paper's 15k and 10k did not learn on 4 of 5 seeds)"
        ),
        run_seconds=PAPER_RUN_SECONDS,
        variant_run_seconds={"authors": AUTHORS_RUN_SECONDS},
        evaluation=EvaluationBudget(),
        evaluation_seconds=PAPER_EVALUATION_SECONDS,
    ),
}
PROFILE_NAMES = tuple(PROFILES)


def get_profile(name: str, seeds: int | None = None) -> Profile:
    """The named profile, optionally with its seeds replaced by ``0 .. seeds - 1``."""
    if name not in PROFILES:
        raise ValueError(f"profile: expected one of {', '.join(PROFILES)}, found {name!r}")
    profile = PROFILES[name]
    if seeds is not None:
        if seeds < 1:
            raise ValueError(f"seeds: expected a positive integer, found {seeds}")
        profile = dataclasses.replace(profile, seeds=tuple(range(seeds)))
    return profile


class RunSpec(NamedTuple):
    """One unit of work: a controller of a system, for one seed."""

    system: str
    controller: str
    seed: int

    @property
    def key(self) -> str:
        """Run folder path ``system/controller/seedN`` under the output folder's ``runs``."""
        return f"{self.system}/{self.controller}/seed{self.seed}"

    @property
    def controller_spec(self) -> ControllerSpec:
        """What the run trains (:class:`~leoc.learners.ControllerSpec`, read from its name)."""
        return ControllerSpec.from_name(self.controller)

    @property
    def framework(self) -> str:
        """The learner (``ddpg``, ``sac``, ``pilco``, ...) or ``linear``."""
        return controller_framework(self.controller)

    @property
    def hybrid(self) -> bool:
        """Whether the controller is a hybrid."""
        return parse_controller(self.controller).hybrid


def run_specs(
    profile: Profile,
    systems: tuple[str, ...] = SYSTEM_NAMES,
    controllers: tuple[str, ...] = DEFAULT_CONTROLLERS,
) -> list[RunSpec]:
    """Every run of a profile, the longest first (:meth:`Profile.expected_seconds`) to balance
    the workers: a long run started last would keep one worker busy while the others idle.

    ``systems``: registered names (default: the paper's three)."""
    known = system_names()
    for name in systems:
        if name not in known:
            raise ValueError(f"systems: unknown {name!r}; expected some of {known}")
    for name in controllers:
        if name not in CONTROLLERS:
            raise ValueError(f"controllers: unknown {name!r}; expected some of {CONTROLLERS}")
    specs = [
        RunSpec(system, controller, seed)
        for system in systems
        for controller in controllers
        for seed in (profile.seeds if controller not in LINEAR_CONTROLLERS else (0,))
    ]
    return sorted(specs, key=lambda spec: -profile.expected_seconds(spec))
