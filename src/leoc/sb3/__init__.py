"""Stable-Baselines3 integration: the LEOC hybrid in SB3's DDPG, TD3 and SAC, and training glue.

One module per SB3 algorithm, each adapting SB3 only: :mod:`leoc.sb3.td3` (the hybrid actor
:class:`HybridActor`, :class:`LeocTD3Policy`, :class:`HybridTD3Policy`, :class:`LeocTD3`),
:mod:`leoc.sb3.ddpg` (:class:`LeocDDPG`; SB3's DDPG uses TD3's policies,
:class:`HybridDDPGPolicy` is :class:`HybridTD3Policy`) and :mod:`leoc.sb3.sac`
(:class:`HybridSACPolicy`, :class:`LeocSAC`), on what they share in :mod:`leoc.sb3.common`
(the blend, the network options, the paper's update settings). Beside them: the configuration
(:mod:`leoc.sb3.config`), training and loading (:mod:`leoc.sb3.train`), its callbacks,
checkpoints and exploration noise, and the float64 physical-units policy
(:mod:`leoc.sb3.physical`).

Use the hybrid in plain SB3::

    from stable_baselines3 import DDPG
    from leoc.sb3 import HybridTD3Policy, hybrid_policy_kwargs
    model = DDPG(HybridTD3Policy, env, policy_kwargs=hybrid_policy_kwargs("pendulum"))

or train with leoc's settings (the paper's, and the choices that make DDPG learn) through
:func:`train_ddpg` (``leoc train SYSTEM --algo ddpg --hybrid``). SAC's hybrid is
:class:`HybridSACPolicy` (``SAC(HybridSACPolicy, env, policy_kwargs=...)``, or ``leoc train
SYSTEM --algo sac --hybrid``): its squashed mean is the same hybrid (:mod:`leoc.sb3.sac`).
The authors' TF-Agents settings (nrjc/LEOC) are :data:`AUTHORS_DDPG` and
:func:`authors_ddpg_overrides`, overrides of :class:`DDPGConfig` fields.

A gymnasium environment is trained on itself, with no torch step function, by
:func:`train_gym` (:mod:`leoc.sb3.gym`; ``leoc train gym:InvertedPendulum-v5 --algo sac
--hybrid``): the LQR from the env's own step map, its gain written on the env's observation.

This package was ``leoc.ddpg`` until issue 39; :func:`load_ddpg_model` still loads the models
saved then.
"""

from leoc.sb3.callbacks import HeldOutEvaluationCallback, LearningCurveCallback
from leoc.sb3.common import SplitCritic, action_box, hybrid_policy_kwargs
from leoc.sb3.config import (
    ALGOS,
    AUTHORS_DDPG,
    EVAL_INTERVAL_BY_SYSTEM,
    PAPER_TOTAL_STEPS,
    SAC_DEFAULTS,
    STEP_RULES_BY_SYSTEM,
    TOTAL_STEPS_BY_SYSTEM,
    DDPGConfig,
    authors_ddpg_overrides,
)
from leoc.sb3.ddpg import HybridDDPGPolicy, LeocDDPG
from leoc.sb3.gym import (
    GYM_DEFAULTS,
    GymController,
    GymPlant,
    SampledRegion,
    gym_plant,
    load_gym_controller,
    sample_region,
    train_gym,
)
from leoc.sb3.noise import SeededOUNoise
from leoc.sb3.physical import AffineOutput, PhysicalPolicy, physical_policy
from leoc.sb3.sac import HybridSACActor, HybridSACPolicy, LeocSAC, LeocSACPolicy, SquashedMean
from leoc.sb3.td3 import HybridActor, HybridTD3Policy, LeocTD3, LeocTD3Policy
from leoc.sb3.train import (
    DDPGResult,
    build_model,
    held_and_reached,
    load_ddpg_controller,
    load_ddpg_model,
    train_ddpg,
)

__all__ = [
    "ALGOS",
    "AUTHORS_DDPG",
    "EVAL_INTERVAL_BY_SYSTEM",
    "GYM_DEFAULTS",
    "PAPER_TOTAL_STEPS",
    "SAC_DEFAULTS",
    "STEP_RULES_BY_SYSTEM",
    "TOTAL_STEPS_BY_SYSTEM",
    "AffineOutput",
    "DDPGConfig",
    "DDPGResult",
    "GymController",
    "GymPlant",
    "HeldOutEvaluationCallback",
    "HybridActor",
    "HybridDDPGPolicy",
    "HybridSACActor",
    "HybridSACPolicy",
    "HybridTD3Policy",
    "LearningCurveCallback",
    "LeocDDPG",
    "LeocSAC",
    "LeocSACPolicy",
    "LeocTD3",
    "LeocTD3Policy",
    "PhysicalPolicy",
    "SampledRegion",
    "SeededOUNoise",
    "SplitCritic",
    "SquashedMean",
    "action_box",
    "authors_ddpg_overrides",
    "build_model",
    "gym_plant",
    "held_and_reached",
    "hybrid_policy_kwargs",
    "load_ddpg_controller",
    "load_ddpg_model",
    "load_gym_controller",
    "physical_policy",
    "sample_region",
    "train_ddpg",
    "train_gym",
]
