"""Stable-Baselines3 integration: LEOC hybrid actor/policies for DDPG, TD3 and SAC, training glue.

Use the hybrid in plain SB3::

    from stable_baselines3 import DDPG
    from leoc.ddpg import HybridTD3Policy, hybrid_policy_kwargs
    model = DDPG(HybridTD3Policy, env, policy_kwargs=hybrid_policy_kwargs("pendulum"))

or train with leoc's settings (the paper's, and the choices that make DDPG learn) through
:func:`train_ddpg` (``leoc train SYSTEM --algo ddpg --hybrid``). SAC's hybrid is
:class:`HybridSACPolicy` (``SAC(HybridSACPolicy, env, policy_kwargs=...)``, or ``leoc train
SYSTEM --algo sac --hybrid``): its squashed mean is the same hybrid (:mod:`leoc.ddpg.sac`).
The authors' TF-Agents settings (nrjc/LEOC) are :data:`AUTHORS_DDPG` and
:func:`authors_ddpg_overrides`, overrides of :class:`DDPGConfig` fields.
"""

from leoc.ddpg.algorithms import LeocDDPG, LeocTD3
from leoc.ddpg.callbacks import HeldOutEvaluationCallback, LearningCurveCallback
from leoc.ddpg.config import (
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
from leoc.ddpg.noise import SeededOUNoise
from leoc.ddpg.physical import AffineOutput, PhysicalPolicy, physical_policy
from leoc.ddpg.policies import (
    HybridActor,
    HybridDDPGPolicy,
    HybridTD3Policy,
    LeocTD3Policy,
    SplitCritic,
    action_box,
    hybrid_policy_kwargs,
)
from leoc.ddpg.sac import HybridSACActor, HybridSACPolicy, LeocSAC, LeocSACPolicy, SquashedMean
from leoc.ddpg.train import (
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
    "PAPER_TOTAL_STEPS",
    "SAC_DEFAULTS",
    "STEP_RULES_BY_SYSTEM",
    "TOTAL_STEPS_BY_SYSTEM",
    "AffineOutput",
    "DDPGConfig",
    "DDPGResult",
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
    "SeededOUNoise",
    "SplitCritic",
    "SquashedMean",
    "action_box",
    "authors_ddpg_overrides",
    "build_model",
    "held_and_reached",
    "hybrid_policy_kwargs",
    "load_ddpg_controller",
    "load_ddpg_model",
    "physical_policy",
    "train_ddpg",
]
