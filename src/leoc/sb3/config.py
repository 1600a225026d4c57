"""Typed configuration of a DDPG/TD3 run: the paper's hyperparameters, and the choices that
make DDPG learn every swing-up as defaults.

The paper's values (Zhang & Capel, L4DC 2021, appendix C, table "Framework hyperparameters"):
Adam, actor learning rate 5e-4, critic learning rate 1e-3, discount 0.995, minibatch 64,
replay buffer 1e5, soft target updates with factor 0.05 every 5 updates, Lambda initialised to
the identity, 10k-15k interaction steps; the actor and critic are 400-300 MLPs as in the
original DDPG experiments (Lillicrap et al., 2016), explored with Ornstein-Uhlenbeck noise.
Reading of the appendix where it is terse:

* "Target update factor 0.05" is the Polyak coefficient and "target update rate 5" the number
  of gradient updates between two soft target updates (``DDPGConfig.target_update_interval``).
* "Number of iterations 10000-15000" are environment steps: 10k for the pendulum and the
  mountain car, 15k for the cart-pole (:data:`PAPER_TOTAL_STEPS`).

Where the appendix is silent, leoc's defaults are the choices the DDPG ablation
(:mod:`leoc.experiments.ablation`, ``results/ddpg-ablation``, issue 20) found to learn: its
``all_safe_exit`` setting with the ``best_held`` model selection. Each is a field, and each
follows the authors' code (nrjc/LEOC, TF-Agents' DDPG; :data:`AUTHORS_DDPG` documents the
file): Ornstein-Uhlenbeck exploration in the physical action's units (theta 0.2, sigma 1.0,
never reset); 1000 initial steps from the noisy policy; Huber TD loss, the action joining the
critic after its first hidden layer in physical units, TF-Agents' initialisation with output
layers U(+/-0.003); on the cart-pole and the mountain car the reward of the state a transition
reaches (:data:`STEP_RULES_BY_SYSTEM`), with leoc's exit that never pays (the authors' -100
exit pays, so leoc does not take it). The run delivers the actor of the evaluation that held
the operating point best (``best_held``, 3 episodes every :data:`EVAL_INTERVAL_BY_SYSTEM`
steps), where the authors keep the best return of the last third. The budgets
(:data:`TOTAL_STEPS_BY_SYSTEM`) are 20k on the cart-pole and the mountain car, where the
paper's were not enough. Until issue 20 leoc ran SB3's choices instead (uniform warm-up of one
episode, OU theta 0.15 / sigma 0.2 on the normalised action, reset every episode, MSE loss,
action at the critic's input, PyTorch's initialisation, the final actor);
:data:`leoc.experiments.ablation.LEOC_ABLATION_BASE` writes them out, and they remain
overrides.

TD3 shares these defaults; the ablation measured DDPG only. SAC keeps its own exploration and
critics (:data:`SAC_DEFAULTS`) and shares the budgets, the step rules and the model selection.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Literal

from leoc.names import SELECTION_PLANTS
from leoc.policies.spec import (
    HybridSpec,
    as_hybrid_spec,
    legacy_hybrid_config,
    with_hybrid_overrides,
)

#: Model-free learners: Stable-Baselines3's DDPG, TD3 and SAC (each as baseline or hybrid).
ALGOS = ("ddpg", "td3", "sac")
Algo = Literal["ddpg", "td3", "sac"]

# Environment steps per run of a system without its own budget (appendix C: 10000-15000).
DEFAULT_TOTAL_STEPS = 10_000
#: The paper's environment steps per run for each of its systems (appendix C).
PAPER_TOTAL_STEPS = {"pendulum": 10_000, "cartpole": 15_000, "mountaincar": 10_000}
#: leoc's environment steps per run (DDPG, TD3 and SAC): the paper's on the pendulum; 20k on
#: the cart-pole and the mountain car, where the DDPG ablation (``results/ddpg-ablation``,
#: issue 20) found no setting that learns on 4 of 5 seeds at the paper's 15k and 10k for all
#: three controllers: with leoc's defaults the cart-pole baseline, hybrid and ROA hybrid hold
#: on >= 4 of 5 seeds from 18.6k steps on, the mountain-car baseline from 19.6k (both hybrids
#: from 10k).
TOTAL_STEPS_BY_SYSTEM = {"pendulum": 10_000, "cartpole": 21_000, "mountaincar": 20_000}
#: Environment steps between two evaluations (the model selection's candidates) per system:
#: the authors' intervals (data/*DDPG*.gin ``eval_interval``), at which ``best_held`` was
#: measured.
EVAL_INTERVAL_BY_SYSTEM = {"pendulum": 200, "cartpole": 300, "mountaincar": 200}
#: :class:`~leoc.systems.StepRules` fields of a model-free run per system, where they are not
#: leoc's rules: on the cart-pole and the mountain car a transition earns the reward of the
#: state it reaches (the authors' choice there; leoc's exit that never pays is kept).
STEP_RULES_BY_SYSTEM: dict[str, dict[str, Any]] = {
    "cartpole": {"reward_on_next_state": True},
    "mountaincar": {"reward_on_next_state": True},
}
# Hold band of the "reached and held the operating point" test, in the units of
# ``System.main_coordinate`` (degrees for the pendulum and cart-pole angles, metres for the car).
PAPER_HIDDEN_SIZES = (400, 300)
# Choices of the fields where the authors differ (their meaning: DDPGConfig's docstring); the
# modules that act on them (algorithms, policies, callbacks, train) import them from here.
NOISE_UNITS = ("normalised", "physical")
WARMUPS = ("uniform", "policy")
CRITIC_LOSSES = ("mse", "huber")
CRITIC_ACTION_UNITS = ("normalised", "physical")
HIDDEN_INITS = ("torch", "tf_agents")
MODEL_SELECTIONS = ("final", "best_last_third", "best_held")

# ------------------------------------------------------------------------------------------- SAC
#: :meth:`DDPGConfig.for_system` defaults of ``algo="sac"`` where SAC's differ from the paper's
#: DDPG (Haarnoja et al. 2018, "Soft Actor-Critic Algorithms and Applications", table 1: minibatch
#: 256, soft target updates with factor 0.005 after every update; rl-baselines3-zoo's
#: ``hyperparams/sac.yml`` for Pendulum-v1, this pendulum's dynamics: Adam step 1e-3 for the
#: actor, the critics and the entropy coefficient). What describes the problem, not the learner,
#: stays the paper's: discount 0.995, 400-300 networks, buffer 1e5, the budgets, and leoc's step
#: rules and model selection. SAC starts as SB3's does, with one episode (200 steps) of uniform
#: actions before the first update (DDPG's 1000 noisy steps answer DDPG's exploration). Its
#: critics are SB3's (the action at the input in normalised units, PyTorch's initialisation)
#: with DDPG's Huber TD loss (delta 1): with SB3's mean squared error SAC did not learn the
#: cart-pole swing-up (issue 20; the ablation's SAC settings,
#: :data:`leoc.experiments.ablation.SAC_TUNING_SETTINGS`).
SAC_DEFAULTS: dict[str, Any] = {
    "actor_learning_rate": 1e-3,
    "critic_learning_rate": 1e-3,
    "batch_size": 256,
    "polyak": 0.005,
    "target_update_interval": 1,
    "learning_starts": 200,
    "warmup": "uniform",
    "critic_action_layer": 0,
    "critic_action_units": "normalised",
    "hidden_init": "torch",
    "last_layer_init": None,
}
#: Fields of the DDPG/TD3 family that SAC does not use (its exploration is its own Gaussian,
#: its action bounded by the squash, its twin critics always TD3's): a SAC config must leave
#: them at their defaults. SAC does use the critics' loss, layout and initialisation
#: (``critic_loss``, ``critic_action_layer``, ``critic_action_units``, ``hidden_init``,
#: ``last_layer_init``; :class:`~leoc.sb3.sac.LeocSAC`, :class:`~leoc.sb3.sac.LeocSACPolicy`),
#: and the OU exploration fields with ``sac_action_noise`` (:data:`OU_FIELDS`).
TD3_FAMILY_FIELDS = (
    "td3_policy_delay",
    "td3_target_noise",
    "td3_target_noise_clip",
    "actor_output_clip",
)
#: Fields only SAC uses: a DDPG or TD3 config must leave them at their defaults.
SAC_FIELDS = ("sac_entropy_coef", "sac_target_entropy", "sac_action_noise")
#: The OU exploration fields: SAC uses them only with ``sac_action_noise=True``.
OU_FIELDS = ("ou_theta", "ou_sigma", "noise_units", "noise_reset")
AUTO = "auto"  # SB3's automatic entropy coefficient / target entropy

# --------------------------------------------------------------------------- the authors' DDPG
# nrjc/LEOC files (read with the search tool's read_file): DDPG/ddpg.py at commit
# ec5aa7af06a218744b124b8a26ef8e84d6f95df2 and at the versions with ``actor_learning_rate``
# (the gin files bind it); dao/trainer.py (the version that trains: ``self.ddpg.agent.train``
# in ``DDPGTrainer.train``); data/*DDPG*.gin at commits 60501287f7c133689407034d5f60b2d00b2e82ac
# and 70dc15f0f0c9f32df25ae90734e3f491fc98fbfc; TF-Agents (tensorflow/agents)
# tf_agents/utils/common.py (OUProcess), tf_agents/agents/ddpg/{actor,critic}_network.py.
AUTHORS_INITIAL_COLLECT_STEPS = 1_000  # dao/trainer.py DDPGTrainer.train(initial_collect_steps)
# data/*DDPG*.gin: DDPGTrainer.num_iterations (one collect step + one update each)
AUTHORS_ITERATIONS = {"pendulum": 10_000, "cartpole": 15_000, "mountaincar": 10_000}
# data/*DDPG*.gin: DDPGTrainer.eval_interval (iterations)
AUTHORS_EVAL_INTERVAL = {"pendulum": 200, "cartpole": 300, "mountaincar": 200}
# data/Cartpole_DDPG_Baseline.gin: DDPG.actor_learning_rate = 1e-4 (every other gin file: 5e-4)
AUTHORS_CARTPOLE_BASELINE_ACTOR_LR = 1e-4

AUTHORS_DDPG: dict[str, Any] = {
    # DDPG/ddpg.py, DdpgAgent(ou_stddev=1., ou_damping=.2) (the versions that bind
    # actor_learning_rate; ec5aa7 has ou_stddev=.5): TF-Agents' OUNoisePolicy adds
    # OUProcess noise, x <- (1 - damping) x + N(0, stddev^2), to the action in the action
    # spec's (physical) units, starting at 0 and never reset (tf_agents/utils/common.py).
    "noise_units": "physical",
    "ou_theta": 0.2,
    "ou_sigma": 1.0,
    "noise_reset": False,
    # dao/trainer.py: replay_buffer.collect_data(steps=initial_collect_steps=1000) with the
    # agent's collect_policy (the noisy actor), then num_iterations x (1 step + 1 update).
    "warmup": "policy",
    "learning_starts": AUTHORS_INITIAL_COLLECT_STEPS,
    # DDPG/ddpg.py: td_errors_loss_fn=tf.compat.v1.losses.huber_loss (delta 1, mean).
    "critic_loss": "huber",
    # DDPG/ddpg.py: CriticNetwork(observation_fc_layer_params=(400,), action_fc_layer_params=None,
    # joint_fc_layer_params=(300,)): obs -> 400 -> concat(action) -> 300 -> 1; TF-Agents feeds
    # the action in the spec's (physical) units.
    "critic_action_layer": 1,
    "critic_action_units": "physical",
    # DDPG/ddpg.py: kernel_initializer=None, last_kernel_initializer=None for both networks:
    # TF-Agents' defaults, VarianceScaling(1/3, fan_in, uniform) = U(+/- 1/sqrt(fan_in)), zero
    # biases, last layers RandomUniform(-0.003, 0.003) (tf_agents/agents/ddpg/*_network.py).
    "hidden_init": "tf_agents",
    "last_layer_init": 0.003,
    # DDPG/ddpg.py MyActorNetwork: d = (x - a) diag(S) (x - a)^T, S = tf.Variable(S,
    # trainable=True) with S = [1.] * D (the gin files do not bind S), no positivity constraint.
    "relevance_parametrisation": "precision",
    "lambda_init": 1.0,
    "learn_lambda": True,
    # DDPG/ddpg.py MyActorNetwork.call returns scale_to_spec(r g + (1 - r) h) unclipped (only
    # the policies clip, ActorPolicy(clip=True), OUNoisePolicy(clip=True)); TF-Agents'
    # DdpgAgent feeds the actor's and target actor's actions to the critics unclipped.
    "actor_output_clip": False,
    # dao/trainer.py: the policy saved when iteration > int(num_iterations / 3 * 2) and the
    # evaluation return beats the best so far; data/*DDPG*.gin: Evaluator.eval_num_episodes = 3.
    "model_selection": "best_last_third",
    "eval_episodes": 3,
    # The same values as leoc's defaults (appendix C), pinned here: DDPG/ddpg.py
    # critic_learning_rate 1e-3, gamma=0.995, target_update_tau=0.05, target_update_period=5,
    # fc_layer_params=(400, 300); ReplayBuffer(replay_buffer_capacity=100000);
    # DDPGTrainer.train(batch_size=64); data/*DDPG*.gin: DDPG.actor_learning_rate = 5e-4.
    "actor_learning_rate": 5e-4,
    "critic_learning_rate": 1e-3,
    "discount": 0.995,
    "polyak": 0.05,
    "target_update_interval": 5,
    "buffer_size": 100_000,
    "batch_size": 64,
    "actor_hidden": PAPER_HIDDEN_SIZES,
    "critic_hidden": PAPER_HIDDEN_SIZES,
    "train_freq": 1,
    "gradient_steps": 1,
}
"""The authors' DDPG settings (nrjc/LEOC with TF-Agents), as :class:`DDPGConfig` overrides that
hold for every system; :func:`authors_ddpg_overrides` adds the per-system ones."""


def authors_ddpg_overrides(system: str, hybrid: bool, budget: int | None = None) -> dict[str, Any]:
    """:data:`AUTHORS_DDPG` plus the authors' per-system settings for ``system``.

    Per system (data/*DDPG*.gin): ``eval_interval`` 200 (pendulum, mountain car) or 300
    (cart-pole) steps; ``total_steps`` = 1000 initial collect steps + ``num_iterations``
    (10000, 15000 for the cart-pole), one step and one update each; the cart-pole baseline's
    actor learning rate 1e-4. A system the authors did not run gets the shared settings only.

    Parameters
    ----------
    system : str
        System name.
    hybrid : bool
        Whether the run trains the LEOC hybrid (else the plain MLP baseline).
    budget : int, optional
        Environment steps in all (initial collect included) in place of the authors'; their
        model selection window (the last third) follows it.

    Returns
    -------
    dict
        Keyword overrides for :meth:`DDPGConfig.for_system` (a fresh dict).
    """
    overrides = dict(AUTHORS_DDPG)
    if system in AUTHORS_ITERATIONS:
        overrides["total_steps"] = AUTHORS_INITIAL_COLLECT_STEPS + AUTHORS_ITERATIONS[system]
        overrides["eval_interval"] = AUTHORS_EVAL_INTERVAL[system]
    if budget is not None:
        overrides["total_steps"] = budget
    if system == "cartpole" and not hybrid:
        overrides["actor_learning_rate"] = AUTHORS_CARTPOLE_BASELINE_ACTOR_LR
    return overrides


@dataclasses.dataclass(frozen=True)
class DDPGConfig:
    r"""Settings of one DDPG/TD3 training run (baseline or LEOC hybrid).

    Attributes
    ----------
    system : str
        System name (``pendulum``, ``cartpole``, ``mountaincar``).
    algo : {"ddpg", "td3", "sac"}
        Stable-Baselines3 algorithm. DDPG is SB3's TD3 with ``policy_delay=1``, no target
        policy smoothing and a single critic. SAC (:mod:`leoc.sb3.sac`) explores with its own
        entropy-regularised Gaussian: the fields of :data:`TD3_FAMILY_FIELDS` must keep their
        defaults, and :meth:`for_system` applies :data:`SAC_DEFAULTS`.
    hybrid : HybridSpec or None
        The LEOC hybrid actor ``sat(r G + (1 - r) H)`` this spec describes
        (:class:`~leoc.policies.HybridSpec`: relevance design, its parameters, what the actor
        loss trains), or None: the plain MLP ``H`` (for SAC: the squashed mean). ``True`` and a
        dict are read as ``HybridSpec()`` and ``HybridSpec.from_dict``.
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
        Environment steps before the first update, acted as ``warmup`` says (1000; SAC: one
        episode, 200).
    warmup : {"uniform", "policy"}
        How the first ``learning_starts`` steps act: with the noisy policy (TF-Agents' initial
        collect; the default) or uniformly at random (SB3; SAC's default).
    train_freq, gradient_steps : int
        Update every ``train_freq`` environment steps with ``gradient_steps`` gradient steps.
    actor_hidden, critic_hidden : tuple of int
        Hidden widths of the actor MLP H and of the critic (400-300).
    ou_theta, ou_sigma : float
        Ornstein-Uhlenbeck mean reversion and innovation scale per step (TF-Agents' damping
        and stddev), in ``noise_units`` (0.2 and 1.0; Lillicrap et al.'s 0.15 and 0.2 were
        leoc's on the normalised action).
    noise_units : {"normalised", "physical"}
        Units the OU process runs in: the physical action (TF-Agents' ``OUNoisePolicy``; the
        default) or the normalised action in [-1, 1] (SB3).
    noise_reset : bool
        Restart the OU process at 0 at every episode end (SB3) or never (TF-Agents; the
        default).
    critic_loss : {"mse", "huber"}
        TD loss of the critic: mean Huber loss with delta 1 (the default) or mean squared error
        (SB3). SAC uses it too, with the same default.
    critic_action_layer : int
        Critic hidden layers before the action joins (1: after the first hidden layer,
        TF-Agents' ``CriticNetwork`` as the authors configure it, the default; 0: at the input,
        SB3).
    critic_action_units : {"normalised", "physical"}
        Units of the action fed to the critic (physical by default).
    hidden_init : {"torch", "tf_agents"}
        Initialisation of the actor's and critic's layers (TF-Agents':
        :math:`U(\pm 1/\sqrt{n_{in}})` weights, zero biases, the default; or PyTorch's).
    last_layer_init : float or None
        Output layers' weights :math:`U(\pm v)` with zero bias (TF-Agents: 0.003, the default);
        None: as ``hidden_init``.
    td3_policy_delay, td3_target_noise, td3_target_noise_clip : float
        TD3's delayed actor updates and target policy smoothing (SB3 defaults; unused by DDPG).
    actor_output_clip : bool
        Clip the hybrid actor's blend and the target actions to the action box inside the
        training graph (leoc, SB3) or leave them unbounded as TF-Agents' DDPG does (the
        executed action is clipped either way).
    lqr_method : {"discrete", "continuous"}
        LQR design used for G (see :func:`leoc.control.design_lqr`).
    eval_interval : int
        Environment steps between two evaluations (:meth:`for_system`: 200, 300 on the
        cart-pole).
    eval_episodes : int
        Deterministic swing-up episodes per evaluation, on a separate environment instance (3).
    model_selection : {"final", "best_last_third", "best_held"}
        The run's controller: the one of the evaluation that held the operating point in the
        largest share of its episodes, the highest mean return among those (any evaluation of
        the run; the earliest on ties; the default), the actor at the end of training (leoc's
        until issue 20), or the one of the best evaluation (mean return) after two thirds of
        the updates (the authors').
    sac_entropy_coef : "auto", "auto_<init>" or float
        SAC's entropy coefficient alpha: learned to reach ``sac_target_entropy`` (``"auto"``,
        starting at 1; ``"auto_0.1"`` starting at 0.1) or fixed (a positive number). SAC only.
    sac_target_entropy : "auto" or float
        Target entropy of the automatic tuning (``"auto"``: minus the action dimension,
        Haarnoja et al. 2018). SAC only.
    sac_action_noise : bool
        SAC only: add DDPG's Ornstein-Uhlenbeck exploration (``ou_theta``, ``ou_sigma``,
        ``noise_units``, ``noise_reset``, seeded as DDPG's) to the actions SAC samples, clipped
        to the action box (SB3 adds an algorithm's ``action_noise`` so), for temporally
        correlated exploration on top of SAC's own Gaussian; the replayed action is the one
        applied. False (the default): SAC's Gaussian only, and the OU fields must keep their
        defaults.
    step_rules : dict
        Fields of the :class:`~leoc.systems.StepRules` the training and evaluation environments
        step under (empty: leoc's rules; :meth:`for_system` sets the reward of the next state
        on the cart-pole and the mountain car; the authors' variant sets theirs).
    training_perturbations : dict
        The perturbations of the training environment
        (:meth:`leoc.systems.TrainingPerturbations.as_dict`: fixed levels and randomised
        maxima, each episode's plant drawn from the run's seed); empty: the nominal plant.
        The evaluation episodes run on the nominal plant. Recorded in ``config.json`` only
        when not empty (a nominal run's config is as before).
    selection_plants : {"nominal", "training"}
        The plants ``model_selection`` judges on: the learning curve's nominal evaluation
        episodes (the default), or, for a run with randomised ``training_perturbations``,
        as many episodes from the same starts on plants of the training distribution, one
        stratum of each range per episode, the same plants at every evaluation
        (:meth:`leoc.systems.TrainingPerturbations.selection_draws`); the curve stays nominal
        and each row records the selection episodes' return and held share under
        ``"selection"``. Recorded in ``config.json`` only when not ``"nominal"``.
    """

    system: str
    algo: str = "ddpg"
    hybrid: HybridSpec | None = None
    total_steps: int = DEFAULT_TOTAL_STEPS
    actor_learning_rate: float = 5e-4
    critic_learning_rate: float = 1e-3
    discount: float = 0.995
    batch_size: int = 64
    buffer_size: int = 100_000
    polyak: float = 0.05
    target_update_interval: int = 5
    learning_starts: int = 1_000
    warmup: str = "policy"
    train_freq: int = 1
    gradient_steps: int = 1
    actor_hidden: tuple[int, ...] = PAPER_HIDDEN_SIZES
    critic_hidden: tuple[int, ...] = PAPER_HIDDEN_SIZES
    ou_theta: float = 0.2
    ou_sigma: float = 1.0
    noise_units: str = "physical"
    noise_reset: bool = False
    critic_loss: str = "huber"
    critic_action_layer: int = 1
    critic_action_units: str = "physical"
    hidden_init: str = "tf_agents"
    last_layer_init: float | None = 0.003
    td3_policy_delay: int = 2
    td3_target_noise: float = 0.2
    td3_target_noise_clip: float = 0.5
    actor_output_clip: bool = True
    lqr_method: str = "discrete"
    eval_interval: int = 1_000
    eval_episodes: int = 3
    model_selection: str = "best_held"
    sac_entropy_coef: str | float = AUTO
    sac_target_entropy: str | float = AUTO
    sac_action_noise: bool = False
    step_rules: dict[str, Any] = dataclasses.field(default_factory=dict)
    training_perturbations: dict[str, Any] = dataclasses.field(default_factory=dict)
    selection_plants: str = "nominal"

    def __post_init__(self) -> None:
        from leoc.names import gym_env_id
        from leoc.systems import system_names
        from leoc.systems.perturbation_levels import training_setting

        if self.system not in system_names() and gym_env_id(self.system) is None:
            raise ValueError(
                f"system: expected one of {system_names()} or gym:ENV_ID, found {self.system!r}"
            )
        if self.algo not in ALGOS:
            raise ValueError(f"algo: expected one of {ALGOS}, found {self.algo!r}")
        object.__setattr__(self, "hybrid", as_hybrid_spec(self.hybrid))
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
        )
        for name in positive_floats:
            value = getattr(self, name)
            if not isinstance(value, (int, float)) or not value > 0:
                raise ValueError(f"{name}: expected a positive number, found {value!r}")
        if not self.discount <= 1.0 or not self.polyak <= 1.0:
            raise ValueError(
                f"discount, polyak: expected values in (0, 1], found {self.discount}, {self.polyak}"
            )
        from leoc.systems import StepRules

        if not isinstance(self.step_rules, dict):
            raise ValueError(f"step_rules: expected a dict, found {self.step_rules!r}")
        try:
            StepRules(**self.step_rules)
        except TypeError as error:
            raise ValueError(f"step_rules: {error}") from error
        if self.learning_starts < 0:
            raise ValueError(f"learning_starts: expected >= 0, found {self.learning_starts}")
        setting = training_setting(self.training_perturbations, self.system)
        object.__setattr__(self, "training_perturbations", setting)
        self._check_authors_fields()
        self._check_algo_fields()
        self._check_selection_plants()

    def _check_selection_plants(self) -> None:
        """``selection_plants``: one of :data:`leoc.names.SELECTION_PLANTS`; ``"training"``
        needs a model selection and randomised training perturbations to draw from."""
        if self.selection_plants not in SELECTION_PLANTS:
            raise ValueError(
                f"selection_plants: expected one of {SELECTION_PLANTS}, found "
                f"{self.selection_plants!r}"
            )
        if self.selection_plants == "nominal":
            return
        if self.model_selection == "final":
            raise ValueError(
                "selection_plants: expected 'nominal' with model_selection='final' (nothing is "
                "selected), found 'training'"
            )
        if not self.training_perturbations.get("randomised"):
            raise ValueError(
                "selection_plants: expected 'training' only with randomised training "
                "perturbations (leoc train --randomise: the distribution the selection plants "
                f"are drawn from), found {self.training_perturbations or 'the nominal plant'}"
            )

    def _check_algo_fields(self) -> None:
        """Fields of another algorithm keep their defaults; SAC's own fields are valid."""
        defaults = {field.name: field.default for field in dataclasses.fields(self)}
        foreign = TD3_FAMILY_FIELDS if self.algo == "sac" else SAC_FIELDS
        for name in foreign:
            if getattr(self, name) != defaults[name]:
                users = "DDPG and TD3 use" if self.algo == "sac" else "SAC uses"
                raise ValueError(
                    f"{name}: only {users} it, so algo={self.algo!r} needs its default "
                    f"{defaults[name]!r}; found {getattr(self, name)!r}"
                )
        if self.algo == "sac" and not self.sac_action_noise:
            for name in OU_FIELDS:
                if getattr(self, name) != defaults[name]:
                    raise ValueError(
                        f"{name}: SAC uses the OU exploration only with sac_action_noise=True, "
                        f"so it needs its default {defaults[name]!r}; found {getattr(self, name)!r}"
                    )
        if not isinstance(self.sac_action_noise, bool):
            raise ValueError(f"sac_action_noise: expected a bool, found {self.sac_action_noise!r}")
        _check_entropy_coef(self.sac_entropy_coef)
        target = self.sac_target_entropy
        if target != AUTO and (
            isinstance(target, bool)
            or not isinstance(target, (int, float))
            or not math.isfinite(target)
        ):
            raise ValueError(
                f"sac_target_entropy: expected 'auto' or a finite number, found {target!r}"
            )

    def _check_authors_fields(self) -> None:
        """Validate the fields whose alternative values follow the authors' code."""
        choices = {
            "noise_units": NOISE_UNITS,
            "warmup": WARMUPS,
            "critic_loss": CRITIC_LOSSES,
            "critic_action_units": CRITIC_ACTION_UNITS,
            "hidden_init": HIDDEN_INITS,
            "model_selection": MODEL_SELECTIONS,
        }
        for name, allowed in choices.items():
            if getattr(self, name) not in allowed:
                raise ValueError(
                    f"{name}: expected one of {allowed}, found {getattr(self, name)!r}"
                )
        for name in ("noise_reset", "actor_output_clip"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"{name}: expected a bool, found {getattr(self, name)!r}")
        if not self.ou_theta > 0 or not self.ou_sigma >= 0:
            raise ValueError(
                f"ou_theta, ou_sigma: expected theta > 0 and sigma >= 0, found "
                f"{self.ou_theta!r}, {self.ou_sigma!r}"
            )
        layer = self.critic_action_layer
        if isinstance(layer, bool) or not isinstance(layer, int):
            raise ValueError(f"critic_action_layer: expected an int, found {layer!r}")
        if not 0 <= layer <= len(self.critic_hidden):
            raise ValueError(
                f"critic_action_layer: expected 0 <= layer <= {len(self.critic_hidden)} (the "
                f"critic's hidden layers {list(self.critic_hidden)}), found {layer}"
            )
        value = self.last_layer_init
        if value is not None and (
            isinstance(value, bool) or not isinstance(value, (int, float)) or not value > 0
        ):
            raise ValueError(
                f"last_layer_init: expected a positive number or None, found {value!r}"
            )

    @classmethod
    def for_system(cls, name: str, algo: str = "ddpg", **overrides: Any) -> DDPGConfig:
        """The paper's defaults for system ``name`` and ``algo``, with ``overrides`` applied.

        Per-system defaults: ``total_steps`` (:data:`TOTAL_STEPS_BY_SYSTEM`: 10k for the
        pendulum, 20k for the cart-pole and the mountain car; SAC's budgets are DDPG's),
        ``eval_interval`` (:data:`EVAL_INTERVAL_BY_SYSTEM`) and ``step_rules``
        (:data:`STEP_RULES_BY_SYSTEM`; an override replaces them whole, so
        ``step_rules={}`` is leoc's rules). ``algo="sac"`` starts from :data:`SAC_DEFAULTS`
        (the overrides still win). The hold test is the system's own (``System.hold_step``).
        ``hybrid`` (None, True, a :class:`~leoc.policies.HybridSpec` or its dict) makes the
        hybrid; an override that names a ``HybridSpec`` field (``relevance="roa"``,
        ``learn_lambda=False``) changes that spec, and is dropped for a baseline
        (:func:`leoc.policies.spec.with_hybrid_overrides`).

        Raises
        ------
        ValueError
            On an unknown system, algorithm or override name, or an invalid value.
        """
        overrides = dict(overrides)
        hybrid = with_hybrid_overrides(overrides.pop("hybrid", None), overrides)
        fields = {field.name for field in dataclasses.fields(cls)}
        unknown = set(overrides) - fields
        if unknown:
            raise ValueError(
                f"overrides: unknown DDPGConfig fields {sorted(unknown)}; "
                f"expected some of {sorted(fields - {'system', 'algo'})} or of the hybrid's "
                f"{list(HybridSpec.field_names())}"
            )
        values: dict[str, Any] = {
            "total_steps": TOTAL_STEPS_BY_SYSTEM.get(name, DEFAULT_TOTAL_STEPS),
            "step_rules": dict(STEP_RULES_BY_SYSTEM.get(name, {})),
            **(SAC_DEFAULTS if algo == "sac" else {}),
        }
        if name in EVAL_INTERVAL_BY_SYSTEM:
            values["eval_interval"] = EVAL_INTERVAL_BY_SYSTEM[name]
        values.update(overrides)
        for key in ("actor_hidden", "critic_hidden"):
            if key in values:
                values[key] = tuple(int(width) for width in values[key])
        return cls(system=name, algo=algo, hybrid=hybrid, **values)

    def network_kwargs(self) -> dict[str, Any]:
        """The critic layout and the networks' initialisation of this config, as keywords of
        the policies (:class:`~leoc.sb3.common.NetworkOptionsMixin`: DDPG, TD3 and SAC)."""
        return {
            "critic_action_layer": self.critic_action_layer,
            "critic_action_units": self.critic_action_units,
            "hidden_init": self.hidden_init,
            "last_layer_init": self.last_layer_init,
        }

    def as_dict(self) -> dict[str, Any]:
        """JSON-friendly dict (tuples become lists; ``training_perturbations`` only when not
        empty)."""
        data = dataclasses.asdict(self)
        for key, value in data.items():
            if isinstance(value, tuple):
                data[key] = list(value)
        data["hybrid"] = None if self.hybrid is None else self.hybrid.to_dict()
        if not self.training_perturbations:  # a nominal run's config is as it always was
            del data["training_perturbations"]
        if self.selection_plants == "nominal":  # as every run before the field
            del data["selection_plants"]
        return data

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> DDPGConfig:
        """Inverse of :meth:`as_dict` (unknown keys such as ``seed`` are ignored; a config saved
        before :class:`~leoc.policies.HybridSpec`, with ``hybrid`` a bool and the hybrid's
        fields beside it, is read into its spec)."""
        fields = {field.name for field in dataclasses.fields(cls)}
        values = {key: value for key, value in legacy_hybrid_config(data).items() if key in fields}
        for key in ("actor_hidden", "critic_hidden"):
            if key in values:
                values[key] = tuple(values[key])
        return cls(**values)


def _check_entropy_coef(value: object) -> None:
    """``sac_entropy_coef``: ``"auto"``, ``"auto_<positive float>"`` or a positive number."""
    if isinstance(value, str):
        head, _, tail = value.partition("_")
        try:
            valid = head == AUTO and (not tail or float(tail) > 0)
        except ValueError:
            valid = False
    else:
        valid = (
            not isinstance(value, bool)
            and isinstance(value, (int, float))
            and math.isfinite(value)
            and value > 0
        )
    if not valid:
        raise ValueError(
            "sac_entropy_coef: expected 'auto', 'auto_<initial value>' or a positive number, "
            f"found {value!r}"
        )
