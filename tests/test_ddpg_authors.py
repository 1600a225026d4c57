"""Tests of the authors' DDPG choices (nrjc/LEOC with TF-Agents) as DDPGConfig fields.

Each option is checked against a value computed here from the authors' formulas (TF-Agents'
OUProcess recursion, the Huber loss's closed form, TF-Agents' network shapes and initialiser
bounds, dao/trainer.py's selection rule), independently of leoc's code path; and every option's
default against SB3's own behaviour (leoc's numbers unchanged).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from stable_baselines3 import DDPG
from stable_baselines3.sac.policies import SACPolicy
from stable_baselines3.td3.policies import TD3Policy
from torch import nn

from leoc.control import design_lqr
from leoc.experiments.ablation import delivered_steps
from leoc.policies import PrecisionRelevance
from leoc.sb3 import (
    DDPGConfig,
    HybridActor,
    HybridTD3Policy,
    LearningCurveCallback,
    LeocDDPG,
    hybrid_policy_kwargs,
    physical_policy,
)
from leoc.sb3.callbacks import last_third_start, selection_key, selection_start
from leoc.sb3.common import HUBER_DELTA, SplitCritic, critic_loss_fn
from leoc.sb3.config import AUTHORS_DDPG, authors_ddpg_overrides
from leoc.sb3.noise import NOISE_SEED_OFFSET, exploration_noise
from leoc.sb3.sac import LeocSACPolicy
from leoc.sb3.td3 import LeocTD3Policy
from leoc.sb3.train import train_ddpg
from leoc.systems import StepRules, make_env, make_system
from leoc.training import Evaluation, evaluate_episodes, evaluation_starts

SMALL_NET = [32, 32]
F64_ATOL = 1e-12
F32_TOL = 1e-5
# TF-Agents' DDPG defaults as nrjc/LEOC sets them (DDPG/ddpg.py).
OU_DAMPING, OU_STDDEV = 0.2, 1.0
LAST_LAYER_LIMIT = 0.003
# OUProcess x <- (1 - damping) x + N(0, stddev^2) is AR(1): var = stddev^2 / (1 - (1-damping)^2)
AUTHORS_OU_STD = math.sqrt(OU_STDDEV**2 / (1.0 - (1.0 - OU_DAMPING) ** 2))  # 1.6667


pytestmark = pytest.mark.usefixtures("single_thread")


# ------------------------------------------------------------------------------------- config


@pytest.mark.parametrize(
    ("system", "hybrid", "total", "interval", "actor_lr"),
    [
        ("pendulum", True, 11_000, 200, 5e-4),
        ("pendulum", False, 11_000, 200, 5e-4),
        ("cartpole", True, 16_000, 300, 5e-4),
        ("cartpole", False, 16_000, 300, 1e-4),
        ("mountaincar", False, 11_000, 200, 5e-4),
    ],
)
def test_authors_overrides_follow_their_gin_files(system, hybrid, total, interval, actor_lr):
    # data/*DDPG*.gin: num_iterations 10000 / 15000 after 1000 initial collect steps,
    # eval_interval 200 / 300, actor lr 5e-4 except the cart-pole baseline's 1e-4.
    config = DDPGConfig.for_system(system, hybrid=hybrid, **authors_ddpg_overrides(system, hybrid))
    assert (config.total_steps, config.eval_interval) == (total, interval)
    assert config.actor_learning_rate == actor_lr and config.critic_learning_rate == 1e-3
    assert config.learning_starts == 1_000 and config.eval_episodes == 3
    assert (config.ou_theta, config.ou_sigma) == (OU_DAMPING, OU_STDDEV)
    assert DDPGConfig.from_dict(config.as_dict()) == config
    assert authors_ddpg_overrides(system, hybrid) is not AUTHORS_DDPG  # a fresh dict


def test_new_fields_default_to_the_ablations_choice_and_are_validated():
    """Issue 20's defaults: the authors' exploration, initial collect and critic, best_held on
    3 episodes; leoc's relevance and clipped output stay (the numbers as the issue states them,
    independent of AUTHORS_DDPG)."""
    config = DDPGConfig.for_system("pendulum")
    defaults = {
        "noise_units": "physical",
        "ou_theta": 0.2,
        "ou_sigma": 1.0,
        "noise_reset": False,
        "warmup": "policy",
        "learning_starts": 1000,
        "critic_loss": "huber",
        "critic_action_layer": 1,
        "critic_action_units": "physical",
        "hidden_init": "tf_agents",
        "last_layer_init": 0.003,
        "actor_output_clip": True,
        "model_selection": "best_held",
        "eval_episodes": 3,
    }
    assert {name: getattr(config, name) for name in defaults} == defaults
    bad = {
        "noise_units": "newtons",
        "warmup": "random",
        "critic_loss": "l1",
        "critic_action_units": "raw",
        "hidden_init": "xavier",
        "model_selection": "best",
        "critic_action_layer": 3,
        "last_layer_init": -0.1,
        "noise_reset": "no",
        "actor_output_clip": 1,
    }
    for name, value in bad.items():
        with pytest.raises(ValueError, match=name):
            DDPGConfig.for_system("pendulum", **{name: value})
    # the hybrid's fields are the HybridSpec's: checked for a hybrid and for a baseline alike
    assert DDPGConfig.for_system("pendulum", hybrid=True).hybrid.relevance_parametrisation == (
        "log_lambda"
    )
    for hybrid in (None, True):
        with pytest.raises(ValueError, match="relevance_parametrisation"):
            DDPGConfig.for_system("pendulum", hybrid=hybrid, relevance_parametrisation="lambda")


# -------------------------------------------------------------------------------------- noise


def test_physical_ou_noise_is_tf_agents_ou_process_and_never_resets():
    system = make_system("cartpole")
    env = make_env(system)
    config = DDPGConfig.for_system("cartpole", **authors_ddpg_overrides("cartpole", False))
    noise = exploration_noise(config, env.action_space, seed=4)
    half = system.action_limit
    # TF-Agents' OUProcess, written out: x_0 = 0, x <- (1 - damping) x + stddev * N(0, 1),
    # on the physical action; SB3 receives it divided by the half-width of the box.
    rng = np.random.default_rng(4 + NOISE_SEED_OFFSET)
    state = 0.0
    for step in range(50):
        if step == 20:
            noise.reset()  # SB3 calls this at an episode end: the authors' process runs on
        state = (1.0 - OU_DAMPING) * state + OU_STDDEV * rng.standard_normal()
        np.testing.assert_allclose(noise()[0] * half, state, rtol=1e-6)
    # Monte Carlo stationary std of the physical noise against the AR(1) closed form, 1.667.
    draws = np.array([noise()[0] for _ in range(60_000)])[1_000:] * half
    assert draws.std() == pytest.approx(AUTHORS_OU_STD, rel=0.04)


def test_default_noise_is_the_physical_process_that_never_resets():
    """leoc's default exploration since issue 20: x <- 0.8 x + 1.0 N(0, 1) on the physical
    action, never reset, written out; the old one (normalised, theta 0.15, sigma 0.2, reset at
    every episode end) stays an override."""
    system = make_system("pendulum")
    env = make_env(system)
    noise = exploration_noise(DDPGConfig.for_system("pendulum"), env.action_space, seed=1)
    rng = np.random.default_rng(1 + NOISE_SEED_OFFSET)
    state = 0.0
    for step in range(10):
        if step == 5:
            noise.reset()  # an episode end: the process runs on
        state = 0.8 * state + 1.0 * rng.standard_normal()
        np.testing.assert_allclose(noise()[0] * system.action_limit, state, rtol=1e-6)
    old = DDPGConfig.for_system(
        "pendulum", noise_units="normalised", ou_theta=0.15, ou_sigma=0.2, noise_reset=True
    )
    noise = exploration_noise(old, env.action_space, seed=1)
    rng = np.random.default_rng(1 + NOISE_SEED_OFFSET)
    state = 0.0
    for _ in range(10):
        state = state + 0.15 * (0.0 - state) + 0.2 * rng.standard_normal()
        assert float(noise()[0]) == np.float32(state)  # bit for bit, normalised units
    noise.reset()
    np.testing.assert_array_equal(noise.state, [0.0])


# ------------------------------------------------------------------------------------- warmup


def _ddpg(warmup: str, learning_starts: int, **kw):
    env = make_env("pendulum")
    return LeocDDPG(
        "MlpPolicy",
        env,
        learning_starts=learning_starts,
        batch_size=16,
        warmup=warmup,
        policy_kwargs={"net_arch": SMALL_NET},
        seed=0,
        device="cpu",
        **kw,
    )


def test_policy_warmup_acts_with_the_policy_and_delays_updates():
    starts = 30
    model = _ddpg("policy", starts)
    model.learn(total_timesteps=1)  # sets up the env and the last observation
    obs = model._last_obs
    action, buffer_action = model._sample_action(starts)  # no action noise: the policy itself
    expected, _ = model.predict(obs, deterministic=True)
    np.testing.assert_allclose(action, expected, rtol=0, atol=0)
    uniform = _ddpg("uniform", starts)
    uniform.learn(total_timesteps=1)
    random_action, _ = uniform._sample_action(starts)
    policy_action, _ = uniform.predict(uniform._last_obs, deterministic=True)
    assert not np.allclose(random_action, policy_action)
    # No update before learning_starts steps, then one per step (TF-Agents: initial collect,
    # then one step + one update per iteration).
    counted = _ddpg("policy", starts)
    counted.learn(total_timesteps=starts)
    assert counted._n_updates == 0
    counted.learn(total_timesteps=20, reset_num_timesteps=False)
    assert counted._n_updates == 20


# -------------------------------------------------------------------------------------- critic


def test_huber_loss_matches_closed_form():
    prediction = torch.tensor([[0.0], [1.0], [-3.0], [0.2]])
    target = torch.tensor([[0.5], [-1.0], [0.0], [0.2]])
    errors = np.array([-0.5, 2.0, -3.0, 0.0])
    # tf.compat.v1.losses.huber_loss (delta 1): 0.5 e^2 if |e| <= 1 else |e| - 0.5, mean.
    closed = np.where(
        np.abs(errors) <= HUBER_DELTA, 0.5 * errors**2, np.abs(errors) - 0.5 * HUBER_DELTA
    )
    value = critic_loss_fn("huber")(prediction, target)
    assert float(value) == pytest.approx(closed.mean(), rel=1e-7)
    assert float(critic_loss_fn("mse")(prediction, target)) == pytest.approx(np.mean(errors**2))


def _filled_pair(critic_loss: str):
    models = []
    for _ in range(2):
        model = _ddpg("uniform", 40, critic_loss=critic_loss)
        model.learn(total_timesteps=40)
        models.append(model)
    return models


def _same_parameters(first, second) -> bool:
    state_a, state_b = first.policy.state_dict(), second.policy.state_dict()
    return all(torch.equal(state_a[key], state_b[key]) for key in state_a)


def _seed_global(seed: int) -> None:
    """SB3's replay buffer samples with numpy's *global* generator; torch's draws the (zero)
    target noise."""
    np.random.seed(seed)  # noqa: NPY002 (SB3's sampling uses the legacy global generator)
    torch.manual_seed(seed)


def test_own_train_step_with_mse_is_sb3_bit_for_bit():
    sb3, own = _filled_pair("mse")
    assert _same_parameters(sb3, own)
    _seed_global(0)
    sb3.train(gradient_steps=4, batch_size=16)
    _seed_global(0)
    own.policy.set_training_mode(True)
    for _ in range(4):
        own._train_step(16, critic_loss_fn("mse"))
    assert _same_parameters(sb3, own)
    # and the Huber loss changes the critic
    huber, reference = _filled_pair("huber")
    _seed_global(0)
    huber.train(gradient_steps=2, batch_size=16)
    _seed_global(0)
    reference._train_step(16, critic_loss_fn("mse"))
    reference._train_step(16, critic_loss_fn("mse"))
    assert not _same_parameters(huber, reference)


def test_split_critic_layers_and_physical_action_after_first_layer():
    system = make_system("cartpole")
    env = make_env(system)
    policy = LeocTD3Policy(
        env.observation_space,
        env.action_space,
        lambda _: 1e-3,
        net_arch=[400, 300],
        n_critics=1,
        critic_action_layer=1,
        critic_action_units="physical",
    )
    critic = policy.critic
    assert isinstance(critic, SplitCritic)
    linears = [m for m in critic.q_networks[0].modules() if isinstance(m, nn.Linear)]
    # TF-Agents CriticNetwork(observation_fc_layer_params=(400,), joint_fc_layer_params=(300,)):
    # obs (5) -> 400 -> concat(action (1)) -> 300 -> 1
    shapes = [(layer.in_features, layer.out_features) for layer in linears]
    assert shapes == [(5, 400), (401, 300), (300, 1)]
    generator = torch.Generator().manual_seed(0)
    obs = torch.randn(8, 5, generator=generator)
    action = 2.0 * torch.rand(8, 1, generator=generator) - 1.0  # normalised, as SB3 stores it
    with torch.no_grad():
        first, joint, out = linears
        hidden = torch.relu(first(obs))  # the action does not enter the first layer
        physical = action * system.action_limit
        expected = out(torch.relu(joint(torch.cat([hidden, physical], dim=1))))
        q_value = critic(obs, action)[0]
    torch.testing.assert_close(q_value, expected, rtol=1e-6, atol=1e-6)
    torch.testing.assert_close(critic.q1_forward(obs, action), expected, rtol=1e-6, atol=1e-6)


@pytest.mark.parametrize(
    "policy_classes", [(TD3Policy, LeocTD3Policy), (SACPolicy, LeocSACPolicy)], ids=["td3", "sac"]
)
def test_default_leoc_policy_is_sb3s_policy_bit_for_bit(policy_classes):
    env = make_env("mountaincar")
    states = []
    for policy_class in policy_classes:
        torch.manual_seed(3)
        policy = policy_class(env.observation_space, env.action_space, lambda _: 1e-3, SMALL_NET)
        states.append(policy.state_dict())
    assert states[0].keys() == states[1].keys()
    assert all(torch.equal(states[0][key], states[1][key]) for key in states[0])


# ----------------------------------------------------------------------------- initialisation


def _check_tf_agents_init(module: nn.Module) -> None:
    linears = [m for m in module.modules() if isinstance(m, nn.Linear)]
    for layer in linears[:-1]:
        # VarianceScaling(1/3, fan_in, uniform): limit sqrt(3 * (1/3) / fan_in)
        limit = math.sqrt(3.0 * (1.0 / 3.0) / layer.in_features)
        weights = layer.weight.detach().abs()
        assert float(weights.max()) <= limit and float(weights.max()) > 0.9 * limit
        assert torch.equal(layer.bias.detach(), torch.zeros_like(layer.bias))
    last = linears[-1]
    assert float(last.weight.detach().abs().max()) <= LAST_LAYER_LIMIT
    assert torch.equal(last.bias.detach(), torch.zeros_like(last.bias))


@pytest.mark.parametrize("hybrid", [False, True])
def test_tf_agents_initialisation_of_actor_and_critic(hybrid):
    env = make_env("pendulum")
    options = {"hidden_init": "tf_agents", "last_layer_init": LAST_LAYER_LIMIT}
    kwargs = {"net_arch": [400, 300], "critic_action_layer": 1, **options}
    if hybrid:
        kwargs = hybrid_policy_kwargs("pendulum", **kwargs)
    policy_class = HybridTD3Policy if hybrid else LeocTD3Policy
    model = DDPG(policy_class, env, policy_kwargs=kwargs, seed=0, device="cpu")
    mlp = model.actor.nonlinear if hybrid else model.actor.mu
    _check_tf_agents_init(mlp)
    _check_tf_agents_init(model.critic.q_networks[0])
    # targets start as copies
    for key, value in model.critic.state_dict().items():
        torch.testing.assert_close(model.critic_target.state_dict()[key], value, rtol=0, atol=0)


# -------------------------------------------------------------------------- relevance (S)


def _precision_model(system_name: str, **kw):
    env = make_env(system_name)
    kwargs = hybrid_policy_kwargs(
        system_name, relevance_parametrisation="precision", net_arch=SMALL_NET, **kw
    )
    return DDPG(HybridTD3Policy, env, policy_kwargs=kwargs, seed=0, device="cpu")


@pytest.mark.parametrize("system_name", ["pendulum", "cartpole", "mountaincar"])
def test_precision_relevance_keeps_identities_and_formula(system_name):
    system = make_system(system_name)
    design = design_lqr(system)
    model = _precision_model(system_name, hidden_init="tf_agents", last_layer_init=LAST_LAYER_LIMIT)
    relevance = model.actor.hybrid.relevance_module
    assert isinstance(relevance, PrecisionRelevance)
    torch.testing.assert_close(relevance.precision, torch.ones(system.obs_dim))  # S = [1.] * D
    generator = torch.Generator().manual_seed(5)
    with torch.no_grad():  # random H and an S with mixed signs (the authors' S is unconstrained)
        for param in model.actor.hybrid.nonlinear.parameters():
            param.copy_(torch.randn(param.shape, generator=generator))
        precision = torch.rand(system.obs_dim, generator=generator) + 0.1
        precision[0] = -0.05
        relevance.precision.copy_(precision)
    policy = physical_policy(model.actor)
    point = torch.as_tensor(system.operating_obs, dtype=torch.float64)
    value = policy(point[None])[0]
    np.testing.assert_allclose(
        value.numpy(), design.W @ system.operating_obs + design.b, rtol=0, atol=F64_ATOL
    )
    jacobian = torch.autograd.functional.jacobian(lambda x: policy(x[None])[0], point)
    np.testing.assert_allclose(jacobian.numpy(), design.W, rtol=0, atol=F64_ATOL)
    # r = 1 / (1 + sum_i S_i (x_i - a_i)^2)^2, written out (DDPG/ddpg.py compute_ratio)
    obs = point + 0.3 * torch.randn(16, system.obs_dim, generator=generator, dtype=torch.float64)
    distance = ((obs - point) ** 2 * precision.double()).sum(dim=1, keepdim=True)
    expected = 1.0 / (distance + 1.0) ** 2
    torch.testing.assert_close(policy.relevance(obs), expected, rtol=1e-6, atol=1e-9)
    with torch.no_grad():
        inside = model.actor(obs.float()).double() * system.action_limit
    torch.testing.assert_close(inside, policy(obs), rtol=F32_TOL, atol=F32_TOL)


def test_unclipped_actor_returns_the_blend_and_keeps_identities():
    system = make_system("cartpole")
    design = design_lqr(system)
    clipped, unclipped = (
        _precision_model("cartpole", clip_output=flag).actor for flag in (True, False)
    )
    unclipped.load_state_dict(clipped.state_dict())
    generator = torch.Generator().manual_seed(2)
    with torch.no_grad():
        for actor in (clipped, unclipped):
            for param in actor.hybrid.nonlinear.parameters():
                param.copy_(torch.randn(param.shape, generator=torch.Generator().manual_seed(9)))
        obs = 3.0 * torch.randn(256, system.obs_dim, generator=generator)
        blend = unclipped(obs)  # r G~ + (1 - r) tanh(MLP), unbounded (TF-Agents' actor)
        assert float(blend.abs().max()) > 1.0
        torch.testing.assert_close(clipped(obs), blend.clamp(-1.0, 1.0), rtol=0, atol=0)
    policy = physical_policy(unclipped)  # the executed action is clipped all the same
    assert float(policy(obs.double()).abs().max()) <= system.action_limit
    point = torch.as_tensor(system.operating_obs, dtype=torch.float64)
    jacobian = torch.autograd.functional.jacobian(lambda x: policy(x[None])[0], point)
    np.testing.assert_allclose(jacobian.numpy(), design.W, rtol=0, atol=F64_ATOL)
    assert unclipped._get_constructor_parameters()["clip_output"] is False


def test_precision_is_trained_and_round_trips(tmp_path):
    model = _precision_model("pendulum")
    names = {name for name, _ in model.actor.named_parameters()}
    assert "hybrid.relevance_module.precision" in names
    angles = torch.linspace(0.3, 1.2, 16)
    obs = torch.stack([torch.cos(angles), torch.sin(angles), 0.5 * torch.ones(16)], dim=1)
    model.actor.optimizer.zero_grad()
    (-model.critic.q1_forward(obs, model.actor(obs)).mean()).backward()
    grad = model.actor.hybrid.relevance_module.precision.grad
    assert grad is not None and float(grad.abs().sum()) > 0
    model.save(tmp_path / "precision.zip")
    loaded = DDPG.load(tmp_path / "precision.zip", device="cpu")
    assert isinstance(loaded.actor, HybridActor)
    assert isinstance(loaded.actor.hybrid.relevance_module, PrecisionRelevance)
    with torch.no_grad():
        torch.testing.assert_close(loaded.actor(obs), model.actor(obs), rtol=0, atol=0)


# ---------------------------------------------------------------------------- model selection


class _StubModel:
    def __init__(self) -> None:
        self.actor = nn.Linear(1, 1, bias=False)


def _evaluation(mean_return: float, held: float, episodes: int = 3) -> Evaluation:
    """An evaluation of ``episodes`` episodes, the first ``round(held * episodes)`` held."""
    n_held = round(held * episodes)
    hold_steps = [10] * n_held + [None] * (episodes - n_held)
    return Evaluation(mean_return, 0.0, [mean_return] * episodes, hold_steps)


def test_best_of_last_third_picks_the_authors_checkpoint():
    total, starts, interval = 11_000, 1_000, 200
    callback = LearningCurveCallback(
        None,
        np.zeros((1, 1)),
        interval,
        progress=False,
        model_selection="best_last_third",
        selection_start=last_third_start(total, starts),
    )
    callback.model = _StubModel()
    steps = list(range(0, total + 1, interval))
    rng = np.random.default_rng(0)
    returns = {step: float(rng.uniform(-900.0, -200.0)) for step in steps}
    returns[5_000] = -10.0  # the best overall, before the window: ignored
    returns[8_200] = -150.0  # the best in the window...
    returns[9_400] = -150.0  # ...tied later: the earlier one is kept (strict improvement)
    for step in steps:
        with torch.no_grad():
            callback.model.actor.weight.fill_(step)  # the actor "at" this evaluation
        callback._consider_for_selection(step, _evaluation(returns[step], held=0.0))
    # dao/trainer.py written out: evaluation at iteration i = step - 1000 is a candidate when
    # i > int(num_iterations / 3 * 2); the saved policy is the first strict maximum.
    iterations = total - starts
    candidates = [s for s in steps if s - starts > int(iterations / 3 * 2)]
    best = max(candidates, key=lambda s: (returns[s], -s))
    assert best == 8_200 and callback.selected_steps == best
    callback.restore_selected()
    assert float(callback.model.actor.weight.detach()) == float(best)


def test_best_held_prefers_holding_to_return_over_the_whole_run():
    callback = LearningCurveCallback(
        None,
        np.zeros((1, 1)),
        100,
        progress=False,
        model_selection="best_held",
        selection_start=selection_start("best_held", 1200, 300),
    )
    callback.model = _StubModel()
    # step: (mean return, held share of 3 episodes); 300 holds all three early (before the
    # last third), 600 has the best return but drops an episode, 900 ties 300 later
    history = {
        0: (-900.0, 0.0),
        300: (-120.0, 1.0),
        600: (-50.0, 2 / 3),
        900: (-120.0, 1.0),
        1200: (-400.0, 1 / 3),
    }
    for step, (value, held) in history.items():
        with torch.no_grad():
            callback.model.actor.weight.fill_(step)
        callback._consider_for_selection(step, _evaluation(value, held))
    expected = max(history, key=lambda s: (history[s][1], history[s][0], -s))
    assert expected == 300 and callback.selected_steps == 300
    callback.restore_selected()
    assert float(callback.model.actor.weight.detach()) == 300.0
    # the ablation's re-selection applies the same rule to recorded evaluations
    steps = list(history)
    values = [history[s][0] for s in steps]
    held = [history[s][1] for s in steps]
    assert delivered_steps(steps, values, 1200, "best_held", 300, held) == 300
    assert delivered_steps(steps, values, 1200, "best_last_third", 300, held) == 1200
    assert delivered_steps(steps, values, 600, "best_held", 300, held) == 300


def test_selection_rules_reject_unknown_names():
    with pytest.raises(ValueError, match="model_selection"):
        selection_key("best", -1.0, 1.0)
    with pytest.raises(ValueError, match="model_selection"):
        LearningCurveCallback(None, np.zeros((1, 1)), 100, model_selection="best_return")
    with pytest.raises(ValueError, match="held_fractions"):
        delivered_steps([0, 100], [-1.0, -2.0], 100, "best_held", 0)


def test_final_selection_keeps_the_last_actor():
    callback = LearningCurveCallback(None, np.zeros((1, 1)), 100, progress=False)
    callback.model = _StubModel()
    with torch.no_grad():
        callback.model.actor.weight.fill_(7.0)
    callback._consider_for_selection(900, _evaluation(0.0, held=1.0))
    callback.restore_selected()
    assert callback.selected_steps is None
    assert float(callback.model.actor.weight.detach()) == 7.0


# A run of a few hundred steps with small networks: enough evaluations to select among.
TINY_SELECTING_RUN = {
    "total_steps": 300,
    "learning_starts": 100,
    "eval_interval": 50,
    "actor_hidden": (16, 16),
    "critic_hidden": (16, 16),
}


def test_tiny_authors_run_returns_the_selected_controller(tmp_path):
    overrides = authors_ddpg_overrides("mountaincar", hybrid=True)
    tiny = {**TINY_SELECTING_RUN, "eval_episodes": 1}
    result = train_ddpg(
        "mountaincar",
        hybrid=True,
        seed=2,
        run_dir=tmp_path,
        progress=False,
        **{**overrides, **tiny},
    )
    assert result.summary["model_selection"] == "best_last_third"
    window = [row for row in result.curve if row["steps"] > 100 + int(200 * 2 / 3)]
    best = max(window, key=lambda row: (row["mean_return"], -row["steps"]))
    assert result.summary["selected_steps"] == best["steps"]
    # the run evaluates under its own rules (leoc's default on the mountain car: the reward
    # of the next state)
    rules = StepRules(**result.config["step_rules"])
    assert rules.reward_on_next_state
    system = make_system("mountaincar").with_rules(rules)
    replay = evaluate_episodes(system, result.policy, evaluation_starts(system, 2, 1))
    assert replay.mean_return == best["mean_return"]  # the returned controller is that actor
    assert isinstance(result.model.critic, SplitCritic)


def test_tiny_best_held_run_returns_the_selected_controller(tmp_path):
    tiny = {**TINY_SELECTING_RUN, "eval_episodes": 2, "model_selection": "best_held"}
    result = train_ddpg("pendulum", hybrid=True, seed=3, run_dir=tmp_path, progress=False, **tiny)
    best = max(
        result.curve, key=lambda row: (row["held_fraction"], row["mean_return"], -row["steps"])
    )
    assert result.summary["selected_steps"] == best["steps"]
    system = make_system("pendulum")
    replay = evaluate_episodes(system, result.policy, evaluation_starts(system, 3, 2))
    assert replay.mean_return == best["mean_return"]  # the returned controller is that actor
    assert replay.held_fraction == best["held_fraction"]
