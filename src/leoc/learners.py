"""Learners: one protocol, one registry, and the typed spec of a controller to train.

A learner trains a controller on a system and loads it back from its run folder. Each is
registered by name, as systems are (:func:`register_learner`; ``leoc.systems.register``):
``leoc train --algo NAME``, ``leoc reproduce`` and the report find it there. leoc registers
four: ``ddpg``, ``td3`` and ``sac`` (Stable-Baselines3, :mod:`leoc.sb3`) and ``pilco``
(:mod:`leoc.pilco`). A learner outside SB3 is one class with the :class:`Learner` methods and
one :func:`register_learner` call.

:class:`ControllerSpec` is what a run trains: its learner, its hybrid
(:class:`~leoc.policies.HybridSpec`, or None for the learned policy alone) and, for the linear
references, whose control period the LQR runs at. It is read once from a controller name
(``ddpg_hybrid_roa``, :meth:`ControllerSpec.from_name`) at the edge and handed down as the
object.

This module imports no learner at import time: each learner's package is imported when it
trains or loads.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar, Protocol, runtime_checkable

from leoc.names import LINEAR, ControllerName, parse_controller

if TYPE_CHECKING:
    import torch

    from leoc.policies.spec import HybridSpec
    from leoc.systems.base import System
    from leoc.training import TrainResult

__all__ = [
    "ControllerSpec",
    "Learner",
    "PilcoLearner",
    "SB3Learner",
    "get_learner",
    "learner_names",
    "register_learner",
]


@dataclasses.dataclass(frozen=True)
class ControllerSpec:
    """What one run trains (or designs).

    Attributes
    ----------
    learner : str
        A registered learner's name (:func:`learner_names`), or ``linear`` for an LQR reference
        (designed, not trained).
    hybrid : HybridSpec or None
        The LEOC hybrid to train (its relevance design and parameters; a learner's settings may
        refine the parameters), or None for the learned policy alone (a baseline) and the LQR.
    period_of : str or None
        A linear reference's control period: that of this learner (``linear_pilco``: PILCO's);
        None: every simulator step. Trained controllers run at their learner's own period.
    """

    learner: str
    hybrid: HybridSpec | None = None
    period_of: str | None = None

    @classmethod
    def from_name(cls, name: str) -> ControllerSpec:
        """The spec a controller name describes (:func:`leoc.names.parse_controller`):
        ``ddpg_hybrid_roa`` is DDPG with ``HybridSpec(relevance="roa")``."""
        from leoc.policies.spec import HybridSpec

        parsed = parse_controller(name)
        hybrid = None if parsed.relevance is None else HybridSpec(relevance=parsed.relevance)
        return cls(parsed.learner, hybrid, parsed.period_of)

    @property
    def name(self) -> str:
        """The controller's name (runs, reports): ``LEARNER_KIND``, ``linear[_LEARNER]``."""
        relevance = None if self.hybrid is None else self.hybrid.relevance
        return ControllerName(self.learner, relevance, self.period_of).name

    @property
    def linear(self) -> bool:
        """Whether this is an LQR reference (designed, not trained)."""
        return self.learner == LINEAR


@runtime_checkable
class Learner(Protocol):
    """What leoc asks of a learner.

    Attributes
    ----------
    name : str
        Its registry name (``leoc train --algo NAME``).
    settings_of : str
        The learner whose settings (variants' and profiles' budgets and overrides) it takes:
        its own name, or another's (TD3 takes DDPG's).
    budget_unit : str
        What its budget counts (``steps``: environment steps; ``iterations``).
    marker : str
        A file only its run folders hold (how a run folder is recognised).
    """

    name: str
    settings_of: str
    budget_unit: str
    marker: str

    def default_budget(self, system: str) -> int | None:
        """Its budget on ``system`` when none is given (None: no default of its own)."""
        ...

    def train(
        self,
        system: System,
        controller: ControllerSpec,
        seed: int,
        out: Path,
        settings: dict[str, Any],
        progress: bool = True,
        overwrite: bool = False,
    ) -> TrainResult:
        """Train ``controller`` on ``system`` with ``seed`` into the run folder ``out`` and
        return the :class:`~leoc.training.TrainResult` (the controller at its control period,
        its learning curve rows and summary). ``settings``: config fields (the variant's and
        profile's); ``progress``: print progress lines; a folder of the same run resumes, one of
        another is refused unless ``overwrite``."""
        ...

    def load(self, run_dir: Path) -> torch.nn.Module:
        """The trained controller of a run folder, at its control period (physical units)."""
        ...


class SB3Learner:
    """DDPG, TD3 or SAC through Stable-Baselines3 (:func:`leoc.sb3.train_ddpg`)."""

    budget_unit: ClassVar[str] = "steps"
    marker: ClassVar[str] = "model.zip"

    def __init__(self, algo: str, settings_of: str | None = None) -> None:
        self.name = algo
        self.settings_of = settings_of or algo

    def default_budget(self, system: str) -> int | None:
        from leoc.sb3.config import DEFAULT_TOTAL_STEPS, TOTAL_STEPS_BY_SYSTEM

        return TOTAL_STEPS_BY_SYSTEM.get(system, DEFAULT_TOTAL_STEPS)

    def train(
        self,
        system: System,
        controller: ControllerSpec,
        seed: int,
        out: Path,
        settings: dict[str, Any],
        progress: bool = True,
        overwrite: bool = False,
    ) -> TrainResult:
        import sys

        from leoc.progress import is_terminal
        from leoc.sb3.train import train_ddpg

        # a bar on a terminal, plain lines in a log (leoc reproduce's workers)
        shown = (True if is_terminal(sys.stdout) else "lines") if progress else False
        return train_ddpg(
            system,
            algo=self.name,
            hybrid=controller.hybrid,
            seed=seed,
            run_dir=out,
            progress=shown,
            overwrite=overwrite,
            **settings,
        )

    def load(self, run_dir: Path) -> torch.nn.Module:
        from leoc.sb3.train import load_ddpg_controller

        return load_ddpg_controller(run_dir)


class PilcoLearner:
    """PILCO (Deisenroth & Rasmussen 2011; :func:`leoc.pilco.train_pilco`)."""

    name: ClassVar[str] = "pilco"
    settings_of: ClassVar[str] = "pilco"
    budget_unit: ClassVar[str] = "iterations"
    marker: ClassVar[str] = "controller.pt"

    def default_budget(self, system: str) -> int | None:
        from leoc.pilco.config import PilcoConfig

        return PilcoConfig.for_system(system).iterations

    def train(
        self,
        system: System,
        controller: ControllerSpec,
        seed: int,
        out: Path,
        settings: dict[str, Any],
        progress: bool = True,
        overwrite: bool = False,
    ) -> TrainResult:
        from leoc.pilco.train import train_pilco

        return train_pilco(
            system,
            hybrid=controller.hybrid,
            seed=seed,
            run_dir=out,
            resume=not overwrite,
            progress=progress,
            **settings,
        )

    def load(self, run_dir: Path) -> torch.nn.Module:
        from leoc.pilco.checkpoint import load_pilco_controller

        return load_pilco_controller(run_dir)


_LEARNERS: dict[str, Learner] = {}


def register_learner(learner: Learner, replace: bool = False) -> Learner:
    """Add ``learner`` to the registry under ``learner.name`` and return it.

    Raises
    ------
    TypeError
        If it lacks a :class:`Learner` attribute or method.
    ValueError
        If the name is taken (unless ``replace``) or is ``linear`` (the LQR references').
    """
    if not isinstance(learner, Learner):
        raise TypeError(
            "learner: expected an object with the Learner attributes and methods (name, "
            "settings_of, budget_unit, marker, default_budget, train, load), found "
            f"{type(learner).__name__}"
        )
    if learner.name == LINEAR or "_" in learner.name:
        raise ValueError(
            f"learner.name: expected a name without '_' other than {LINEAR!r} (controller names "
            f"are LEARNER_KIND), found {learner.name!r}"
        )
    if learner.name in _LEARNERS and not replace:
        raise ValueError(f"learner.name: {learner.name!r} is registered already")
    _LEARNERS[learner.name] = learner
    return learner


def learner_names() -> tuple[str, ...]:
    """The registered learners' names, in registration order."""
    return tuple(_LEARNERS)


def get_learner(name: str) -> Learner:
    """The registered learner ``name``.

    Raises
    ------
    ValueError
        Naming ``learner``, the registered names and what was found.
    """
    try:
        return _LEARNERS[name]
    except KeyError:
        raise ValueError(f"learner: expected one of {learner_names()}, found {name!r}") from None


for _learner in (
    PilcoLearner(),
    SB3Learner("ddpg"),
    SB3Learner("td3", settings_of="ddpg"),
    SB3Learner("sac"),
):
    register_learner(_learner)
