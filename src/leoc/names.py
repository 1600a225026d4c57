"""Names the command line needs before anything heavy is imported.

The ``leoc`` command builds its parser (and answers ``--help``) from these tuples without
importing torch, gymnasium's environments or the systems. The modules that own each name re-use
them, and ``tests/test_cli.py`` checks that they agree with the registry and the profiles.
"""

from __future__ import annotations

import importlib.abc
import importlib.machinery
import sys
from typing import Any, NamedTuple

PAPER_SYSTEM_NAMES = ("pendulum", "cartpole", "mountaincar")
"""The paper's three benchmark systems (what ``leoc reproduce`` runs by default)."""
BUILTIN_SYSTEM_NAMES = (*PAPER_SYSTEM_NAMES, "acrobot")
"""Every system ``leoc.systems`` registers on import."""
BUILTIN_EPISODE_STEPS = 200
"""Episode length of every built-in system (the gymnasium ``TimeLimit``)."""
GENERIC_ENTRY_POINT = "leoc.systems.envs:LeocEnv"
BUILTIN_ENV_IDS = {
    "pendulum": ("leoc/PendulumSwingUp-v0", "leoc.systems.envs:PendulumSwingUpEnv"),
    "cartpole": ("leoc/CartPoleSwingUp-v0", "leoc.systems.envs:CartPoleSwingUpEnv"),
    "mountaincar": ("leoc/MountainCarHilltop-v0", "leoc.systems.envs:MountainCarHilltopEnv"),
    "acrobot": ("leoc/Acrobot-v0", GENERIC_ENTRY_POINT),
}
"""Gymnasium id and entry point of each built-in system (``import leoc`` registers them)."""

GYM_PREFIX = "gym:"
"""A system name ``gym:ENV_ID`` is the gymnasium environment ``ENV_ID`` itself, trained on by
:func:`leoc.sb3.train_gym` (``leoc train gym:InvertedPendulum-v5 --algo sac --hybrid``)."""


def gym_env_id(name: str) -> str | None:
    """The gymnasium id of a ``gym:ENV_ID`` system name, None for any other name.

    Raises
    ------
    ValueError
        ``gym:`` with no id after it.
    """
    if not name.startswith(GYM_PREFIX):
        return None
    env_id = name[len(GYM_PREFIX) :].strip()
    if not env_id:
        raise ValueError(
            f"system: expected gym:ENV_ID (e.g. gym:InvertedPendulum-v5), found {name!r}"
        )
    return env_id


def gym_folder_name(name: str) -> str:
    """The run-folder component of a system name: ``gym:ENV_ID`` becomes ``gym-ENV_ID`` (no
    colon in a path), any other name is itself."""
    return name.replace(":", "-", 1) if name.startswith(GYM_PREFIX) else name


CONTROLLERS = (
    "linear",
    "linear_pilco",
    "ddpg_baseline",
    "ddpg_hybrid",
    "ddpg_hybrid_roa",
    "ddpg_hybrid_lyapunov",
    "td3_baseline",
    "td3_hybrid",
    "td3_hybrid_roa",
    "td3_hybrid_lyapunov",
    "sac_baseline",
    "sac_hybrid",
    "sac_hybrid_roa",
    "sac_hybrid_lyapunov",
    "pilco_baseline",
    "pilco_hybrid",
    "pilco_hybrid_roa",
    # no pilco_hybrid_lyapunov: PILCO's config refuses relevance='lyapunov' (PILCO's hybrid
    # has the paper's or the ROA relevance, leoc.pilco.config), so such a run could not train
)
"""Every controller ``leoc reproduce`` knows, in report order: per framework its baseline, then
its hybrids with the paper's, the ROA and (DDPG, TD3 and SAC only) the Lyapunov relevance."""
LEARNER_NAMES = ("pilco", "ddpg", "td3", "sac")
"""leoc's learners (``leoc.learners.learner_names()``, registration order): ``leoc train
--algo``'s choices."""
FRAMEWORKS = ("ddpg", "td3", "sac", "pilco")
"""The learners of ``leoc reproduce``'s trained controllers (each controller's name starts with
one), in report order."""


LINEAR = "linear"
"""The learner name of the linear references (designed, not trained)."""
CONTROLLER_KINDS = {"baseline": None, "hybrid": "paper", "hybrid_roa": "roa"}
"""A trained controller's name is ``LEARNER_KIND``: each kind and its hybrid's relevance (None:
the learned policy alone). A relevance design of another name ``X`` is the kind ``hybrid_X``."""
HYBRID_KIND = "hybrid"


class ControllerName(NamedTuple):
    """What a controller name says (:func:`parse_controller`): the one reading of the names of
    ``leoc reproduce``'s controllers, run folders and the report.

    Attributes
    ----------
    learner : str
        A learner (``ddpg``, ``td3``, ``sac``, ``pilco``, or one registered) or ``linear``.
    relevance : str or None
        The hybrid's relevance design (``paper``, ``roa``), None for a baseline or an LQR.
    period_of : str or None
        A linear reference's control period: that of this learner (``linear_pilco``: PILCO's);
        None: every simulator step.
    """

    learner: str
    relevance: str | None = None
    period_of: str | None = None

    @property
    def hybrid(self) -> bool:
        """Whether the name is a hybrid's."""
        return self.relevance is not None

    @property
    def name(self) -> str:
        """The controller name again (:func:`parse_controller`'s inverse)."""
        if self.learner == LINEAR:
            return LINEAR if self.period_of is None else f"{LINEAR}_{self.period_of}"
        kinds = (k for k, relevance in CONTROLLER_KINDS.items() if relevance == self.relevance)
        return f"{self.learner}_{next(kinds, f'{HYBRID_KIND}_{self.relevance}')}"


def parse_controller(name: str) -> ControllerName:
    """Read a controller name: ``linear``, ``linear_LEARNER`` (the LQR at that learner's control
    period) or ``LEARNER_KIND`` with KIND in :data:`CONTROLLER_KINDS` (``ddpg_hybrid_roa``).

    Raises
    ------
    ValueError
        On a name of neither form, naming ``controller``.
    """
    learner, _, kind = str(name).partition("_")
    if learner == LINEAR:
        return ControllerName(LINEAR, None, kind or None)
    hybrid, _, relevance = kind.partition("_")
    if learner and kind in CONTROLLER_KINDS:
        return ControllerName(learner, CONTROLLER_KINDS[kind])
    if not learner or hybrid != HYBRID_KIND or not relevance:
        raise ValueError(
            f"controller: expected 'linear', 'linear_LEARNER' or 'LEARNER_KIND' with KIND one of "
            f"{tuple(CONTROLLER_KINDS)} or 'hybrid_RELEVANCE' (e.g. 'ddpg_hybrid_roa'), found "
            f"{name!r}"
        )
    return ControllerName(learner, relevance)


def controller_framework(controller: str) -> str:
    """The learner of a controller name (``ddpg``, ``sac``, ``pilco``), or ``linear`` for the
    linear references (``linear``, ``linear_pilco``)."""
    return parse_controller(controller).learner


REQUEST_ONLY_FRAMEWORKS = ("td3", "sac")
"""Learners whose controllers ``leoc reproduce`` runs only when ``--controllers`` names them
(the paper has no TD3 and no SAC)."""
REQUEST_ONLY_RELEVANCES = ("roa", "lyapunov")
"""Relevance designs whose hybrids ``leoc reproduce`` runs only when ``--controllers`` names them
(the paper's hybrids have the paper's relevance)."""
DEFAULT_CONTROLLERS = tuple(
    name
    for name in CONTROLLERS
    if parse_controller(name).relevance not in REQUEST_ONLY_RELEVANCES
    and controller_framework(name) not in REQUEST_ONLY_FRAMEWORKS
)
"""What ``leoc reproduce`` runs unless ``--controllers`` says otherwise: the paper's controllers
and the two linear references (the ROA- and Lyapunov-relevance hybrids and TD3's and SAC's
controllers are added on request)."""
PROFILE_NAMES = ("quick", "smoke", "paper")
"""The profiles of ``leoc reproduce`` (``leoc.experiments.profiles.PROFILES``, same order)."""
VARIANT_NAMES = ("leoc", "authors")
"""Implementations (``leoc.experiments.variants``): leoc's defaults, or the authors' choices."""
METRIC_SET_NAMES = ("leoc", "authors")
"""Response metric sets (``leoc.evaluation.metric_sets``)."""
RELEVANCE_NAMES = ("paper", "roa", "lyapunov")
"""Relevance functions of a hybrid (``leoc.policies.relevance.RELEVANCE_KINDS``): the paper's
r(x) = (1 + d)^-2, the ROA relevance, exactly 1 on the LQR's certified region, or the paper's
form with the LQR's Lyapunov function as its distance."""
ROBUSTNESS_CATEGORIES = (
    "observation_noise",
    "action_delay",
    "actuator_gain",
    "torque_noise",
    "viscous_friction",
    "coulomb_friction",
    "parameter_error",
    "push",
)
"""The perturbation categories of the robustness protocol
(``leoc.evaluation.robustness_protocol.CATEGORY_NAMES``), in report order."""
ROBUSTNESS_LEVELS = 21
"""Levels per category of the robustness protocol (RealAIGym's 21)."""
ROBUSTNESS_EPISODES = 5
"""Episodes per level and start kind of the robustness protocol."""
SELECTION_PLANTS = ("nominal", "training")
"""Where a DDPG/TD3/SAC run's model selection judges its candidates
(``leoc.sb3.DDPGConfig.selection_plants``, ``leoc train --select-on``): the nominal evaluation
episodes, or the same starts on plants of the training distribution."""
LYAPUNOV_CHOICES = ("best", "lqr", "own")
"""The V a controller's proof uses (``leoc roa --prove --lyapunov``,
:func:`leoc.control.certify_controller`): the larger proved set of the two, the LQR's P, or
the discrete Lyapunov matrix of the controller's own linearisation at its equilibrium."""

LQR_METHODS = ("discrete", "continuous", "authors")
"""LQR designs of ``leoc.control.design_lqr``."""
BACKEND_NAMES = ("local", "ray")
"""Where a sweep's runs run (``leoc.experiments.sweep.BACKENDS``): worker processes on this
machine, or Ray tasks."""
ABLATION_SYSTEM_NAMES = ("cartpole", "mountaincar", "pendulum")
"""The DDPG ablation's systems (``leoc.experiments.ablation.ABLATION_SYSTEMS``): the two that
failed, then the pendulum as the control."""
ABLATION_CONTROLLERS = ("ddpg_baseline", "ddpg_hybrid", "ddpg_hybrid_roa")
"""The DDPG controllers of the ablation's default grid."""
ABLATION_SAC_CONTROLLERS = ("sac_baseline", "sac_hybrid", "sac_hybrid_roa")
"""The SAC controllers the ablation also runs (not in the default grid)."""
ABLATION_TD3_CONTROLLERS = ("td3_baseline", "td3_hybrid", "td3_hybrid_roa")
"""The TD3 controllers the ablation also runs (not in the default grid)."""
ABLATION_SETTINGS = (
    "leoc",
    "authors",
    "exploration",
    "initial_collect",
    "critic",
    "exit_penalty",
    "model_selection",
)
"""The settings of the ablation's default grid (``leoc.experiments.ablation.SETTINGS``)."""
ABLATION_ALL_SETTINGS = (
    *ABLATION_SETTINGS,
    "all_factors",
    "all_but_exploration",
    "all_but_initial_collect",
    "all_but_critic",
    "all_but_exit_penalty",
    "all_but_model_selection",
    "all_safe_exit",
    "horizon_exit",
    "all_horizon_exit",
    "defaults",
    "sac_sb3_critic",
    "sac_alpha_0.1",
    "sac_alpha_0.01",
    "sac_initial_collect",
    "sac_ddpg_optimiser",
    "sac_huber",
    "sac_critic",
    "sac_ou",
    "relevance_paper",
    "relevance_precision",
    "relevance_frozen",
    "relevance_init_10",
    "relevance_lr_0.1",
    "relevance_lr_0.01",
    "relevance_floor_0.99",
    "relevance_floor_0.9",
    "relevance_floor_0.5",
    "relevance_lyapunov",
    "relevance_power_2",
    "relevance_power_2_floor_0.5",
    "relevance_power_2_floor_0.9",
)
"""Every setting the ablation runs (``leoc.experiments.ablation.ALL_SETTINGS``, same order)."""
ABLATION_TEST_EPISODES = 5
"""Held-out swing-up episodes of the ablation's success test, per evaluation."""

GYM_STUDY_ENVS = ("InvertedPendulum-v5", "InvertedDoublePendulum-v5", "Pendulum-v1")
"""The gymnasium envs of ``leoc gym-study`` by default (``leoc.experiments.gym_study``); the
MuJoCo pair at every start noise, ``Pendulum-v1`` against leoc's own pendulum
(``leoc.experiments.gym_pendulum``)."""
GYM_STUDY_DEFAULT_NOISE = "default"
"""``leoc gym-study``'s word for the env's own ``reset_noise_scale`` (no keyword passed)."""
GYM_STUDY_NOISES = (GYM_STUDY_DEFAULT_NOISE, "0.5", "0.8")
"""The start noises (``reset_noise_scale``) of ``leoc gym-study`` by default."""
GYM_STUDY_PROFILES = ("smoke", "full")
"""The profiles of ``leoc gym-study`` (``leoc.experiments.gym_study.STUDY_PROFILES``)."""
GYM_STUDY_CONTROLLERS = ("lqr", "sac_baseline", "sac_hybrid", "sac_hybrid_roa")
"""The controllers of ``leoc gym-study``, in table order: the clipped LQR alone, SAC alone, the
SAC hybrid with the paper's relevance (no floor) and with the ROA relevance."""


def register_builtin_envs() -> None:
    """Register the built-in systems' gymnasium ids by entry point, without building them.

    ``gymnasium.make`` of one of these ids imports :mod:`leoc.systems.envs`, which imports
    :mod:`leoc.systems` and registers every system in full (an id registered here is replaced
    there). So ``import leoc`` keeps gymnasium's convention (importing the package registers its
    environments) without importing torch.
    """
    import gymnasium as gym

    for name, (env_id, entry_point) in BUILTIN_ENV_IDS.items():
        if env_id in gym.registry:
            continue
        kwargs = {"system": name} if entry_point == GENERIC_ENTRY_POINT else {}
        gym.register(
            id=env_id,
            entry_point=entry_point,
            max_episode_steps=BUILTIN_EPISODE_STEPS,
            kwargs=kwargs,
        )


class _RegisterAfterImport(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Finds ``gymnasium`` with the normal machinery and, once it has been executed, registers
    the built-in environments; then steps aside (it is used once)."""

    def __init__(self) -> None:
        self._loader: Any = None

    def find_spec(self, name: str, path: Any = None, target: Any = None) -> Any:
        if name != "gymnasium" or self not in sys.meta_path:
            return None
        sys.meta_path.remove(self)
        spec = importlib.machinery.PathFinder.find_spec(name, path)
        if spec is None or spec.loader is None:
            return spec
        self._loader, spec.loader = spec.loader, self
        return spec

    def create_module(self, spec: Any) -> Any:
        return self._loader.create_module(spec)

    def exec_module(self, module: Any) -> None:
        self._loader.exec_module(module)
        register_builtin_envs()


def register_builtin_envs_with_gymnasium() -> None:
    """Register the built-in ids now if gymnasium is imported, else as soon as it is: ``import
    leoc`` then stays free of gymnasium's (and numpy's) import time, which the ``leoc`` command
    does not need to answer ``--help``, and ``gymnasium.make("leoc/...")`` works either way."""
    if "gymnasium" in sys.modules:
        register_builtin_envs()
    elif not any(isinstance(finder, _RegisterAfterImport) for finder in sys.meta_path):
        sys.meta_path.insert(0, _RegisterAfterImport())
