r"""The DDPG ablation: which of the authors' DDPG choices decide whether DDPG learns a swing-up.

A grid of *settings* x controllers x systems x seeds (issue 20). Each setting is a set of
:class:`~leoc.sb3.DDPGConfig` overrides relative to leoc's defaults, derived from the one
place that holds the authors' values (:data:`~leoc.sb3.AUTHORS_DDPG`,
:func:`~leoc.sb3.authors_ddpg_overrides`, ``AUTHORS.rules_for``), never from numbers of its own:

===================  ==========================================================================
setting              DDPGConfig fields, relative to leoc's defaults
===================  ==========================================================================
``leoc``             none: leoc's defaults when the grid ran, written out as
                     :data:`LEOC_ABLATION_BASE` (every setting starts from them)
``authors``          the authors' full DDPG setup, :func:`~leoc.sb3.authors_ddpg_overrides`
                     (every field below, plus their precision relevance, unclipped actor
                     output and, on the cart-pole baseline, actor learning rate 1e-4), and all
                     their step rules (``AUTHORS.rules_for(system)``: the -100 exit and the
                     reward on the next state; the pendulum's gym 0.17 integrator)
``exploration``      OU noise in physical units, theta 0.2, sigma 1.0, never reset
                     (``noise_units``, ``ou_theta``, ``ou_sigma``, ``noise_reset``)
``initial_collect``  1000 steps from the noisy policy before the first update
                     (``warmup``, ``learning_starts``)
``critic``           Huber TD loss; critic obs -> 400 -> concat(physical action) -> 300;
                     TF-Agents' initialisation with last layers U(+/-0.003), for actor and
                     critic (``critic_loss``, ``critic_action_layer``, ``critic_action_units``,
                     ``hidden_init``, ``last_layer_init``)
``exit_penalty``     the authors' exit rule for that system: -100 once on leaving the track,
                     the reward of the next state (the ``exit_penalty`` and
                     ``reward_on_next_state`` fields of ``AUTHORS.rules_for(system)``); on the
                     pendulum, which has no track, they are leoc's, so the setting is left out
                     there (:func:`setting_applies`)
``model_selection``  the best evaluation of the last third on 3 episodes
                     (``model_selection``, ``eval_episodes``)
===================  ==========================================================================

The setting ``defaults`` (:data:`DEFAULTS_SETTING`, not in the default grid) is leoc's
defaults as the running code has them, no override: the choices issue 20 took from this grid
(``all_safe_exit`` with the ``best_held`` selection, and budgets of 21k steps on the cart-pole
and 20k on the mountain car, :mod:`leoc.sb3.config`). It measures those defaults in the same
harness, for DDPG, TD3 and SAC alike.

Where no single choice is enough, combinations decide which are needed
(:data:`COMBINED_SETTINGS`, not in the default grid): ``all_factors`` is leoc's defaults with
all five choices above switched on at once (unlike ``authors``, it keeps leoc's relevance,
clipped actor output, actor learning rate and the pendulum's integrator), and
``all_but_FACTOR`` is ``all_factors`` with one of them left at leoc's value.
``all_safe_exit`` splits the exit rule, the one factor leoc cannot adopt whole (the authors'
-100 exit pays, :class:`~leoc.systems.StepRules`): ``all_but_exit_penalty`` plus the rule's
other half, the reward of the next state, with leoc's exit that never pays. On a system
where the authors take the reward before the step (the pendulum) it equals
``all_but_exit_penalty`` and is left out.

Two more settings (:data:`HORIZON_EXIT_SETTINGS`) change the shape of leoc's exit, not its
size: ``horizon_exit`` is leoc's defaults with the exit charged for a whole episode whenever
it happens (``StepRules(horizon_exit=True)``: one reward per transition, where leoc's charges
the steps left, which the observation does not show; it still never pays), and
``all_horizon_exit`` is ``all_safe_exit`` with that exit. They apply where a system can leave
its region (the cart-pole and the mountain car).

SAC (:mod:`leoc.sb3.sac`) runs in the same harness, with the same held-out success test:
its controllers ``sac_baseline``, ``sac_hybrid`` and ``sac_hybrid_roa`` take the settings that
are not DDPG choices (:data:`SAC_SETTINGS`: leoc's defaults and the exit rule), so the grid
also measures SAC's success rate against the budget, and SAC's own settings
(:data:`SAC_TUNING_SETTINGS`, not in the default grid): ``defaults`` with SB3's critics, as
SAC's defaults were when they ran (``sac_sb3_critic``), and with one SAC choice changed (a
fixed entropy coefficient, 1000 initial steps from SAC's policy, DDPG's optimiser, the Huber
loss, DDPG's whole critic, DDPG's OU exploration on top of SAC's).

Every cell keeps leoc's discrete LQR for the hybrids' G (the LQR design is not a DDPG choice;
``leoc reproduce --variant authors`` runs the authors' design as well). Controllers: the DDPG
baseline, the hybrid with the paper's relevance and the hybrid with the ROA relevance; systems:
the cart-pole and the mountain car, with the pendulum as the control.

Success, and the controller it is measured on
---------------------------------------------
A run *succeeds at budget T* when the controller it would deliver had its budget been T
holds the operating point (:meth:`~leoc.systems.System.hold_step`) in every one of
:data:`TEST_EPISODES` held-out swing-up episodes. One run of budget :math:`T_{max}` gives
that for every evaluated budget :math:`T \le T_{max}`, honestly:

* SB3's DDPG with a constant learning rate does not depend on the total budget, so the first
  T steps of the long run *are* the run of budget T (a test checks it);
* the held-out episodes (:class:`~leoc.sb3.callbacks.HeldOutEvaluationCallback`) evaluate
  the actor at every evaluation step on starts seeded ``seed + 30000 + k``, on leoc's system
  (leoc's step rules, whatever rules the setting trains under: every cell faces the same
  test); they feed nothing back into training or selection;
* the delivered controller at T follows the setting's model selection
  (:func:`delivered_steps`): with ``"final"`` the actor at step T; with ``"best_last_third"``
  the actor of the best *selection* evaluation (the trainer's own ``eval_episodes`` episodes,
  under the setting's rules, as the run itself selects) after
  :func:`~leoc.sb3.callbacks.last_third_start` of T. Its held-out episodes then measure it
  without the optimism of having been chosen on them.

"The actor at step T" is the one the trainer's learning curve evaluates at step T (before
that step's gradient update; the saved ``model.zip`` has one update more). Beside it, each
cell also reports the optimistic *prefix* criterion of ``benchmarks/bench_ddpg_seeds.py``:
some held-out evaluation up to T held in every episode ("reached by T"), which counts a run
that learnt and then forgot.

Folder layout::

    OUT/plan.json                                     the plan (budgets, evaluation intervals,
                                                      held-out episodes, overrides), pinned by
                                                      the first invocation, and the last command
    OUT/runs/SYSTEM/CONTROLLER/SETTING/seedN/train/   train_ddpg's run folder
    OUT/runs/SYSTEM/CONTROLLER/SETTING/seedN/train.log   the run's progress lines
    OUT/runs/SYSTEM/CONTROLLER/SETTING/seedN/result.json written last, atomically: done
    OUT/pilco/                                        optional: PILCO hybrid run folders
                                                      (SYSTEM/CONTROLLER/seedN/train) that join
                                                      the relevance table
                                                      (leoc.experiments.relevance_report)

The sweep (:func:`leoc.experiments.sweep.sweep`) skips a run whose ``result.json`` exists, so
an interrupted grid continues where it stopped, locally or on a Ray cluster.
"""

from __future__ import annotations

import contextlib
import copy
import dataclasses
import json
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any, NamedTuple

from leoc import names
from leoc.experiments.layout import LOG_FILE
from leoc.experiments.sweep import SweepResult, check_backend, default_run_dir, sweep
from leoc.experiments.variants import AUTHORS
from leoc.io import read_json_object, write_json_atomic
from leoc.learners import ControllerSpec
from leoc.names import controller_framework
from leoc.policies.spec import HybridSpec
from leoc.sb3.callbacks import selection_key, selection_start
from leoc.sb3.config import (
    AUTHORS_DDPG,
    AUTHORS_EVAL_INTERVAL,
    DEFAULT_TOTAL_STEPS,
    MODEL_SELECTIONS,
    PAPER_TOTAL_STEPS,
    TOTAL_STEPS_BY_SYSTEM,
    DDPGConfig,
    authors_ddpg_overrides,
)
from leoc.systems.base import DEFAULT_RULES

#: The settings of the grid, in table order (see the module docstring).
SETTINGS = names.ABLATION_SETTINGS
#: The single-factor settings: one authors' choice each, on leoc's defaults.
FACTORS = ("exploration", "initial_collect", "critic", "exit_penalty", "model_selection")
#: The combined setting that keeps the exit rule's safe half only (the module docstring).
SAFE_EXIT_SETTING = "all_safe_exit"
#: Combinations of the factors: all of them, all but one (leave-one-out), and all with the
#: exit rule's safe half only (:data:`SAFE_EXIT_SETTING`).
COMBINED_SETTINGS = (
    "all_factors",
    *(f"all_but_{factor}" for factor in FACTORS),
    SAFE_EXIT_SETTING,
)
#: leoc's exit charged for a whole episode, alone and on ``all_safe_exit`` (module docstring).
HORIZON_EXIT_SETTINGS = ("horizon_exit", "all_horizon_exit")
#: leoc's defaults of the code that runs it (:meth:`~leoc.sb3.DDPGConfig.for_system`, no
#: override), for DDPG, TD3 and SAC alike: the setting that measures the defaults issue 20
#: chose from this grid (module docstring).
DEFAULTS_SETTING = "defaults"
#: SAC's settings (issue 20: with SB3's critics SAC did not learn the cart-pole), for the SAC
#: controllers only: each is leoc's defaults with SB3's critics (:data:`SB3_SAC_CRITIC`, SAC's
#: defaults when they were measured) and the fields given, and a label. ``sac_huber`` is what
#: SAC's defaults took: it equals ``defaults`` since.
SAC_TUNING_SETTINGS: dict[str, tuple[str, dict[str, Any]]] = {
    "sac_sb3_critic": ("SB3 critics (SAC's defaults before issue 20)", {}),
    "sac_alpha_0.1": ("SB3 critics, entropy coefficient 0.1 (fixed)", {"sac_entropy_coef": 0.1}),
    "sac_alpha_0.01": ("SB3 critics, entropy coefficient 0.01 (fixed)", {"sac_entropy_coef": 0.01}),
    "sac_initial_collect": (
        "SB3 critics, 1000 initial steps from SAC's policy",
        {"learning_starts": 1000, "warmup": "policy"},
    ),
    "sac_ddpg_optimiser": (
        "SB3 critics, DDPG's optimiser (batch 64, actor step 5e-4, targets 0.05 every 5)",
        {
            "batch_size": 64,
            "actor_learning_rate": 5e-4,
            "polyak": 0.05,
            "target_update_interval": 5,
        },
    ),
    "sac_huber": ("SB3 critics with the Huber TD loss", {"critic_loss": "huber"}),
    "sac_critic": (
        "DDPG's critic (Huber, action after layer 1, TF-Agents' init)",
        {
            "critic_loss": "huber",
            "critic_action_layer": 1,
            "critic_action_units": "physical",
            "hidden_init": "tf_agents",
            "last_layer_init": 0.003,
        },
    ),
    "sac_ou": (
        "SB3 critics, DDPG's OU noise added to SAC's samples",
        {"sac_action_noise": True},
    ),
}
#: The paper relevance's fields as leoc's defaults had them when issue 40's ablation ran
#: (:math:`r = (1 + d)^{-2}`, no floor), written out: every setting measured from those
#: defaults keeps them now that the defaults floor :math:`\Lambda` and square :math:`d`.
PAPER_RELEVANCE_BASE: dict[str, Any] = {"r_min": None, "relevance_power": 1.0}
#: How the paper's relevance is learned (issue 40), one choice switched from leoc's defaults as
#: they were when it ran (:data:`PAPER_RELEVANCE_BASE` on the running code's other defaults,
#: so a cell differs from ``relevance_paper`` in that choice only), for the hybrids with the
#: paper's relevance of DDPG, TD3 and SAC: name -> (label, :class:`~leoc.policies.HybridSpec`
#: fields). ``relevance_power_2_floor_0.5`` is what leoc's defaults took from it.
RELEVANCE_SETTINGS: dict[str, tuple[str, dict[str, Any]]] = {
    "relevance_paper": (
        "the paper's r = (1 + d)^-2, Lambda learned (leoc's defaults before issue 40)",
        {},
    ),
    "relevance_precision": (
        "authors' precision parametrisation (S = Lambda^-1, unconstrained)",
        {"relevance_parametrisation": "precision"},
    ),
    "relevance_frozen": ("Lambda frozen at its initial 1", {"learn_lambda": False}),
    "relevance_init_10": ("initial Lambda 10 (learned)", {"lambda_init": 10.0}),
    "relevance_lr_0.1": ("Lambda's learning rate 0.1 x the actor's", {"relevance_lr_scale": 0.1}),
    "relevance_lr_0.01": (
        "Lambda's learning rate 0.01 x the actor's",
        {"relevance_lr_scale": 0.01},
    ),
    "relevance_floor_0.99": (
        "Lambda floored: r >= 0.99 on the LQR's proved set",
        {"r_min": 0.99},
    ),
    "relevance_floor_0.9": ("Lambda floored: r >= 0.9 on the LQR's proved set", {"r_min": 0.9}),
    "relevance_floor_0.5": ("Lambda floored: r >= 0.5 on the LQR's proved set", {"r_min": 0.5}),
    "relevance_lyapunov": (
        "distance = LQR's Lyapunov function V / (lambda rho), lambda learned",
        {"relevance": "lyapunov"},
    ),
    "relevance_power_2": ("r = (1 + d^2)^-2 (Lambda learned, no floor)", {"relevance_power": 2.0}),
    "relevance_power_2_floor_0.5": (
        "r = (1 + d^2)^-2, Lambda floored: r >= 0.5 on the LQR's proved set (leoc's defaults)",
        {"relevance_power": 2.0, "r_min": 0.5},
    ),
    "relevance_power_2_floor_0.9": (
        "r = (1 + d^2)^-2, Lambda floored: r >= 0.9 on the LQR's proved set",
        {"relevance_power": 2.0, "r_min": 0.9},
    ),
}
#: Every setting the harness runs: the default grid's, the combinations, the exit shapes,
#: today's defaults, SAC's settings and the relevance's.
ALL_SETTINGS = (
    SETTINGS
    + COMBINED_SETTINGS
    + HORIZON_EXIT_SETTINGS
    + (DEFAULTS_SETTING,)
    + tuple(SAC_TUNING_SETTINGS)
    + tuple(RELEVANCE_SETTINGS)
)
#: The authors' DDPG fields each single-factor setting switches on (values: ``AUTHORS_DDPG``).
SINGLE_FACTOR_FIELDS: dict[str, tuple[str, ...]] = {
    "exploration": ("noise_units", "ou_theta", "ou_sigma", "noise_reset"),
    "initial_collect": ("warmup", "learning_starts"),
    "critic": (
        "critic_loss",
        "critic_action_layer",
        "critic_action_units",
        "hidden_init",
        "last_layer_init",
    ),
    "model_selection": ("model_selection", "eval_episodes"),
}
#: leoc's DDPG defaults, as they were when the ablation ran, of every field its settings
#: switch (written out, not read from :class:`~leoc.sb3.DDPGConfig`): ``leoc`` is these
#: values and every other setting starts from them, so the published grid stays what this
#: code runs when leoc's defaults change (issue 20 chooses new ones from this grid).
LEOC_ABLATION_BASE: dict[str, Any] = {
    "noise_units": "normalised",
    "ou_theta": 0.15,
    "ou_sigma": 0.2,
    "noise_reset": True,
    "warmup": "uniform",
    "learning_starts": 200,
    "critic_loss": "mse",
    "critic_action_layer": 0,
    "critic_action_units": "normalised",
    "hidden_init": "torch",
    "last_layer_init": None,
    "relevance_parametrisation": "log_lambda",
    "lambda_init": 1.0,
    "learn_lambda": True,
    **PAPER_RELEVANCE_BASE,
    "actor_output_clip": True,
    "model_selection": "final",
    "eval_episodes": 5,
    "actor_learning_rate": 5e-4,
    "critic_learning_rate": 1e-3,
    "discount": 0.995,
    "polyak": 0.05,
    "target_update_interval": 5,
    "buffer_size": 100_000,
    "batch_size": 64,
    "actor_hidden": (400, 300),
    "critic_hidden": (400, 300),
    "train_freq": 1,
    "gradient_steps": 1,
    "step_rules": {},
}
#: SAC's critics before issue 20 (SB3's: mean squared TD error, the action at the input in
#: normalised units, PyTorch's initialisation), written out: SAC's defaults took the Huber loss
#: from the SAC settings below, which start from these.
SB3_SAC_CRITIC: dict[str, Any] = {
    "critic_loss": "mse",
    "critic_action_layer": 0,
    "critic_action_units": "normalised",
    "hidden_init": "torch",
    "last_layer_init": None,
}
#: SAC's defaults before issue 20 of the fields that changed since, for the SAC cells of the
#: settings other than ``defaults`` and :data:`SAC_TUNING_SETTINGS`: leoc's step rules, the
#: final actor on 5 evaluation episodes and SB3's critics (SAC's other hyperparameters,
#: :data:`~leoc.sb3.SAC_DEFAULTS`, did not change).
SAC_ABLATION_BASE: dict[str, Any] = {
    **PAPER_RELEVANCE_BASE,
    "step_rules": {},
    "model_selection": "final",
    "eval_episodes": 5,
    **SB3_SAC_CRITIC,
}
#: The :class:`~leoc.systems.StepRules` fields of the ``exit_penalty`` setting.
EXIT_RULE_FIELDS = ("exit_penalty", "reward_on_next_state")
#: One line per setting, for tables and figure legends.
SETTING_LABELS = {
    "leoc": "leoc's defaults",
    "authors": "authors' full setup",
    "exploration": "+ authors' OU exploration",
    "initial_collect": "+ 1000 initial noisy steps",
    "critic": "+ Huber, critic shape, TF-Agents init",
    "exit_penalty": "+ authors' exit rule",
    "model_selection": "+ best of last third",
    "all_factors": "+ all five choices",
    **{f"all_but_{factor}": f"+ all five but {factor.replace('_', ' ')}" for factor in FACTORS},
    SAFE_EXIT_SETTING: "+ all five, exit that never pays (reward on next state)",
    "horizon_exit": "+ exit charged for a whole episode",
    "all_horizon_exit": "+ all five, exit charged for a whole episode (reward on next state)",
    DEFAULTS_SETTING: "leoc's defaults since issue 20",
    **{name: label for name, (label, _) in SAC_TUNING_SETTINGS.items()},
    **{name: label for name, (label, _) in RELEVANCE_SETTINGS.items()},
}
#: The DDPG controllers of the grid (``leoc reproduce`` names).
ABLATION_CONTROLLERS = names.ABLATION_CONTROLLERS
#: The SAC controllers the harness also runs (not in the default grid).
SAC_CONTROLLERS = names.ABLATION_SAC_CONTROLLERS
#: The TD3 controllers the harness also runs (not in the default grid).
TD3_CONTROLLERS = names.ABLATION_TD3_CONTROLLERS
#: Every controller the harness runs, in table order.
GRID_CONTROLLERS = ABLATION_CONTROLLERS + SAC_CONTROLLERS + TD3_CONTROLLERS
#: The settings that apply to SAC: the others switch DDPG/TD3 fields SAC does not have.
SAC_SETTINGS = (
    "leoc",
    "exit_penalty",
    DEFAULTS_SETTING,
    *SAC_TUNING_SETTINGS,
    *RELEVANCE_SETTINGS,
)
#: The settings that apply to TD3: today's defaults and the relevance's (the DDPG settings
#: describe the DDPG defaults of issue 20, which TD3 never had).
TD3_SETTINGS = (DEFAULTS_SETTING, *RELEVANCE_SETTINGS)
#: The systems of the grid: the two that fail, then the pendulum as the control.
ABLATION_SYSTEMS = names.ABLATION_SYSTEM_NAMES
#: Seeds per setting when none are given: 5 for leoc's defaults and the authors' setup.
FULL_SEEDS = 5
#: Seeds per single-factor setting when none are given (add more where a cell is undecided).
SINGLE_FACTOR_SEEDS = 3
#: Held-out swing-up episodes of the success test.
TEST_EPISODES = names.ABLATION_TEST_EPISODES
#: Seed offset of the held-out starts (evaluation: 10000, exploration noise: 20000).
TEST_SEED_OFFSET = 30_000
#: Name of a run's result, written last (its presence marks the run done).
RESULT_FILE = "result.json"
#: The plan pinned by the first invocation on a folder.
PLAN_FILE = "plan.json"
#: Subfolder of a run folder holding :func:`~leoc.sb3.train_ddpg`'s files.
TRAIN_DIR = "train"
# Wall time of one run [s] per 1000 steps, from results/paper's DDPG runs (leoc.experiments.
# profiles.PAPER_RUN_SECONDS over the paper's budgets); the ETA's prior before runs finish.
FALLBACK_SECONDS_PER_KSTEP = 12.0
#: SAC's wall time over DDPG's on the same run, for the ETA (``python benchmarks/bench_sac.py``:
#: 30.1 s against 11.1 s for 1000 steps of the pendulum hybrids; batch 256 against 100).
SAC_COST_FACTOR = 2.7
# Decimals of the held-out returns in a record (they are reported, not tested on).
RETURN_DECIMALS = 3
#: Evaluation interval of a system the authors did not run (environment steps).
DEFAULT_INTERVAL = 500
#: Fields a run's identity fixes: the plan's overrides may not set them.
PLAN_FIELDS = ("system", "algo", "hybrid", "relevance", "total_steps", "eval_interval")


# ----------------------------------------------------------------------------------- settings
def setting_overrides(
    setting: str, system: str, hybrid: bool, budget: int | None = None, algo: str = "ddpg"
) -> dict[str, Any]:
    """The :class:`~leoc.sb3.DDPGConfig` overrides of ``setting`` on ``system``:
    :data:`LEOC_ABLATION_BASE` with what the setting switches (see the module table).

    Parameters
    ----------
    setting : str
        One of :data:`ALL_SETTINGS`.
    system : str
        System name.
    hybrid : bool
        Whether the run trains a hybrid (the authors' cart-pole baseline has its own actor
        learning rate).
    budget : int, optional
        The run's environment steps (the authors' setup sets ``total_steps`` to it).
    algo : {"ddpg", "td3", "sac"}
        The learner: SAC keeps its own defaults (:data:`~leoc.sb3.SAC_DEFAULTS`) and
        takes :data:`SAC_ABLATION_BASE` as its base.

    Returns
    -------
    dict
        A fresh dict; :data:`LEOC_ABLATION_BASE` itself for ``leoc`` and for a setting that
        changes nothing on ``system`` (:data:`SAC_ABLATION_BASE` for SAC); empty for
        ``defaults``, which runs :meth:`~leoc.sb3.DDPGConfig.for_system` as it is.
    """
    if setting not in ALL_SETTINGS:
        raise ValueError(f"setting: expected one of {ALL_SETTINGS}, found {setting!r}")
    if setting == DEFAULTS_SETTING:
        return {}
    if setting in RELEVANCE_SETTINGS:
        return {**PAPER_RELEVANCE_BASE, **copy.deepcopy(RELEVANCE_SETTINGS[setting][1])}
    if setting in SAC_TUNING_SETTINGS:
        return {
            **SB3_SAC_CRITIC,
            **PAPER_RELEVANCE_BASE,
            **copy.deepcopy(SAC_TUNING_SETTINGS[setting][1]),
        }
    base = LEOC_ABLATION_BASE if algo != "sac" else SAC_ABLATION_BASE
    return {**copy.deepcopy(base), **_switched(setting, system, hybrid, budget)}


def _switched(setting: str, system: str, hybrid: bool, budget: int | None) -> dict[str, Any]:
    """What ``setting`` changes on :data:`LEOC_ABLATION_BASE` (see :func:`setting_overrides`)."""
    if setting == "leoc":
        return {}
    if setting in HORIZON_EXIT_SETTINGS:
        base = SAFE_EXIT_SETTING if setting == "all_horizon_exit" else "leoc"
        overrides = setting_overrides(base, system, hybrid, budget)
        overrides["step_rules"] = {**overrides.get("step_rules", {}), "horizon_exit": True}
        return overrides
    if setting == SAFE_EXIT_SETTING:
        overrides = setting_overrides("all_but_exit_penalty", system, hybrid, budget)
        exit_rules = setting_overrides("exit_penalty", system, hybrid, budget).get("step_rules", {})
        if "reward_on_next_state" in exit_rules:
            overrides["step_rules"] = {"reward_on_next_state": exit_rules["reward_on_next_state"]}
        return overrides
    if setting in COMBINED_SETTINGS:
        left_out = setting.removeprefix("all_but_") if setting != "all_factors" else None
        overrides: dict[str, Any] = {}
        for factor in FACTORS:
            if factor != left_out:
                overrides.update(_switched(factor, system, hybrid, budget))
        return overrides
    if setting == "authors":
        overrides = authors_ddpg_overrides(system, hybrid, budget)
        rules = AUTHORS.rules_for(system)
        if rules != DEFAULT_RULES:
            overrides["step_rules"] = dataclasses.asdict(rules)
        return overrides
    if setting == "exit_penalty":
        rules = AUTHORS.rules_for(system)
        changed = {
            name: getattr(rules, name)
            for name in EXIT_RULE_FIELDS
            if getattr(rules, name) != getattr(DEFAULT_RULES, name)
        }
        return {"step_rules": changed} if changed else {}
    return {name: AUTHORS_DDPG[name] for name in SINGLE_FACTOR_FIELDS[setting]}


def setting_applies(setting: str, system: str, controller: str = "ddpg_baseline") -> bool:
    """Whether ``setting`` differs from leoc's defaults on ``system`` (``leoc`` and
    ``defaults`` always apply) and exists for ``controller``'s algorithm (SAC:
    :data:`SAC_SETTINGS`); a setting that does not is left out of the grid there."""
    framework = controller_framework(controller)
    if (framework == "sac" and setting not in SAC_SETTINGS) or (
        framework == "td3" and setting not in TD3_SETTINGS
    ):
        return False
    if setting in RELEVANCE_SETTINGS:  # the paper relevance's hybrids only
        return names.parse_controller(controller).relevance == "paper"
    if setting in SAC_TUNING_SETTINGS:  # SAC's settings: not DDPG settings
        return controller_framework(controller) == "sac"
    if setting.startswith("all_but_"):  # a copy of all_factors where the factor changes nothing
        return setting_applies(setting.removeprefix("all_but_"), system, controller)
    if setting == DEFAULTS_SETTING:
        return True
    if setting == SAFE_EXIT_SETTING:  # a copy of all_but_exit_penalty where no rule changes
        return bool(setting_overrides(setting, system, hybrid=False)["step_rules"])
    if setting in HORIZON_EXIT_SETTINGS:  # a copy of leoc / all_safe_exit with no exit
        from leoc.systems import make_system

        return make_system(system).can_leave()
    return setting == "leoc" or bool(_switched(setting, system, False, None))


def default_seeds(setting: str) -> tuple[int, ...]:
    """Seeds of ``setting`` when none are given: ``0 .. 4`` for ``leoc``, ``authors`` and
    ``defaults``, ``0 .. 2`` for a single-factor or combined setting."""
    count = FULL_SEEDS if setting in ("leoc", "authors", DEFAULTS_SETTING) else SINGLE_FACTOR_SEEDS
    return tuple(range(count))


class AblationSpec(NamedTuple):
    """One run of the grid: a controller of a system, under a setting, for one seed."""

    system: str
    controller: str
    setting: str
    seed: int

    @property
    def key(self) -> str:
        """Run folder path ``SYSTEM/CONTROLLER/SETTING/seedN`` under ``OUT/runs``."""
        return f"{self.system}/{self.controller}/{self.setting}/seed{self.seed}"

    @property
    def controller_spec(self) -> ControllerSpec:
        """What the run trains (:class:`~leoc.learners.ControllerSpec`, read from its name)."""
        return ControllerSpec.from_name(self.controller)

    @property
    def algo(self) -> str:
        """The learner: ``"ddpg"``, ``"td3"`` or ``"sac"``."""
        return controller_framework(self.controller)

    @property
    def hybrid(self) -> bool:
        """Whether the controller is a hybrid."""
        return self.controller_spec.hybrid is not None


def grid_specs(
    systems: Sequence[str] = ABLATION_SYSTEMS,
    controllers: Sequence[str] = ABLATION_CONTROLLERS,
    settings: Sequence[str] = SETTINGS,
    seeds: Sequence[int] | None = None,
) -> list[AblationSpec]:
    """The runs of a grid, the costliest system first (cart-pole), settings in table order.

    Parameters
    ----------
    systems, controllers, settings : sequence of str
        Subsets of :data:`ABLATION_SYSTEMS` (or any registered system),
        :data:`GRID_CONTROLLERS` and :data:`ALL_SETTINGS` (default: the grid's
        :data:`SETTINGS`).
    seeds : sequence of int, optional
        The seeds of every setting; default :func:`default_seeds` per setting.

    Returns
    -------
    list of AblationSpec
        Without the settings that do not apply to a system or a controller's algorithm
        (:func:`setting_applies`).
    """
    from leoc.systems import system_names

    known = system_names()
    for name, values, allowed in (
        ("systems", systems, known),
        ("controllers", controllers, GRID_CONTROLLERS),
        ("settings", settings, ALL_SETTINGS),
    ):
        unknown = [value for value in values if value not in allowed]
        if unknown:
            raise ValueError(f"{name}: unknown {unknown}; expected some of {tuple(allowed)}")
    if seeds is not None and any(int(seed) != seed or seed < 0 for seed in seeds):
        raise ValueError(f"seeds: expected non-negative integers, found {list(seeds)}")
    ordered = sorted(systems, key=lambda name: -PAPER_TOTAL_STEPS.get(name, 0))
    return [
        AblationSpec(system, controller, setting, int(seed))
        for system in ordered
        for setting in settings
        for controller in controllers
        if setting_applies(setting, system, controller)
        for seed in (default_seeds(setting) if seeds is None else seeds)
    ]


# --------------------------------------------------------------------------------------- plan
def _json_form(value: Any) -> Any:
    """``value`` as JSON reads it back (tuples become lists), for comparisons."""
    return json.loads(json.dumps(value))


@dataclasses.dataclass(frozen=True)
class AblationPlan:
    """What every run of one ablation folder shares.

    Attributes
    ----------
    budgets : mapping system -> int
        Environment steps of each run (default: the paper's, 10k / 15k / 10k); a budget is a
        multiple of the evaluation interval, so that it is an evaluated step.
    eval_intervals : mapping system -> int
        Environment steps between evaluations (default: the authors', 200 / 300 / 200, which
        the ``model_selection`` setting selects among); every evaluated step is a budget of
        the success table.
    test_episodes : int
        Held-out swing-up episodes per evaluation (:data:`TEST_EPISODES`).
    overrides : mapping
        :class:`~leoc.sb3.DDPGConfig` fields set in every cell (e.g. small networks for a
        smoke run); none may be a field that a setting switches or that
        :data:`PLAN_FIELDS` names.
    """

    budgets: Mapping[str, int] = dataclasses.field(default_factory=dict)
    eval_intervals: Mapping[str, int] = dataclasses.field(default_factory=dict)
    test_episodes: int = TEST_EPISODES
    overrides: Mapping[str, Any] = dataclasses.field(default_factory=dict)

    def __post_init__(self) -> None:
        for name, values in (("budgets", self.budgets), ("eval_intervals", self.eval_intervals)):
            for system, value in values.items():
                if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                    raise ValueError(
                        f"{name}: expected positive integers, found {system}={value!r}"
                    )
        episodes = self.test_episodes
        if isinstance(episodes, bool) or not isinstance(episodes, int) or episodes < 1:
            raise ValueError(f"test_episodes: expected a positive integer, found {episodes!r}")
        clash = sorted(set(self.overrides) & (set(PLAN_FIELDS) | switched_fields()))
        if clash:
            raise ValueError(
                f"overrides: {clash} are set by the grid (a setting switches them, or they fix "
                "the run); override other DDPGConfig fields only"
            )
        for system in set(self.budgets) | set(self.eval_intervals):
            budget, interval = self.budget_for(system), self.eval_interval_for(system)
            if budget % interval:
                raise ValueError(
                    f"budgets: expected a multiple of the evaluation interval on {system} "
                    f"({interval}), found {budget}"
                )

    def budget_for(self, system: str) -> int:
        """Environment steps of a run on ``system``."""
        return int(self.budgets.get(system, PAPER_TOTAL_STEPS.get(system, DEFAULT_TOTAL_STEPS)))

    def eval_interval_for(self, system: str) -> int:
        """Environment steps between two evaluations on ``system``."""
        return int(
            self.eval_intervals.get(system, AUTHORS_EVAL_INTERVAL.get(system, DEFAULT_INTERVAL))
        )

    def config_overrides(self, spec: AblationSpec) -> dict[str, Any]:
        """Keyword overrides of ``spec``'s :class:`~leoc.sb3.DDPGConfig` (for
        :func:`~leoc.sb3.train_ddpg`): the setting's, then the plan's."""
        budget = self.budget_for(spec.system)
        return {
            **setting_overrides(spec.setting, spec.system, spec.hybrid, budget, spec.algo),
            "total_steps": budget,
            "eval_interval": self.eval_interval_for(spec.system),
            **self.overrides,
        }

    def config(self, spec: AblationSpec) -> DDPGConfig:
        """The :class:`~leoc.sb3.DDPGConfig` of ``spec``."""
        overrides = self.config_overrides(spec)
        hybrid = spec.controller_spec.hybrid
        return DDPGConfig.for_system(spec.system, spec.algo, hybrid=hybrid, **overrides)

    def pinned(self, systems: Sequence[str]) -> dict[str, Any]:
        """JSON form of the plan for ``systems`` (what a folder's :data:`PLAN_FILE` pins)."""
        return _json_form(
            {
                "budgets": {name: self.budget_for(name) for name in systems},
                "eval_intervals": {name: self.eval_interval_for(name) for name in systems},
                "test_episodes": self.test_episodes,
                "overrides": dict(self.overrides),
            }
        )


def switched_fields() -> set[str]:
    """Every :class:`~leoc.sb3.DDPGConfig` field some setting sets to a value other than
    leoc's default, on some system of :data:`ABLATION_SYSTEMS` and controller."""
    fields = {"step_rules"}
    for system in ABLATION_SYSTEMS:
        for hybrid in (False, True):
            # the hybrid's fields (HybridSpec) at their defaults beside the config's own
            defaults = {**HybridSpec().to_dict(), **DDPGConfig.for_system(system).as_dict()}
            for setting in ALL_SETTINGS:
                for name, value in setting_overrides(setting, system, hybrid).items():
                    if _json_form(value) != _json_form(defaults[name]):
                        fields.add(name)
    return fields - {"total_steps", "eval_interval"}


def merge_plan(stored: Mapping[str, Any], plan: AblationPlan, systems: Sequence[str]) -> dict:
    """The folder's pinned plan extended by ``plan`` for ``systems``; raises if they differ.

    Parameters
    ----------
    stored : mapping
        The folder's pinned plan (:meth:`AblationPlan.pinned`; empty for a new folder).
    plan : AblationPlan
    systems : sequence of str

    Returns
    -------
    dict
        The pinned plan to write back.

    Raises
    ------
    ValueError
        When ``plan`` gives a system another budget or evaluation interval than the folder's
        runs have, or other held-out episodes or overrides: its runs would not be comparable.
    """
    new = plan.pinned(systems)
    merged = _json_form(dict(stored)) if stored else {**new, "budgets": {}, "eval_intervals": {}}
    for name in ("test_episodes", "overrides"):
        if merged.get(name) != new[name]:
            raise ValueError(
                f"out: the folder's runs have {name} {merged.get(name)!r}, this invocation "
                f"{new[name]!r}; use another folder"
            )
    for name in ("budgets", "eval_intervals"):
        for system, value in new[name].items():
            found = merged[name].setdefault(system, value)
            if found != value:
                raise ValueError(
                    f"out: the folder's {system} runs have {name} {found}, this invocation "
                    f"{value}; use another folder"
                )
    return merged


# ----------------------------------------------------------------------------------- one run
def held_out_starts(system: Any, seed: int, episodes: int) -> Any:
    """``(episodes, S)`` held-out swing-up starts of the run seeded ``seed``:
    ``System.sample_start(default_rng(seed + 30000 + k))``, disjoint from the trainer's
    evaluation starts (``seed + 10000 + k``)."""
    import numpy as np

    return np.stack(
        [
            system.sample_start(np.random.default_rng(seed + TEST_SEED_OFFSET + k), "swing_up")
            for k in range(episodes)
        ]
    )


def _evaluations(curve: Sequence[Mapping[str, Any]], held_out: Sequence[Mapping[str, Any]]):
    """The trainer's evaluations joined with the held-out ones, step by step."""
    steps = [int(row["steps"]) for row in curve]
    if steps != [int(row["steps"]) for row in held_out]:
        raise RuntimeError(
            f"held-out evaluations at steps {[row['steps'] for row in held_out]} do not match "
            f"the learning curve's {steps}"
        )
    return [
        {
            "steps": int(row["steps"]),
            "selection_return": float(row["mean_return"]),
            "selection_held_fraction": float(row["held_fraction"]),
            "test_returns": [round(float(value), RETURN_DECIMALS) for value in test["returns"]],
            "test_hold_steps": list(test["hold_steps"]),
        }
        for row, test in zip(curve, held_out, strict=True)
    ]


def run_cell(spec: AblationSpec, plan: AblationPlan, out_dir: Path) -> dict[str, Any]:
    """Train one run of the grid and return its record (the sweep writes it to
    :data:`RESULT_FILE`).

    Trains with :func:`~leoc.sb3.train_ddpg` into ``RUN/train`` (progress lines to
    ``RUN/train.log``), a :class:`~leoc.sb3.callbacks.HeldOutEvaluationCallback` on leoc's
    system testing at the trainer's evaluation steps.

    Returns
    -------
    dict
        ``key``, ``system``, ``controller``, ``setting``, ``seed``, ``budget``,
        ``eval_interval``, ``learning_starts``, ``model_selection``, ``test_episodes``,
        ``config`` (the DDPGConfig), ``evaluations`` (per step: ``selection_return``,
        ``selection_held_fraction``, ``test_returns``, ``test_hold_steps``),
        ``selected_steps`` (the trainer's own choice at the full budget), wall seconds and
        library versions.
    """
    import torch

    from leoc.experiments.reproduce import WORKER_THREADS, versions
    from leoc.sb3.callbacks import HeldOutEvaluationCallback
    from leoc.sb3.train import train_ddpg
    from leoc.systems import make_system

    run_dir = default_run_dir(out_dir, spec)
    run_dir.mkdir(parents=True, exist_ok=True)
    torch.set_num_threads(WORKER_THREADS)
    config = plan.config(spec)
    test_system = make_system(spec.system)  # leoc's rules: the same test for every setting
    starts = held_out_starts(test_system, spec.seed, plan.test_episodes)
    held_out = HeldOutEvaluationCallback(test_system, starts, config.eval_interval)
    started = time.perf_counter()
    with (
        open(run_dir / LOG_FILE, "a", buffering=1) as log,
        contextlib.redirect_stdout(log),
        contextlib.redirect_stderr(log),
    ):
        print(f"== {spec.key}: {config.total_steps} steps", flush=True)
        result = train_ddpg(
            spec.system,
            spec.algo,
            hybrid=spec.controller_spec.hybrid,
            seed=spec.seed,
            run_dir=run_dir / TRAIN_DIR,
            progress="lines",
            callbacks=[held_out],
            **plan.config_overrides(spec),
        )
        print(f"trained in {time.perf_counter() - started:.1f} s", flush=True)
    record = _record(spec, plan, config, _evaluations(result.curve, held_out.rows))
    return {
        **record,
        "lqr_agreement": delivered_lqr_agreement(run_dir, test_system, spec.hybrid),
        "selected_steps": result.summary.get("selected_steps"),
        "wall_seconds": time.perf_counter() - started,
        "versions": versions(),
    }


def delivered_lqr_agreement(run_dir: Path, system: Any, hybrid: bool) -> dict[str, Any] | None:
    """:func:`~leoc.evaluation.lqr_agreement.lqr_agreement` of the controller the run delivers
    at its full budget (the trainer's saved model) against the LQR designed for its control
    period, on ``system``; None for a baseline."""
    if not hybrid:
        return None
    from leoc.evaluation.lqr_agreement import lqr_agreement
    from leoc.experiments.controllers import load_trained_controller

    return lqr_agreement(system, load_trained_controller(run_dir / TRAIN_DIR))


def _record(
    spec: AblationSpec, plan: AblationPlan, config: DDPGConfig, evaluations: list[dict]
) -> dict[str, Any]:
    """The part of a run's record (:func:`run_cell`) that its spec, plan and evaluations fix."""
    return {
        **spec._asdict(),
        "key": spec.key,
        "budget": config.total_steps,
        "eval_interval": config.eval_interval,
        "learning_starts": config.learning_starts,
        "model_selection": config.model_selection,
        "test_episodes": plan.test_episodes,
        "config": config.as_dict(),
        "evaluations": evaluations,
    }


@dataclasses.dataclass(frozen=True)
class AblationRunner:
    """The sweep's unit of work: ``runner(spec, out_dir)`` calls :func:`run_cell` with the
    plan (a picklable callable for worker processes and Ray tasks).

    Attributes
    ----------
    plan : AblationPlan
    """

    plan: AblationPlan

    def __call__(self, spec: AblationSpec, out_dir: Path) -> dict[str, Any]:
        return run_cell(spec, self.plan, Path(out_dir))


# ------------------------------------------------------------------------ success at a budget
class RunOutcome(NamedTuple):
    """What one run gives at one budget T.

    Attributes
    ----------
    delivered_steps : int
        Step of the evaluation whose actor the run delivers at T (:func:`delivered_steps`).
    success : bool
        The delivered actor held the operating point in every held-out episode.
    reached : bool
        Some held-out evaluation at a step <= T held in every episode (the optimistic prefix
        criterion).
    """

    delivered_steps: int
    success: bool
    reached: bool


def delivered_steps(
    steps: Sequence[int],
    selection_returns: Sequence[float],
    budget: int,
    model_selection: str,
    learning_starts: int,
    held_fractions: Sequence[float] | None = None,
) -> int:
    """Step of the evaluation whose actor a run of budget ``budget`` delivers.

    ``"final"``: ``budget`` itself. ``"best_last_third"``: among the evaluations at steps
    ``s`` with :func:`~leoc.sb3.callbacks.last_third_start` ``(budget, learning_starts) < s
    <= budget``, the one with the strictly highest selection return (the earliest on ties), as
    :class:`~leoc.sb3.LearningCurveCallback` selects; ``budget`` when the window holds none.
    ``"best_held"``: among all evaluations up to ``budget``, the one whose selection episodes
    held in the largest share, the highest selection return among those (the earliest on
    ties); :func:`~leoc.sb3.callbacks.selection_key` is the rule of both.

    Parameters
    ----------
    steps : sequence of int
        Evaluation steps of the run, increasing; ``budget`` must be one of them.
    selection_returns : sequence of float
        Mean return of the trainer's evaluation at each step (what the run selects on).
    budget : int
    model_selection : {"final", "best_last_third", "best_held"}
    learning_starts : int
        The run's ``learning_starts`` (the last-third window counts updates after it).
    held_fractions : sequence of float, optional
        Share of the trainer's evaluation episodes that held at each step (required by
        ``"best_held"``).

    Returns
    -------
    int
    """
    if budget not in steps:
        raise ValueError(f"budget: expected an evaluated step {list(steps)}, found {budget}")
    if model_selection not in MODEL_SELECTIONS:
        raise ValueError(
            f"model_selection: expected one of {MODEL_SELECTIONS}, found {model_selection!r}"
        )
    if model_selection == "final":
        return int(budget)
    if held_fractions is None:
        if model_selection == "best_held":
            raise ValueError("held_fractions: expected one per step for 'best_held', found None")
        held_fractions = [0.0] * len(steps)
    start = selection_start(model_selection, budget, learning_starts)
    best_steps, best_key = int(budget), None
    for step, value, held in zip(steps, selection_returns, held_fractions, strict=True):
        key = selection_key(model_selection, value, held)
        if start < step <= budget and (best_key is None or key > best_key):
            best_steps, best_key = int(step), key
    return best_steps


def all_held(hold_steps: Sequence[int | None]) -> bool:
    """Whether every episode held the operating point (False for no episode at all)."""
    return bool(hold_steps) and all(step is not None for step in hold_steps)


def run_outcome(
    record: Mapping[str, Any], budget: int, model_selection: str | None = None
) -> RunOutcome:
    """:class:`RunOutcome` of a run's record (:func:`run_cell`) at ``budget``, delivered by the
    run's own model selection or, given ``model_selection``, re-selected by that rule from the
    same evaluations (the held-out test episodes play no part in any rule)."""
    evaluations = record["evaluations"]
    steps = [int(row["steps"]) for row in evaluations]
    delivered = delivered_steps(
        steps,
        [row["selection_return"] for row in evaluations],
        budget,
        model_selection or record["model_selection"],
        int(record["learning_starts"]),
        [row["selection_held_fraction"] for row in evaluations],
    )
    by_step = {int(row["steps"]): row for row in evaluations}
    reached = any(
        all_held(row["test_hold_steps"]) for row in evaluations if int(row["steps"]) <= budget
    )
    return RunOutcome(delivered, all_held(by_step[delivered]["test_hold_steps"]), reached)


# ------------------------------------------------------------------------------------ driving
def expected_seconds(plan: AblationPlan) -> Callable[[AblationSpec], float]:
    """A run's expected wall time for the sweep's ETA: the measured cost of its system and
    controller at leoc's budget (``leoc.experiments.profiles.PAPER_RUN_SECONDS``), scaled
    to the plan's budget; a SAC kind that was not measured costs its DDPG controller's times
    :data:`SAC_COST_FACTOR`."""
    from leoc.experiments.profiles import PAPER_RUN_SECONDS

    def cost(spec: AblationSpec) -> float:
        budget = plan.budget_for(spec.system)
        factor = 1.0
        measured = PAPER_RUN_SECONDS.get(f"{spec.system}/{spec.controller}")
        if measured is None and spec.algo in ("sac", "td3"):
            factor = SAC_COST_FACTOR if spec.algo == "sac" else 1.0
            ddpg = spec.controller.replace(f"{spec.algo}_", "ddpg_", 1)
            measured = PAPER_RUN_SECONDS.get(f"{spec.system}/{ddpg}")
        steps = TOTAL_STEPS_BY_SYSTEM.get(spec.system)
        if measured is None or steps is None:
            return factor * FALLBACK_SECONDS_PER_KSTEP * budget / 1000.0
        return factor * measured * budget / steps

    return cost


def run_ablation(
    out_dir: str | Path,
    specs: Sequence[AblationSpec],
    plan: AblationPlan | None = None,
    *,
    backend: str = "local",
    jobs: int | None = None,
    address: str | None = None,
    echo: Callable[[str], None] = print,
    command: str = "",
) -> SweepResult:
    """Run (or continue) the runs ``specs`` of an ablation folder.

    Parameters
    ----------
    out_dir : path
        The folder (see the module docstring); created if missing.
    specs : sequence of AblationSpec
        :func:`grid_specs` or any subset; runs already done are skipped.
    plan : AblationPlan, optional
        Budgets, intervals, held-out episodes, overrides (default: :class:`AblationPlan`'s).
        The folder's first invocation pins it per system; a later one must agree.
    backend, jobs, address
        As :class:`leoc.experiments.sweep.Sweep`.
    echo : callable
        Receives the progress lines.
    command : str
        The command line, recorded in :data:`PLAN_FILE`.

    Returns
    -------
    SweepResult

    Raises
    ------
    ValueError
        When ``plan`` disagrees with the folder's pinned plan, or an option is out of range.
    """
    from leoc.experiments.eta import trainer_progress

    plan = plan or AblationPlan()
    out = Path(out_dir)
    check_backend(backend, address)  # before anything is written
    _pin_plan(out, plan, specs, command, echo)
    return sweep(
        list(specs),
        AblationRunner(plan),
        out,
        backend=backend,
        jobs=jobs,
        address=address,
        done_file=RESULT_FILE,
        log_file=LOG_FILE,
        echo=echo,
        expected_seconds=expected_seconds(plan),
        progress_of=trainer_progress,
    )


def _pin_plan(
    out: Path,
    plan: AblationPlan,
    specs: Sequence[AblationSpec],
    command: str,
    echo: Callable[[str], None],
) -> None:
    """Write the folder's :data:`PLAN_FILE`: its pinned plan extended by ``plan`` for the
    systems of ``specs`` (:func:`merge_plan`, which raises if they disagree), and ``command``."""
    systems = sorted({spec.system for spec in specs})
    stored = read_json_object(out / PLAN_FILE, echo, "ablation plan") or {}
    pinned = merge_plan(stored.get("plan", {}), plan, systems)
    out.mkdir(parents=True, exist_ok=True)
    write_json_atomic(out / PLAN_FILE, {"plan": pinned, "command": command}, indent=2)


def read_records(out_dir: str | Path, echo: Callable[[str], None] = print) -> list[dict]:
    """Every finished run's record in an ablation folder, in key order."""
    records = []
    for path in sorted(Path(out_dir).glob(f"runs/*/*/*/seed*/{RESULT_FILE}")):
        record = read_json_object(path, echo, "result")
        if record is not None:
            records.append(record)
    return records
