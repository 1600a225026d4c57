"""The evaluations of one controller, each a named evaluator, assembled by one ordered list.

A run's ``evaluation.json`` (:func:`leoc.experiments.reproduce.execute_run`) starts with
:func:`evaluate_controller`'s dict: ``{evaluator.name: evaluator(context)}`` for every
evaluator of :data:`EVALUATORS`, in that order. An evaluator is a name (its key in the file)
and a function of an :class:`EvaluationContext` (the system stepping under the variant's rules,
the controller at its own control period, the run's seed, the variant, the profile's
evaluation budget, and the LQR designed for that period with its proved certificate, computed
once and shared) returning a JSON-friendly value. A new evaluation is one new evaluator and one
entry of the list.

Every evaluation is seeded on its own (the run's seed, or fixed seeds), so the values do not
depend on the order of the list. The proved region and the robustness protocol use fixed seeds
(:data:`PROOF_SEED`, :data:`PROTOCOL_SEED`): every controller of a study meets the same samples,
starts, noise and pushes, so their comparison is paired.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable
from typing import Any, NamedTuple

import torch

from leoc.evaluation.robustness import relevance_trace, robustness_sweep
from leoc.evaluation.rollout import (
    RESPONSE_TESTS,
    control_period,
    measure_response,
    response_test,
)
from leoc.experiments.layout import SWING_UP_EPISODES
from leoc.experiments.profiles import EvaluationBudget, RunSpec
from leoc.experiments.variants import LEOC, Variant
from leoc.names import controller_framework
from leoc.systems.base import System
from leoc.training import evaluate_episodes, evaluation_starts

__all__ = [
    "EVALUATORS",
    "PROOF_SEED",
    "PROTOCOL_SEED",
    "CertifiedLQR",
    "EvaluationContext",
    "Evaluator",
    "certified_lqr",
    "evaluate_action_repeat",
    "evaluate_controller",
    "evaluate_hybrid_claims",
    "evaluate_lqr_agreement",
    "evaluate_proved_region",
    "evaluate_relevance",
    "evaluate_responses",
    "evaluate_robustness",
    "evaluate_robustness_protocol",
    "evaluate_roa",
    "evaluate_swing_up",
    "hybrid_claims_of",
    "refresh_lqr_references",
    "refreshed_proved_region",
    "region_of_attraction",
]

PROOF_SEED = 0
"""Seed of a proved region's sampled estimates and box shares (``leoc roa``'s default): the
same samples for every controller, and for the LQR beside it."""
PROTOCOL_SEED = 0
"""The robustness protocol's one seed (``leoc robustness``' default): every controller of a
study, the LQRs included, runs from the same starts and meets the same noise and pushes."""


DEFAULT_BUDGET = EvaluationBudget()
"""Every evaluation at its own default size (the ``quick`` and ``paper`` profiles')."""


class CertifiedLQR(NamedTuple):
    """An LQR design and its certificate (a tuple: ``design, certificate = lqr``).

    Attributes
    ----------
    design : LQRDesign
        At the controller's control period.
    certificate : LyapunovCertificate
        Its proved certificate (:func:`leoc.control.certify_lqr`).
    """

    design: Any
    certificate: Any


def certified_lqr(system: System, period: int, lqr_method: str = "discrete") -> CertifiedLQR:
    """The LQR design (``lqr_method``) of ``system`` at ``period`` and its proved certificate."""
    from leoc.control import certify_lqr, design_lqr

    design = design_lqr(system, method=lqr_method, action_repeat=period)  # type: ignore[arg-type]
    return CertifiedLQR(design, certify_lqr(system, design))


def hybrid_claims_of(
    system: System,
    controller: torch.nn.Module,
    seed: int,
    lqr: tuple[Any, Any],
    sweep_points: int | None = None,
) -> Any:
    """:func:`leoc.evaluation.hybrid_claims.hybrid_claims` against the LQR ``lqr`` (design and
    certificate, :func:`certified_lqr`) at the controller's period (None for non-hybrids);
    ``sweep_points`` impulse-sweep sizes (None: the sweep's default)."""
    from leoc.evaluation.basins import default_basin_box
    from leoc.evaluation.hybrid_claims import hybrid_claims
    from leoc.policies import lqr_controller

    design, certificate = lqr
    sweep = {} if sweep_points is None else {"sweep_points": sweep_points}
    box = default_basin_box(system)
    return hybrid_claims(
        system, controller, lqr_controller(design), certificate, box, seed, **sweep
    )


def region_of_attraction(
    system: System,
    controller: torch.nn.Module,
    lqr_method: str = "discrete",
    certificate: Any = None,
) -> dict[str, Any]:
    """The certificate of the LQR designed for the controller's period, and the controller's
    empirical basins: on seeded starts in the system's basin box, and on starts uniform in that
    certified set (1.0 when the controller's basin contains it, on those starts)."""
    from leoc.evaluation.basins import (
        basin_starts,
        box_fraction,
        certified_set_check,
        default_basin_box,
        empirical_basin,
    )

    if certificate is None:
        certificate = certified_lqr(system, control_period(controller), lqr_method)[1]
    box = default_basin_box(system)
    basin = empirical_basin(system, controller, basin_starts(system, box), box=box)
    inside = certified_set_check(system, controller, certificate) if certificate.certified else None
    return {
        "certificate": certificate.summary(),
        "box": box.tolist(),
        "certified_box_fraction": box_fraction(certificate, box)[0]
        if certificate.certified
        else 0.0,
        "basin_box_fraction": float(basin.held.mean()),
        "certified_set_held": None if inside is None else float(inside.held.mean()),
    }


@dataclasses.dataclass(frozen=True)
class EvaluationContext:
    """What every evaluator of one run sees.

    Attributes
    ----------
    system_name : str
        The system's name (``RunSpec.system``).
    system : System
        The system stepping under the variant's rules.
    controller : torch.nn.Module
        The trained or designed controller, at its own control period.
    seed : int
        The run's seed.
    variant : Variant
    controller_name : str
        The controller's name (``RunSpec.controller``; ``linear`` and ``linear_pilco`` are the
        LQRs).
    budget : EvaluationBudget
        How large the costliest evaluations are (the profile's; default: their own defaults).
    """

    system_name: str
    system: System
    controller: torch.nn.Module
    seed: int
    variant: Variant
    controller_name: str
    budget: EvaluationBudget = DEFAULT_BUDGET

    @functools.cached_property
    def period(self) -> int:
        """The controller's control period (simulator steps per decision)."""
        return control_period(self.controller)

    @functools.cached_property
    def lqr(self) -> CertifiedLQR:
        """The variant's LQR at :attr:`period` and its proved certificate (computed once)."""
        return certified_lqr(self.system, self.period, self.variant.lqr_method)


@dataclasses.dataclass(frozen=True)
class Evaluator:
    """One evaluation: ``name`` (its key in ``evaluation.json``) and ``evaluate``, a function
    of the :class:`EvaluationContext` returning a JSON-friendly value."""

    name: str
    evaluate: Callable[[EvaluationContext], Any]

    def __call__(self, context: EvaluationContext) -> Any:
        """``evaluate(context)``."""
        return self.evaluate(context)


def evaluate_action_repeat(context: EvaluationContext) -> int:
    """The controller's control period."""
    return context.period


def evaluate_roa(context: EvaluationContext) -> dict[str, Any]:
    """:func:`region_of_attraction` with the shared certificate."""
    return region_of_attraction(
        context.system, context.controller, context.variant.lqr_method, context.lqr.certificate
    )


def evaluate_hybrid_claims(context: EvaluationContext) -> Any:
    """:func:`hybrid_claims_of` against the shared LQR at the budget's sweep sizes (None for
    non-hybrids)."""
    points = context.budget.impulse_sweep_points
    return hybrid_claims_of(context.system, context.controller, context.seed, context.lqr, points)


def evaluate_responses(context: EvaluationContext) -> dict[str, Any]:
    """Every response test, measured with both metric sets: ``metrics`` (leoc's) and
    ``metrics_authors`` (the authors', on their arcsin(sin theta) deviation,
    ``deviation_authors``)."""
    system, controller = context.system, context.controller
    responses = {}
    for test in RESPONSE_TESTS:
        steps = context.variant.steps_for(context.system_name)
        result = response_test(system, controller, test, steps)
        # the same closed loop measured the authors' way: one simulation serves both sets
        authors = measure_response(system, result.trajectory, test, metric_set="authors")
        responses[test] = {
            "metrics": result.metrics._asdict(),
            "deviation": result.deviation.tolist(),
            "total_reward": result.trajectory.total_reward,
            "metrics_authors": authors.metrics._asdict(),
            "deviation_authors": authors.deviation.tolist(),
        }
    return responses


def evaluate_robustness(context: EvaluationContext) -> list[dict[str, Any]]:
    """The robustness sweep's points at the budget's scales, each with its mean return."""
    scales = context.budget.robustness_scales
    sweep = robustness_sweep(
        context.system,
        context.controller,
        seed=context.seed,
        **({} if scales is None else {"scales": scales}),
    )
    return [{**point._asdict(), "return_mean": point.return_mean} for point in sweep]


def evaluate_swing_up(context: EvaluationContext) -> dict[str, Any]:
    """Swing-up episodes from the run's seeded starts: returns, hold steps and their summary."""
    starts = evaluation_starts(context.system, context.seed, SWING_UP_EPISODES)
    swing = evaluate_episodes(context.system, context.controller, starts)
    return {
        "returns": swing.returns,
        "hold_steps": swing.hold_steps,
        "mean_return": swing.mean_return,
        "held_fraction": swing.held_fraction,
    }


def evaluate_relevance(context: EvaluationContext) -> dict[str, list[Any]] | None:
    """The relevance along a seeded swing-up (None for non-hybrids)."""
    trace = relevance_trace(context.system, context.controller, context.seed)
    return None if trace is None else {k: v.tolist() for k, v in trace._asdict().items()}


def evaluate_lqr_agreement(context: EvaluationContext) -> dict[str, Any] | None:
    """:func:`leoc.evaluation.lqr_agreement.lqr_agreement` against the shared LQR: does the
    hybrid keep its LQR's impulse and step responses, and what its relevance learned (None for
    non-hybrids)."""
    from leoc.evaluation.lqr_agreement import lqr_agreement
    from leoc.policies import lqr_controller
    from leoc.systems.rollout import relevance_function

    if relevance_function(context.controller) is None:
        return None
    lqr = lqr_controller(context.lqr.design)
    return lqr_agreement(context.system, context.controller, lqr)


def evaluate_proved_region(context: EvaluationContext) -> dict[str, Any] | None:
    """The controller's own proved region of attraction beside its LQR's
    (:func:`leoc.evaluation.proved_regions.proved_region`, as ``leoc roa --controller RUN
    --prove``): the LQR at its period, saturated as its output is (PILCO's ``sin``), on the
    system's basin box, within the budget's ``proof_boxes`` and ``proof_seconds``; with
    ``saturation``, ``budget_seconds`` and ``budget_boxes``. None for the LQRs (their region is
    the ``roa`` entry's certificate)."""
    from leoc.evaluation.basins import default_basin_box
    from leoc.evaluation.proved_regions import proved_region
    from leoc.policies.hybrid import lqr_certificate, output_saturation

    if controller_framework(context.controller_name) == "linear":
        return None
    system, design = context.system, context.lqr.design
    saturation = output_saturation(context.controller)
    entry = proved_region(
        system,
        context.controller,
        design,
        lqr_certificate(system, design, saturation),
        default_basin_box(system),
        saturation=saturation,
        seed=PROOF_SEED,
        max_seconds=context.budget.proof_seconds,
        max_boxes=context.budget.proof_boxes,
    )
    return {
        **entry,
        "saturation": saturation,
        "budget_seconds": context.budget.proof_seconds,
        "budget_boxes": context.budget.proof_boxes,
    }


def refreshed_proved_region(record: dict[str, Any]) -> dict[str, Any] | None:
    """The ``proved_region`` entry of one run's ``evaluation.json`` (``record``) with its LQR
    reference remade as :func:`evaluate_proved_region` now makes it (the LQR's best V,
    :func:`leoc.evaluation.proved_regions.refresh_lqr_reference`); None when the record has
    no entry or its entry already names its reference's V. Needs no trained model: the
    controller's side of the entry is kept."""
    from leoc.control import design_lqr
    from leoc.evaluation.basins import default_basin_box
    from leoc.evaluation.proved_regions import REFERENCE_KEY, refresh_lqr_reference
    from leoc.experiments.variants import get_variant
    from leoc.policies.hybrid import lqr_certificate

    entry = record.get("proved_region")
    if not isinstance(entry, dict) or REFERENCE_KEY in entry:
        return None
    variant = get_variant(record["variant"])
    system = variant.system(record["spec"]["system"])
    # the design alone: certified_lqr would also prove the clipped LQR, which is not needed
    design = design_lqr(
        system, method=variant.lqr_method, action_repeat=int(record["action_repeat"])
    )
    saturation = entry.get("saturation", "clip")
    riccati = lqr_certificate(system, design, saturation)
    box = default_basin_box(system)
    return refresh_lqr_reference(system, entry, design, riccati, box, seed=PROOF_SEED)


def refresh_lqr_references(folder: Any, echo: Callable[[str], None] = print) -> int:
    """Rewrite (atomically) every ``evaluation.json`` under ``folder/runs`` whose proved
    region was compared with the LQR's Riccati certificate alone
    (:func:`refreshed_proved_region`); returns how many were rewritten."""
    import json
    from pathlib import Path

    from leoc.experiments.layout import EVALUATION_FILE
    from leoc.io import write_json_atomic

    rewritten = 0
    for path in sorted(Path(folder).glob(f"runs/*/*/seed*/{EVALUATION_FILE}")):
        record = json.loads(path.read_text())
        entry = refreshed_proved_region(record)
        if entry is None:
            continue
        record["proved_region"] = entry
        write_json_atomic(path, record)
        rewritten += 1
        where = path.parent.relative_to(folder)
        echo(f"{where}: the LQR reference now keeps its {entry['lqr_lyapunov']} V")
    return rewritten


def evaluate_robustness_protocol(context: EvaluationContext) -> dict[str, Any] | None:
    """The robustness protocol (:func:`leoc.evaluation.robustness_protocol.run_protocol`) at
    the budget's levels and episodes, seeded with :data:`PROTOCOL_SEED`, on the system's
    measured maximum levels: :meth:`~leoc.evaluation.robustness_protocol.ProtocolResult.as_dict`
    (every level's held episodes, and the scores). None for a system without measured maximum
    levels (a user's: ``leoc robustness SYSTEM --calibrate`` measures them)."""
    from leoc.evaluation.robustness_protocol import DEFAULT_MAX_LEVELS, run_protocol

    if context.system.name not in DEFAULT_MAX_LEVELS:
        return None
    result = run_protocol(
        context.system,
        context.controller,
        context.controller_name,
        levels=context.budget.protocol_levels,
        episodes=context.budget.protocol_episodes,
        seed=PROTOCOL_SEED,
    )
    return result.as_dict()


#: The evaluations of :func:`evaluate_controller`, in the order of ``evaluation.json``'s keys.
EVALUATORS: tuple[Evaluator, ...] = (
    Evaluator("action_repeat", evaluate_action_repeat),
    Evaluator("roa", evaluate_roa),
    Evaluator("hybrid_claims", evaluate_hybrid_claims),
    Evaluator("responses", evaluate_responses),
    Evaluator("robustness", evaluate_robustness),
    Evaluator("swing_up", evaluate_swing_up),
    Evaluator("relevance", evaluate_relevance),
    Evaluator("lqr_agreement", evaluate_lqr_agreement),
    Evaluator("proved_region", evaluate_proved_region),
    Evaluator("robustness_protocol", evaluate_robustness_protocol),
)


def evaluate_controller(
    spec: RunSpec,
    controller: torch.nn.Module,
    variant: Variant = LEOC,
    system: System | None = None,
    budget: EvaluationBudget = DEFAULT_BUDGET,
) -> dict[str, Any]:
    """Every evaluation of :data:`EVALUATORS` of one controller, at its period, on the system
    stepping under ``variant``'s rules (``system``, built once by the caller; default
    ``variant.system(spec.system)``), sized by ``budget`` (the profile's):
    ``{evaluator.name: evaluator(context)}`` in order."""
    system = variant.system(spec.system) if system is None else system
    context = EvaluationContext(
        spec.system, system, controller, spec.seed, variant, spec.controller, budget
    )
    return {evaluator.name: evaluator(context) for evaluator in EVALUATORS}
