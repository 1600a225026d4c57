"""Implementation variants: leoc's own choices, and the authors' (nrjc/LEOC) that the paper's
numbers come from.

A :class:`Variant` is one frozen object, built at the edge from a name (``--variant``) and
passed down; nothing below the edge asks which variant it is. Each field names one choice where
the two implementations differ, documented with the nrjc/LEOC file it follows:

=====================  ====================================  ===================================
field                  leoc (default)                        authors
=====================  ====================================  ===================================
``lqr_method``         ``discrete``: DARE on the exact       ``authors``: ``control.lqr`` on
                       linearisation of the step map         their ``env.control()`` models,
                                                             R = 1, times u_max
                                                             (``dao/controller_utils.py``,
                                                             ``dao/envs/*_env.py``)
``linear_saturation``  ``none`` (the system clips,           ``sin``: u_max sin(W o / u_max),
                       exact inside the limits)              their PILCO ``LinearController``
                                                             (``pilco/controllers.py``)
``step_rules``         leoc's :class:`StepRules`             exit -100 once, reward after the
                       (an exit never pays)                  step (cart-pole, mountain car);
                                                             gym 0.17's pendulum integrator
``response_steps``     200 simulator steps                   400 on the cart-pole (the length
                                                             of the paper's cart-pole record)
``ddpg``               none (DDPGConfig's defaults)          :func:`authors_ddpg_overrides`
                                                             (TF-Agents DDPG as
                                                             ``DDPG/ddpg.py`` and the gin
                                                             files configure it)
``pilco``              none (PilcoConfig's defaults)         :func:`authors_pilco_overrides`
                                                             (``dao/trainer.py``, the gin files)
``sac``                none (SAC's defaults)                 none (the authors ran no SAC: their
                                                             LQR and step rules, leoc's SAC)
=====================  ====================================  ===================================

The metric set (leoc's or the authors', :mod:`leoc.evaluation.metric_sets`) is chosen apart
from the variant: ``leoc reproduce`` reports both for every run.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from types import MappingProxyType
from typing import Any

from torch import nn

from leoc.evaluation.rollout import RESPONSE_STEPS
from leoc.learners import get_learner
from leoc.names import FRAMEWORKS
from leoc.pilco.config import authors_pilco_overrides
from leoc.sb3.config import authors_ddpg_overrides
from leoc.systems import StepRules, System, make_system
from leoc.systems.base import DEFAULT_RULES

__all__ = ["AUTHORS", "LEOC", "VARIANTS", "VARIANT_NAMES", "Variant", "get_variant"]

LEOC_LQR_METHOD = "discrete"
# nrjc/LEOC dao/envs/cartpole_env.py and mountaincar_env.py: ``reward -= 100`` on the step that
# leaves the track, the reward computed on the state after the step.
AUTHORS_EXIT_PENALTY = -100.0
# The cart-pole's impulse and step records in the paper (appendix D: settling 117 and 282 steps
# fit a 400-step record; the authors' Evaluator ran that many steps there).
AUTHORS_CARTPOLE_RESPONSE_STEPS = 400


@dataclasses.dataclass(frozen=True)
class Variant:
    """One implementation of LEOC's experiments (see the module table).

    Attributes
    ----------
    name : str
    description : str
        One line for reports.
    lqr_method : str
        ``method`` of :func:`leoc.control.design_lqr` for every linear part (the linear
        references and the hybrids' G).
    linear_saturation : str
        Saturation of the linear reference controllers (:func:`leoc.policies.lqr_controller`).
    step_rules : mapping of system name -> StepRules
        Rules of each system's steps; a system not listed steps under leoc's.
    response_steps : mapping of system name -> int
        Length of the impulse and step records; a system not listed gets 200.
    ddpg, sac, pilco : callable or None
        ``settings(system, hybrid, budget) -> dict`` of :class:`~leoc.sb3.DDPGConfig` (DDPG,
        SAC) or :class:`~leoc.pilco.PilcoConfig` fields this variant sets (None: none);
        ``budget`` is the run's training budget (DDPG/SAC steps, PILCO iterations) where a
        profile sets one, else None (the variant's own). The variant's ``lqr_method`` and step
        rules are added by :meth:`training_settings`.
    """

    name: str
    description: str
    lqr_method: str = "discrete"
    linear_saturation: str = "none"
    step_rules: Mapping[str, StepRules] = dataclasses.field(
        default_factory=lambda: MappingProxyType({})
    )
    response_steps: Mapping[str, int] = dataclasses.field(
        default_factory=lambda: MappingProxyType({})
    )
    ddpg: Callable[[str, bool, int | None], dict[str, Any]] | None = None
    pilco: Callable[[str, bool, int | None], dict[str, Any]] | None = None
    sac: Callable[[str, bool, int | None], dict[str, Any]] | None = None

    def training_settings(
        self, framework: str, system: str, hybrid: bool, budget: int | None = None
    ) -> dict[str, Any]:
        """Config fields of a ``framework`` (``leoc.names.FRAMEWORKS``) run under this variant:
        its framework settings, its LQR design (where it is not leoc's) and its step rules
        (where they are not leoc's), so that leoc's own configs stay as they were.

        ``budget`` (DDPG/SAC environment steps or PILCO iterations; None: the variant's or the
        config's own) is the run's training budget; it is set as ``total_steps`` or
        ``iterations`` and the variant's settings that depend on it follow it (the authors'
        PILCO model selection starts after half of the iterations)."""
        if framework not in FRAMEWORKS:
            raise ValueError(f"framework: expected one of {FRAMEWORKS}, found {framework!r}")
        if budget is not None and (isinstance(budget, bool) or int(budget) != budget or budget < 1):
            raise ValueError(f"budget: expected a positive integer or None, found {budget!r}")
        # a learner with no settings of its own takes another's (TD3 DDPG's: its settings_of)
        settings_of = {"ddpg": self.ddpg, "sac": self.sac, "pilco": self.pilco}[
            get_learner(framework).settings_of
        ]
        settings = dict(settings_of(system, hybrid, budget)) if settings_of is not None else {}
        if budget is not None:
            settings["iterations" if framework == "pilco" else "total_steps"] = int(budget)
        if self.lqr_method != LEOC_LQR_METHOD:
            settings["lqr_method"] = self.lqr_method
        rules = self.rules_for(system)
        if rules != DEFAULT_RULES:
            settings["step_rules"] = dataclasses.asdict(rules)
        return settings

    def rules_for(self, system: str) -> StepRules:
        """The step rules of the system called ``system``."""
        return self.step_rules.get(system, DEFAULT_RULES)

    def system(self, name: str) -> System:
        """The registered system ``name`` stepping under this variant's rules."""
        return make_system(name).with_rules(self.rules_for(name))

    def steps_for(self, system: str) -> int:
        """Impulse/step record length of ``system`` (simulator steps)."""
        return int(self.response_steps.get(system, RESPONSE_STEPS))

    def linear_controller(self, system: System, action_repeat: int = 1) -> nn.Module:
        """The linear reference controller of ``system`` at ``action_repeat``: this variant's
        LQR design and saturation."""
        from leoc.control import design_lqr
        from leoc.policies import lqr_controller

        design = design_lqr(system, method=self.lqr_method, action_repeat=action_repeat)  # type: ignore[arg-type]
        return lqr_controller(design, self.linear_saturation, system.action_limit)

    def summary(self) -> dict[str, object]:
        """JSON-friendly description (recorded in every run's meta data)."""
        return {
            "name": self.name,
            "description": self.description,
            "lqr_method": self.lqr_method,
            "linear_saturation": self.linear_saturation,
            "step_rules": {k: dataclasses.asdict(v) for k, v in self.step_rules.items()},
            "response_steps": dict(self.response_steps),
            "ddpg": None if self.ddpg is None else self.ddpg.__qualname__,
            "pilco": None if self.pilco is None else self.pilco.__qualname__,
            "sac": None if self.sac is None else self.sac.__qualname__,
        }


#: leoc's own choices (the default).
LEOC = Variant(
    "leoc",
    "leoc's defaults: discrete LQR on the exact step map, an exit that never pays",
)
#: The authors' choices (nrjc/LEOC), which the paper's numbers come from.
AUTHORS = Variant(
    "authors",
    "the authors' implementation (nrjc/LEOC): continuous LQR on their models scaled by u_max "
    "with a sin squash, a -100 exit, gym 0.17's pendulum",
    lqr_method="authors",
    linear_saturation="sin",
    step_rules=MappingProxyType(
        {
            "pendulum": StepRules(legacy_integrator=True),
            "cartpole": StepRules(exit_penalty=AUTHORS_EXIT_PENALTY, reward_on_next_state=True),
            "mountaincar": StepRules(exit_penalty=AUTHORS_EXIT_PENALTY, reward_on_next_state=True),
        }
    ),
    response_steps=MappingProxyType({"cartpole": AUTHORS_CARTPOLE_RESPONSE_STEPS}),
    ddpg=authors_ddpg_overrides,
    pilco=authors_pilco_overrides,
)
#: The variants by name (``--variant``).
VARIANTS: dict[str, Variant] = {variant.name: variant for variant in (LEOC, AUTHORS)}
#: Names of the variants.
VARIANT_NAMES = tuple(VARIANTS)


def get_variant(name: str | Variant) -> Variant:
    """The variant called ``name`` (a :class:`Variant` is returned as is)."""
    if isinstance(name, Variant):
        return name
    if name not in VARIANTS:
        raise ValueError(f"variant: expected one of {VARIANT_NAMES}, found {name!r}")
    return VARIANTS[name]
