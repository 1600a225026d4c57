"""Tests of leoc.sb3: the LEOC hybrid actor inside Stable-Baselines3's DDPG and TD3.

References are independent of the code under test: the LQR design recomputed with
``design_lqr``, the blend recomputed from its formula, autograd Jacobians, closed forms.
"""

from __future__ import annotations

import base64
import importlib.util
import io
import json
import math
import subprocess
import sys
import tempfile
import zipfile

import numpy as np
import pytest
import torch
from gymnasium import spaces
from stable_baselines3 import DDPG, TD3
from stable_baselines3.common.torch_layers import FlattenExtractor

from leoc.control import design_lqr
from leoc.policies import FlooredRelevance, HybridDesign, HybridSpec
from leoc.sb3 import (
    DDPGConfig,
    HybridActor,
    HybridTD3Policy,
    LeocDDPG,
    LeocTD3,
    SeededOUNoise,
    build_model,
    held_and_reached,
    hybrid_policy_kwargs,
    load_ddpg_controller,
    physical_policy,
    train_ddpg,
)
from leoc.systems import SYSTEM_NAMES, StepRules, make_env, make_system
from leoc.training import CURVE_COLUMNS

SMALL_NET = [32, 32]
F64_ATOL = 1e-12
F32_RTOL = 1e-5
F32_ATOL = 1e-5
# A tiny but complete training run (seconds, not minutes).
TINY_RUN = {
    "total_steps": 240,
    "learning_starts": 60,
    "actor_hidden": (16, 16),
    "critic_hidden": (16, 16),
    "eval_interval": 120,
    "eval_episodes": 1,
    "progress": False,
}


pytestmark = pytest.mark.usefixtures("single_thread")

#: The hybrid's relevance, as HybridSpec fields: "paper", the paper's r = (1 + d)^-2 as
#: published (``log_lambda`` on the HybridPolicy itself; leoc's default before issue 40);
#: "default", leoc's default HybridSpec() since issue 40, r = (1 + d^2)^-2 with Lambda floored
#: (FlooredRelevance: lambda = floor (1 + e^q), q its ``log_excess``) so that r >= 0.5 on the
#: LQR's proved region of attraction.
RELEVANCE_FIELDS = {"paper": {"r_min": None, "relevance_power": 1.0}, "default": {}}
RELEVANCES = tuple(RELEVANCE_FIELDS)
#: The parameter Lambda is learned through, by relevance.
RELEVANCE_PARAMETER = {
    "paper": "hybrid.log_lambda",
    "default": "hybrid.relevance_module.log_excess",
}


def _hybrid_model(
    system_name: str,
    algo=DDPG,
    learn_lambda: bool = True,
    seed: int = 0,
    relevance: str = "paper",
    **kw,
):
    env = make_env(system_name)
    policy_kwargs = hybrid_policy_kwargs(
        system_name, learn_lambda=learn_lambda, net_arch=SMALL_NET, **RELEVANCE_FIELDS[relevance]
    )
    model = algo(HybridTD3Policy, env, policy_kwargs=policy_kwargs, seed=seed, device="cpu", **kw)
    _check_relevance(model.actor, relevance)
    return model


def _check_relevance(actor: HybridActor, relevance: str) -> None:
    """The actor holds the relevance its label names: the paper's on the HybridPolicy itself,
    or the floored p = 2 one on the floor its design resolved from the LQR's certificate."""
    module = actor.hybrid.relevance_module
    if relevance == "paper":
        assert module is None
        return
    assert isinstance(module, FlooredRelevance) and module.power == 2.0
    floor = actor.hybrid_design.relevance_data["lambda_floor"]
    np.testing.assert_allclose(module.floor.double().numpy(), floor, rtol=1e-7, atol=0)


def _relevance_parameter(actor: HybridActor) -> torch.Tensor:
    """The tensor Lambda is held by: the paper's ``log_lambda`` or the floor's excess q."""
    module = actor.hybrid.relevance_module
    return actor.hybrid.log_lambda if module is None else module.log_excess


def _lambda(actor: HybridActor, relevance: str) -> torch.Tensor:
    """Lambda's diagonal in float64, from its parameter by the relevance's definition:
    exp(log_lambda), or floor * (1 + exp(q)) for the floored relevance."""
    if relevance == "paper":
        return torch.exp(actor.hybrid.log_lambda.detach().double())
    module = actor.hybrid.relevance_module
    return module.floor.double() * (1.0 + torch.exp(module.log_excess.detach().double()))


#: p of r = (1 + d^p)^-2, by relevance.
RELEVANCE_POWER = {"paper": 1, "default": 2}


def _reference_relevance(actor: HybridActor, relevance: str, obs: torch.Tensor, point):
    """r(obs) from its formula: the paper's (1 + d)^-2, the default's (1 + d^2)^-2, with
    d = sum((obs - a)^2 / lambda)."""
    distance = ((obs - point) ** 2 / _lambda(actor, relevance)).sum(dim=1, keepdim=True)
    return 1.0 / (1.0 + distance ** RELEVANCE_POWER[relevance]) ** 2


def _randomise(actor: HybridActor, generator: torch.Generator) -> None:
    """Random H (MLP weights far from their initialisation) and random positive Lambda (its
    parameter: log_lambda, or the floored relevance's excess q)."""
    with torch.no_grad():
        for param in actor.hybrid.nonlinear.parameters():
            param.copy_(torch.randn(param.shape, generator=generator))
        parameter = _relevance_parameter(actor)
        parameter.copy_(torch.randn(parameter.shape, generator=generator))


@pytest.mark.slow
@pytest.mark.parametrize(
    ("system_name", "relevance"),
    [(name, "paper") for name in SYSTEM_NAMES] + [(name, "default") for name in SYSTEM_NAMES],
)
def test_identity_at_operating_point_in_physical_units(system_name, relevance):
    system = make_system(system_name)
    design = design_lqr(system)  # independent reference for G(x) = W x + b
    model = _hybrid_model(system_name, relevance=relevance)
    _randomise(model.actor, torch.Generator().manual_seed(7))
    policy = physical_policy(model.actor)
    point = torch.as_tensor(system.operating_obs, dtype=torch.float64)

    value = policy(point[None, :])[0]
    expected = design.W @ system.operating_obs + design.b
    np.testing.assert_allclose(value.numpy(), expected, rtol=0, atol=F64_ATOL)

    jacobian = torch.autograd.functional.jacobian(lambda x: policy(x[None, :])[0], point)
    np.testing.assert_allclose(jacobian.numpy(), design.W, rtol=0, atol=F64_ATOL)

    # The float32 actor inside SB3 has the same identities in normalised units u / u_max.
    limit = system.action_limit
    point32 = point.float()
    actor_value = model.actor(point32[None, :])[0].detach().double() * limit
    np.testing.assert_allclose(actor_value.numpy(), expected, rtol=F32_RTOL, atol=F32_ATOL)
    actor_jac = torch.autograd.functional.jacobian(lambda x: model.actor(x[None, :])[0], point32)
    np.testing.assert_allclose(
        actor_jac.double().numpy() * limit, design.W, rtol=F32_RTOL, atol=F32_ATOL
    )


@pytest.mark.slow
@pytest.mark.parametrize("algo", ["ddpg", "td3", "sac"])
@pytest.mark.parametrize("system_name", SYSTEM_NAMES)
def test_identities_hold_in_the_model_leocs_defaults_build(algo, system_name):
    """The hybrid the trainer builds from leoc's defaults (issue 20: TF-Agents' initialisation,
    output layers U(+/-0.003), the critic with the action after its first layer; SAC's own)
    keeps pi(a) = G(a) and d pi/dx (a) = W, with every actor parameter moved far from its
    initialisation."""
    system = make_system(system_name)
    design = design_lqr(system)  # independent reference for G(x) = W x + b
    config = DDPGConfig.for_system(
        system_name, algo, hybrid=True, actor_hidden=(16, 16), critic_hidden=(16, 16)
    )
    init = (config.hidden_init, config.last_layer_init)
    assert init == (("torch", None) if algo == "sac" else ("tf_agents", 0.003))  # SAC: SB3's
    model = build_model(config, seed=0, env=make_env(system))
    generator = torch.Generator().manual_seed(13)
    with torch.no_grad():
        for param in model.actor.parameters():  # H's weights, Lambda's parameter, SAC's heads
            param.add_(torch.randn(param.shape, generator=generator))
    policy = physical_policy(model.actor)
    point = torch.as_tensor(system.operating_obs, dtype=torch.float64)
    expected = design.W @ system.operating_obs + design.b
    value = policy(point[None, :])[0]
    np.testing.assert_allclose(value.detach().numpy(), expected, rtol=0, atol=F64_ATOL)
    jacobian = torch.autograd.functional.jacobian(lambda x: policy(x[None, :])[0], point)
    np.testing.assert_allclose(jacobian.numpy(), design.W, rtol=0, atol=1e-10)
    away = point + 0.7  # and the learned part acts away from a (the identities are not a tie)
    assert not np.allclose(
        policy(away[None, :])[0].detach().numpy(), design.W @ away.numpy() + design.b
    )


@pytest.mark.parametrize("kind", RELEVANCES)
def test_blend_away_from_operating_point_matches_formula(kind):
    system = make_system("cartpole")
    design = design_lqr(system)
    model = _hybrid_model("cartpole", relevance=kind)
    generator = torch.Generator().manual_seed(3)
    _randomise(model.actor, generator)
    obs = torch.randn(64, system.obs_dim, generator=generator, dtype=torch.float64)
    point = torch.as_tensor(system.operating_obs)
    relevance = _reference_relevance(model.actor, kind, obs, point)
    linear = obs @ torch.as_tensor(design.W).T + torch.as_tensor(design.b)
    with torch.no_grad():
        mlp_out = model.actor.hybrid.nonlinear(obs.float()).double()  # tanh(MLP), normalised
        expected = (relevance * linear + (1 - relevance) * system.action_limit * mlp_out).clamp(
            -system.action_limit, system.action_limit
        )
        physical = physical_policy(model.actor)(obs)
        inside_sb3 = model.actor(obs.float()).double() * system.action_limit
    np.testing.assert_allclose(physical.numpy(), expected.numpy(), rtol=F32_RTOL, atol=F32_ATOL)
    np.testing.assert_allclose(inside_sb3.numpy(), expected.numpy(), rtol=F32_RTOL, atol=F32_ATOL)
    assert float((expected.abs() >= system.action_limit - 1e-9).float().mean()) > 0  # clip used


@pytest.mark.parametrize("relevance", RELEVANCES)
def test_fused_actor_forward_equals_hybrid_policy(relevance):
    model = _hybrid_model("mountaincar", relevance=relevance)
    generator = torch.Generator().manual_seed(11)
    _randomise(model.actor, generator)
    obs = 2.0 * torch.randn(128, 2, generator=generator)
    with torch.no_grad():
        reference = model.actor.hybrid(obs)  # leoc.policies.HybridPolicy, clip saturation
        fused = model.actor(obs)
    np.testing.assert_allclose(fused.numpy(), reference.numpy(), rtol=1e-6, atol=1e-6)


#: A floor on Lambda for a hand-made design (any positive floor keeps the identities; the
#: LQR's certificate is not under test here).
HAND_MADE_FLOOR = [0.2, 1.5, 0.4]


@pytest.mark.parametrize("relevance", RELEVANCES)
def test_identity_with_asymmetric_action_box(relevance):
    obs_space = spaces.Box(-np.inf, np.inf, shape=(3,), dtype=np.float64)
    act_space = spaces.Box(
        np.array([-1.0, 0.5], dtype=np.float32), np.array([3.0, 2.5], dtype=np.float32)
    )
    rng = np.random.default_rng(0)
    gain = rng.normal(size=(2, 3))
    point = rng.normal(size=3)
    bias = np.array([1.2, 1.4]) - gain @ point  # G(a) strictly inside the box
    spec = HybridSpec(lambda_init=(0.3, 2.0, 0.7), **RELEVANCE_FIELDS[relevance])
    data = {} if relevance == "paper" else {"lambda_floor": HAND_MADE_FLOOR}

    def actor_of(design: HybridDesign) -> HybridActor:
        space = FlattenExtractor(obs_space)
        return HybridActor(
            obs_space, act_space, SMALL_NET, space, 3, hybrid_spec=spec, hybrid_design=design
        )

    if relevance == "default":  # the floor comes with the design (hybrid_design resolves it)
        with pytest.raises(ValueError, match="r_min: expected the design's relevance_data"):
            actor_of(HybridDesign(gain, bias, point))
    actor = actor_of(HybridDesign(gain, bias, point, data))
    _check_relevance(actor, relevance)
    _randomise(actor, torch.Generator().manual_seed(1))
    policy = physical_policy(actor)
    point_t = torch.as_tensor(point)
    np.testing.assert_allclose(
        policy(point_t[None, :])[0].numpy(), gain @ point + bias, rtol=0, atol=F64_ATOL
    )
    jacobian = torch.autograd.functional.jacobian(lambda x: policy(x[None, :])[0], point_t)
    np.testing.assert_allclose(jacobian.numpy(), gain, rtol=0, atol=F64_ATOL)
    far = policy(torch.full((1, 3), 50.0, dtype=torch.float64))[0].numpy()
    assert np.all(far >= act_space.low - 1e-12) and np.all(far <= act_space.high + 1e-12)


@pytest.mark.parametrize("relevance", RELEVANCES)
@pytest.mark.parametrize("algo", [DDPG, TD3])
def test_target_actor_is_hybrid_and_matches(algo, relevance):
    model = _hybrid_model("pendulum", algo=algo, relevance=relevance)
    assert isinstance(model.actor, HybridActor)
    assert isinstance(model.actor_target, HybridActor)
    assert model.actor_target is not model.actor
    for key, value in model.actor.state_dict().items():
        torch.testing.assert_close(model.actor_target.state_dict()[key], value, rtol=0, atol=0)
    names = {name for name, _ in model.actor.named_parameters()}
    assert RELEVANCE_PARAMETER[relevance] in names
    fixed = ("linear.W", "linear.b", "operating_point", "floor")
    assert not any(name.endswith(fixed) for name in names)
    buffers = {name for name, _ in model.actor.named_buffers()}
    assert {"hybrid.linear.W", "hybrid.linear.b", "hybrid.operating_point"} <= buffers
    if relevance == "default":
        module = ("hybrid.relevance_module.floor", "hybrid.relevance_module.operating_point")
        assert set(module) <= buffers


def _actor_loss_grads(model, obs: torch.Tensor) -> dict[str, torch.Tensor]:
    """SB3's DDPG/TD3 actor loss, -Q(x, pi(x)), back-propagated once."""
    model.actor.optimizer.zero_grad()
    loss = -model.critic.q1_forward(obs, model.actor(obs)).mean()
    loss.backward()
    return {name: p.grad for name, p in model.actor.named_parameters()}


@pytest.mark.parametrize("relevance", RELEVANCES)
def test_gradient_flows_to_mlp_and_log_lambda(relevance):
    system = make_system("pendulum")
    model = _hybrid_model("pendulum", relevance=relevance)
    # Mid-range observations: relevance strictly between 0 and 1, actions inside the limits.
    angles = torch.linspace(0.3, 1.2, 32)
    obs = torch.stack([torch.cos(angles), torch.sin(angles), 0.5 * torch.ones(32)], dim=1)
    if relevance == "default":
        # The floored relevance keeps r near 1 there, where the LQR's action saturates (and the
        # clip passes no gradient): take the velocity at which G (design_lqr) is zero instead,
        # so that the blend (1 - r) H is inside the limits.
        design = design_lqr(system)
        gain, bias = torch.as_tensor(design.W[0]).float(), float(design.b[0])
        obs[:, 2] = -(obs[:, :2] @ gain[:2] + bias) / gain[2]
        with torch.no_grad():
            relevance_value, blend = model.actor.relevance(obs), model.actor.hybrid.blend(obs)
        assert torch.all((relevance_value > 0.0) & (relevance_value < 1.0))
        assert torch.all(blend.abs() < 1.0)
    grads = _actor_loss_grads(model, obs)
    relevance_grad = grads[RELEVANCE_PARAMETER[relevance]]
    assert relevance_grad is not None
    assert torch.all(torch.isfinite(relevance_grad))
    assert float(relevance_grad.abs().sum()) > 0
    mlp_grads = [g for name, g in grads.items() if name.startswith("hybrid.nonlinear")]
    assert mlp_grads and all(g is not None and float(g.abs().sum()) > 0 for g in mlp_grads)
    # At the operating point r = 1 and grad r = 0: the MLP gets no gradient there.
    point = torch.as_tensor(system.operating_obs, dtype=torch.float32)[None, :].repeat(4, 1)
    grads_at_point = _actor_loss_grads(model, point)
    for name, grad in grads_at_point.items():
        if name.startswith("hybrid.nonlinear"):
            assert float(grad.abs().max()) == 0.0


@pytest.mark.parametrize("relevance", RELEVANCES)
def test_training_updates_lambda_and_target_lambda(relevance):
    model = _hybrid_model("pendulum", learning_starts=50, batch_size=32, relevance=relevance)
    initial = _relevance_parameter(model.actor).detach().clone()
    model.learn(total_timesteps=120)
    learned = _relevance_parameter(model.actor).detach()
    target = _relevance_parameter(model.actor_target).detach()
    assert not torch.equal(learned, initial)
    assert not torch.equal(target, initial)  # soft-updated along with the MLP


@pytest.mark.parametrize("relevance", RELEVANCES)
def test_frozen_lambda_is_a_buffer_and_never_changes(relevance):
    model = _hybrid_model(
        "pendulum", learn_lambda=False, learning_starts=50, batch_size=32, relevance=relevance
    )
    held = RELEVANCE_PARAMETER[relevance]
    names = {name for name, _ in model.actor.named_parameters()}
    assert held not in names
    assert held in dict(model.actor.named_buffers())
    initial = _relevance_parameter(model.actor).clone()
    model.learn(total_timesteps=120)
    torch.testing.assert_close(_relevance_parameter(model.actor), initial, rtol=0, atol=0)
    if relevance == "paper":
        np.testing.assert_allclose(model.actor.hybrid.lambda_.numpy(), 1.0, rtol=1e-7)
    else:  # lambda_init = 1 raised to twice the floor the design resolved (FlooredRelevance)
        floor = np.asarray(model.actor.hybrid_design.relevance_data["lambda_floor"])
        lambda_ = model.actor.hybrid.relevance_module.lambda_
        np.testing.assert_allclose(lambda_.numpy(), np.maximum(1.0, 2.0 * floor), rtol=1e-7)


def test_actor_learning_rate_and_target_update_interval():
    polyak_full = 1.0  # a full copy makes "updated or not" exact
    interval = 3
    env = make_env("pendulum")
    model = LeocDDPG(
        "MlpPolicy",
        env,
        learning_rate=1e-3,
        actor_learning_rate=5e-4,
        target_update_interval=interval,
        tau=polyak_full,
        learning_starts=40,
        batch_size=16,
        policy_kwargs={"net_arch": SMALL_NET},
        seed=0,
        device="cpu",
    )
    model.learn(total_timesteps=40)  # fills the buffer, no update yet
    assert model._n_updates == 0
    for _ in range(2 * interval):
        model.train(gradient_steps=1, batch_size=16)
        same = all(
            torch.equal(p, q)
            for p, q in zip(model.actor.parameters(), model.actor_target.parameters(), strict=True)
        )
        assert same == (model._n_updates % interval == 0)
    assert model.actor.optimizer.param_groups[0]["lr"] == pytest.approx(5e-4)
    assert model.critic.optimizer.param_groups[0]["lr"] == pytest.approx(1e-3)
    assert model.tau == polyak_full


def test_ou_noise_seeded_and_stationary_std():
    theta, sigma = 0.15, 0.2
    first = SeededOUNoise(1, theta, sigma, seed=5)
    second = SeededOUNoise(1, theta, sigma, seed=5)
    draws_a = np.array([first() for _ in range(20)])
    draws_b = np.array([second() for _ in range(20)])
    np.testing.assert_array_equal(draws_a, draws_b)
    long = SeededOUNoise(1, theta, sigma, seed=1)
    samples = np.array([long()[0] for _ in range(100_000)])[1_000:]
    expected_std = sigma / math.sqrt(theta * (2.0 - theta))  # AR(1) stationary std
    assert samples.std() == pytest.approx(expected_std, rel=0.05)
    long.reset()
    np.testing.assert_array_equal(long.state, [0.0])


def test_held_steps_known_answers():
    curve = [
        {"steps": s, "held_fraction": f} for s, f in [(0, 0), (1, 1), (2, 0.5), (3, 1), (4, 1)]
    ]
    assert held_and_reached(curve) == (3, 1)
    assert held_and_reached(curve[:3]) == (None, 1)


def test_config_defaults_and_overrides():
    # leoc's budgets (issue 20: the paper's 15k / 10k did not learn on 4 of 5 seeds), the
    # authors' evaluation intervals, the reward of the next state where there is a track
    cartpole, car = DDPGConfig.for_system("cartpole"), DDPGConfig.for_system("mountaincar")
    assert (cartpole.total_steps, car.total_steps) == (21_000, 20_000)
    assert (cartpole.eval_interval, car.eval_interval) == (300, 200)
    assert cartpole.step_rules == car.step_rules == {"reward_on_next_state": True}
    assert StepRules(**cartpole.step_rules).exit_penalty is None  # leoc's exit: never pays
    assert DDPGConfig.for_system("cartpole", step_rules={}).step_rules == {}  # replaced whole
    pendulum = DDPGConfig.for_system("pendulum", "td3", actor_hidden=[64, 64])
    assert pendulum.total_steps == 10_000 and pendulum.algo == "td3"
    assert pendulum.step_rules == {} and pendulum.eval_interval == 200
    assert pendulum.actor_hidden == (64, 64)
    assert (pendulum.actor_learning_rate, pendulum.critic_learning_rate) == (5e-4, 1e-3)
    assert (pendulum.discount, pendulum.batch_size, pendulum.buffer_size) == (0.995, 64, 100_000)
    with pytest.raises(ValueError, match="unknown DDPGConfig fields"):
        DDPGConfig.for_system("pendulum", bogus=1)
    with pytest.raises(ValueError, match="algo"):
        DDPGConfig.for_system("pendulum", "ppo")
    assert DDPGConfig.from_dict(pendulum.as_dict()) == pendulum


@pytest.mark.slow
@pytest.mark.parametrize("algo", ["ddpg", "td3"])
def test_seeded_run_repeats_exactly_and_writes_run_folder(tmp_path, algo, monkeypatch):
    temp = tmp_path / "system-temp"
    temp.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(temp))  # SB3's logger folder would go here
    runs = [
        train_ddpg("pendulum", algo, hybrid=True, seed=3, run_dir=tmp_path / f"r{k}", **TINY_RUN)
        for k in range(2)
    ]
    state_a = runs[0].model.policy.state_dict()
    state_b = runs[1].model.policy.state_dict()
    assert state_a.keys() == state_b.keys()
    for key in state_a:
        torch.testing.assert_close(state_a[key], state_b[key], rtol=0, atol=0)
    assert runs[0].curve == runs[1].curve
    if algo == "ddpg":  # a different seed gives a different run (checked once, for time)
        other = train_ddpg(
            "pendulum", algo, hybrid=True, seed=4, run_dir=tmp_path / "o", **TINY_RUN
        )
        assert any(
            not torch.equal(value, other.model.policy.state_dict()[key])
            for key, value in state_a.items()
            if value.is_floating_point() and "target" not in key and value.numel() > 1
        )
    files = {p.name for p in (tmp_path / "r0").iterdir()}
    expected = {"config.json", "model.zip", "best_model.zip", "curve.json", "curve.csv"}
    assert expected | {"learning_curve.png"} <= files
    assert not any(name.endswith(".tmp") for name in files)
    config = json.loads((tmp_path / "r0" / "config.json").read_text())
    assert (
        config["seed"] == 3
        and config["hybrid"] == HybridSpec().to_dict()
        and config["algo"] == algo
    )
    # no SB3-<date> folder in the system temp folder (torch's own caches may go there)
    assert not [path for path in temp.iterdir() if path.name.startswith("SB3")]
    rows = runs[0].curve
    assert set(CURVE_COLUMNS) | {"returns", "hold_steps"} <= set(rows[0])  # trainer contract
    assert runs[0].summary["model_selection"] == "best_held"
    assert [row["steps"] for row in rows] == [0, 120, 240]
    assert rows[1]["interaction_seconds"] == pytest.approx(120 * make_system("pendulum").dt)


def _relevance_state(actor) -> dict[str, list]:
    """The relevance's entries of a hybrid actor's state: the paper's log_lambda, or the
    relevance module's parameters and buffers (the floor's excess q, the floor, the point)."""
    return {
        key: value.double().tolist()
        for key, value in actor.state_dict().items()
        if key == "hybrid.log_lambda" or key.startswith("hybrid.relevance_module.")
    }


@pytest.mark.slow
@pytest.mark.parametrize(
    # the default on the mountain car: its trainer's LQR certificate takes a second to prove,
    # the cart-pole's (its own: the trainer's step rules are in the certificate's key) > 10 s
    ("system_name", "relevance"),
    [("cartpole", "paper"), ("mountaincar", "default")],
)
def test_save_load_round_trip_in_fresh_process(tmp_path, system_name, relevance):
    # leoc's default hybrid is train_ddpg's hybrid=True; the paper's is spelt out
    hybrid = True if relevance == "default" else HybridSpec(**RELEVANCE_FIELDS[relevance])
    result = train_ddpg(
        system_name, "td3", hybrid=hybrid, seed=1, run_dir=tmp_path / "run", **TINY_RUN
    )
    _check_relevance(result.model.actor, relevance)
    generator = torch.Generator().manual_seed(0)
    obs_dim = make_system(system_name).obs_dim
    obs = torch.randn(8, obs_dim, generator=generator, dtype=torch.float64)
    final = physical_policy(result.model.actor)
    expected = final(obs).detach().numpy()
    hybrid_policy = result.model.actor.hybrid
    module = hybrid_policy.relevance_module
    lambda_ = (hybrid_policy if module is None else module).lambda_
    expected_lambda = lambda_.detach().double().numpy()
    expected_state = _relevance_state(result.model.actor)
    assert RELEVANCE_PARAMETER[relevance] in expected_state
    script = (
        "import json, sys, torch\n"
        "from leoc.sb3 import load_ddpg_controller, load_ddpg_model\n"
        "run, obs = sys.argv[1], torch.tensor(json.loads(sys.argv[2]), dtype=torch.float64)\n"
        "policy = load_ddpg_controller(run, 'final')\n"
        "model = load_ddpg_model(run, 'final')\n"
        "h = model.actor.hybrid\n"
        "lambda_ = (h if h.relevance_module is None else h.relevance_module).lambda_\n"
        "state = {k: v.double().tolist() for k, v in model.actor.state_dict().items()\n"
        "  if k == 'hybrid.log_lambda' or k.startswith('hybrid.relevance_module.')}\n"
        "print(json.dumps({'actions': policy(obs).tolist(),\n"
        "  'lambda': lambda_.double().tolist(), 'state': state,\n"
        "  'relevance': type(h.relevance_module).__name__,\n"
        "  'target_hybrid': type(model.actor_target).__name__,\n"
        "  'hybrid': policy.is_hybrid}))\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", script, str(result.run_dir), json.dumps(obs.tolist())],
        capture_output=True,
        text=True,
        check=True,
        timeout=120,
    )
    loaded = json.loads(out.stdout.strip().splitlines()[-1])
    np.testing.assert_allclose(np.array(loaded["actions"]), expected, rtol=0, atol=F64_ATOL)
    np.testing.assert_allclose(np.array(loaded["lambda"]), expected_lambda, rtol=0, atol=0)
    assert loaded["state"].keys() == expected_state.keys()
    for key, value in expected_state.items():
        np.testing.assert_array_equal(np.array(loaded["state"][key]), value, err_msg=key)
    kind = {"paper": "NoneType", "default": "FlooredRelevance"}[relevance]
    assert loaded["relevance"] == kind
    assert loaded["target_hybrid"] == "HybridActor" and loaded["hybrid"] is True
    best = load_ddpg_controller(result.run_dir)  # the run's (final) controller, in this process
    np.testing.assert_allclose(best(obs).numpy(), result.policy(obs).numpy(), rtol=0, atol=F64_ATOL)


#: Where leoc.ddpg kept the SB3 classes a model zip names (the package is leoc.sb3 since issue 39).
MODULES_BEFORE_THE_MOVE = {
    "ddpg": "leoc.ddpg.policies",
    "td3": "leoc.ddpg.policies",
    "sac": "leoc.ddpg.sac",
}
NOISE_MODULE_BEFORE_THE_MOVE = "leoc.ddpg.noise"


def _pickled_reference(module: str, name: str) -> dict[str, str]:
    """A zip ``data`` entry that unpickles to ``module.name`` (protocol 0's GLOBAL opcode)."""
    reference = f"c{module}\n{name}\n.".encode()
    return {":type:": "<class 'type'>", ":serialized:": base64.b64encode(reference).decode()}


def _save_as_before_the_move(model, algo: str, path) -> None:
    """Save ``model`` as leoc.ddpg did: its zip names the policy class and the exploration noise
    by modules of leoc.ddpg, which are gone."""
    buffer = io.BytesIO()
    model.save(buffer)
    with zipfile.ZipFile(buffer) as saved:
        entries = {name: saved.read(name) for name in saved.namelist()}
    data = json.loads(entries["data"])
    policy_name = type(model.policy).__name__  # HybridDDPGPolicy is HybridTD3Policy
    data["policy_class"] = _pickled_reference(MODULES_BEFORE_THE_MOVE[algo], policy_name)
    if isinstance(data.get("action_noise"), dict):  # DDPG's and TD3's OU noise
        data["action_noise"] = _pickled_reference(NOISE_MODULE_BEFORE_THE_MOVE, "SeededOUNoise")
    entries["data"] = json.dumps(data).encode()
    with zipfile.ZipFile(path, "w") as moved:
        for name, raw in entries.items():
            moved.writestr(name, raw)


@pytest.mark.parametrize(
    ("algo", "hybrid", "saved_hybrid"),
    [
        ("ddpg", True, "spec"),
        ("td3", False, "spec"),
        ("td3", True, "bool"),  # a config saved before HybridSpec
        ("sac", True, "spec"),
        ("sac", False, "bool"),
    ],
)
def test_a_model_saved_before_the_move_still_loads(tmp_path, algo, hybrid, saved_hybrid):
    """load_ddpg_controller gives SB3 the policy class from the run's config, so a zip that names
    leoc.ddpg's classes (unloadable: SB3's own load fails) still loads, with the same actions."""
    assert importlib.util.find_spec("leoc.ddpg") is None  # the old module is gone
    config = DDPGConfig.for_system(
        "pendulum", algo, hybrid=hybrid, actor_hidden=(16, 16), critic_hidden=(16, 16)
    )
    model = build_model(config, seed=3, env=make_env("pendulum"))
    run = tmp_path / "run"
    run.mkdir()
    _save_as_before_the_move(model, algo, run / "model.zip")
    config_dict = {**config.as_dict(), "seed": 3}
    if saved_hybrid == "bool":
        config_dict["hybrid"] = hybrid
    (run / "config.json").write_text(json.dumps(config_dict))
    with pytest.raises(ModuleNotFoundError, match="leoc.ddpg"):
        type(model).load(run / "model.zip", device="cpu")
    obs = torch.randn(8, 3, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    loaded = load_ddpg_controller(run)
    assert loaded.is_hybrid is hybrid
    assert torch.equal(loaded(obs), physical_policy(model.actor)(obs))


def test_baseline_physical_policy_matches_sb3_predict():
    env = make_env("mountaincar")
    model = LeocTD3("MlpPolicy", env, policy_kwargs={"net_arch": SMALL_NET}, seed=0, device="cpu")
    obs = np.random.default_rng(0).normal(size=(16, 2))
    sb3_actions, _ = model.predict(obs, deterministic=True)
    physical = physical_policy(model.actor)(torch.as_tensor(obs)).numpy()
    np.testing.assert_allclose(physical, sb3_actions, rtol=F32_RTOL, atol=F32_ATOL)
    assert not physical_policy(model.actor).is_hybrid


@pytest.mark.parametrize("algo", ["ddpg", "td3", "sac"])
@pytest.mark.parametrize("hybrid", [False, True])
def test_physical_policy_accepts_the_sb3_policy(algo, hybrid):
    """``physical_policy(model.policy)`` is ``physical_policy(model.actor)``, and both act as the
    SB3 actor's deterministic action (``model.predict``) to float32 precision."""
    from stable_baselines3 import SAC

    from leoc.sb3 import HybridSACPolicy

    env = make_env("cartpole")
    if hybrid:
        policy_class = HybridSACPolicy if algo == "sac" else HybridTD3Policy
        kwargs = hybrid_policy_kwargs("cartpole", net_arch=SMALL_NET)
    else:
        policy_class, kwargs = "MlpPolicy", {"net_arch": SMALL_NET}
    algorithm = {"ddpg": DDPG, "td3": TD3, "sac": SAC}[algo]
    model = algorithm(policy_class, env, policy_kwargs=kwargs, seed=0, device="cpu")
    # away from the operating point, where the MLP part acts
    obs = np.random.default_rng(1).normal(size=(16, env.observation_space.shape[0]))
    sb3_actions, _ = model.predict(obs, deterministic=True)
    from_policy = physical_policy(model.policy)
    actions = from_policy(torch.as_tensor(obs)).numpy()
    np.testing.assert_array_equal(actions, physical_policy(model.actor)(torch.as_tensor(obs)))
    np.testing.assert_allclose(actions, sb3_actions, rtol=F32_RTOL, atol=F32_ATOL)
    assert from_policy.is_hybrid == hybrid


def test_physical_policy_names_the_call_for_a_model():
    model = LeocTD3("MlpPolicy", make_env("pendulum"), policy_kwargs={"net_arch": SMALL_NET})
    with pytest.raises(TypeError, match=r"physical_policy\(model\.policy\).*found LeocTD3$"):
        physical_policy(model)


@pytest.mark.extended
def test_hybrid_ddpg_learns_to_hold_pendulum_on_most_seeds(tmp_path):
    """The paper's budget (10k steps) on three seeds: at least two reach and hold the operating
    point with a return above -600 (swing-up in a few seconds, then balanced); one seed's
    outcome is not the test. Measured (benchmarks/bench_ddpg_seeds.py --hybrid --seeds 0 1 2 3):
    seeds 0-3 learnt by steps 2000, 5500, 6000 and 4000, so 3000 steps (this test's budget
    before) was a 1-in-4 draw."""
    learnt = []
    for seed in range(3):
        result = train_ddpg(
            "pendulum",
            "ddpg",
            hybrid=True,
            seed=seed,
            run_dir=tmp_path / f"seed{seed}",
            eval_interval=500,
            progress=False,
        )
        assert result.config["total_steps"] == 10_000  # the paper's pendulum budget
        learnt.append(result.reached_steps is not None and result.best_return > -600.0)
    assert sum(learnt) >= 2, learnt


# ----------------------------------------------------------------------------- relevance="roa"


def _roa_model(system_name: str, **kw):
    env = make_env(system_name)
    policy_kwargs = hybrid_policy_kwargs(system_name, relevance="roa", net_arch=SMALL_NET)
    return DDPG(HybridTD3Policy, env, policy_kwargs=policy_kwargs, seed=0, device="cpu", **kw)


def _roa_band_obs(model, system, count: int, low: float, high: float) -> torch.Tensor:
    """float32 observations whose level V / rho_in lies in [low, high] (random directions)."""
    module = model.actor.hybrid.relevance_module
    P = np.asarray(model.actor.hybrid_design.relevance_data["lyapunov_matrix"])
    rho_in = model.actor.hybrid_design.relevance_data["rho_in"]
    rng = np.random.default_rng(0)
    directions = rng.standard_normal((count, system.state_dim))
    levels = rng.uniform(low, high, size=count) * rho_in
    scales = np.sqrt(levels / np.einsum("bi,ij,bj->b", directions, P, directions))
    states = system.operating_state + scales[:, None] * directions
    assert module.max_width > 0
    return system.observe(torch.as_tensor(states)).float()


@pytest.mark.parametrize("system_name", ["cartpole", "mountaincar"])
def test_roa_actor_is_the_lqr_bit_for_bit_inside_the_flat_top(system_name):
    system = make_system(system_name)
    model = _roa_model(system_name)
    generator = torch.Generator().manual_seed(3)
    with torch.no_grad():
        for param in model.actor.hybrid.nonlinear.parameters():
            param.copy_(torch.randn(param.shape, generator=generator))
    obs = _roa_band_obs(model, system, 256, 0.0, 0.999)
    with torch.no_grad():
        action = model.actor(obs)
        linear = torch.clamp(model.actor.hybrid.linear(obs), -1.0, 1.0)
        assert torch.equal(model.actor.relevance(obs), torch.ones(256, 1))
    assert torch.equal(action, linear)
    # The float64 physical policy: the saturated LQR, and pi(a) = G(a), Jacobian W.
    design = design_lqr(system)
    policy = physical_policy(model.actor)
    obs64 = obs.double()
    expected = np.clip(
        obs64.numpy() @ design.W.T + design.b, -system.action_limit, system.action_limit
    )
    np.testing.assert_allclose(policy(obs64).numpy(), expected, rtol=0, atol=F64_ATOL)
    point = torch.as_tensor(system.operating_obs)
    jacobian = torch.autograd.functional.jacobian(lambda x: policy(x[None])[0], point)
    np.testing.assert_allclose(jacobian.numpy(), design.W, rtol=0, atol=F64_ATOL)


def test_roa_training_step_reaches_width_and_network_and_round_trips(tmp_path):
    system = make_system("pendulum")
    model = _roa_model("pendulum", learning_starts=10, batch_size=16)
    names = {name for name, _ in model.actor.named_parameters()}
    assert "hybrid.relevance_module.width_param" in names
    obs = _roa_band_obs(model, system, 32, 1.05, 1.5)  # inside the transition band
    grads = _actor_loss_grads(model, obs)
    width_grad = grads["hybrid.relevance_module.width_param"]
    assert width_grad is not None and float(width_grad.abs()) > 0
    mlp_grads = [g for name, g in grads.items() if name.startswith("hybrid.nonlinear")]
    assert mlp_grads and all(g is not None and float(g.abs().sum()) > 0 for g in mlp_grads)
    # One optimiser step moves the width (the actor's optimiser holds it).
    before = float(model.actor.hybrid.relevance_module.width.detach())
    model.actor.optimizer.step()
    assert float(model.actor.hybrid.relevance_module.width.detach()) != before
    # SB3 save/load rebuilds the ROA actor with its learned width.
    model.save(tmp_path / "roa.zip")
    loaded = DDPG.load(tmp_path / "roa.zip", device="cpu")
    assert loaded.actor.hybrid_spec.relevance == loaded.actor_target.hybrid_spec.relevance == "roa"
    probe = _roa_band_obs(model, system, 16, 0.5, 2.5)
    with torch.no_grad():
        torch.testing.assert_close(loaded.actor(probe), model.actor(probe), rtol=0, atol=0)
    config = DDPGConfig.for_system("pendulum", hybrid=True, relevance="roa")
    assert DDPGConfig.from_dict(config.as_dict()).hybrid.relevance == "roa"
    with pytest.raises(ValueError, match="relevance: expected one of"):
        DDPGConfig.for_system("pendulum", relevance="flat")


def test_ddpg_progress_lines_give_steps_speed_and_the_last_return() -> None:
    """The line's structure (steps done of the budget, a speed, the last evaluation), not its
    timing: the speed is steps over the wall time since the start, so 25 s or more after a
    start 2500 steps ago it is at most 100 steps/s, whatever the machine stalls."""
    import re
    import time

    from leoc.sb3.callbacks import LearningCurveCallback
    from leoc.training import Evaluation

    callback = LearningCurveCallback(
        make_system("pendulum"), np.zeros((1, 2)), 500, progress="lines", total_steps=10_000
    )
    callback.num_timesteps = 2500
    callback._started = time.monotonic() - 25.0
    line = callback.progress_line()
    assert line.startswith("[ddpg] step 2500/10000 (25%)")
    speed = re.search(r"([0-9][0-9,.]*) steps/s", line)
    assert speed is not None, line
    assert 0 < float(speed.group(1).replace(",", "")) <= 100
    assert "last evaluation" not in line  # none yet
    callback._last = Evaluation(-812.34, 1.0, [-812.34], [None])
    assert callback.progress_line().endswith("last evaluation: return -812.3, held 0%")


def test_profiles_carry_measured_run_costs() -> None:
    from leoc.experiments.profiles import FALLBACK_RUN_SECONDS, RunSpec, get_profile

    quick, paper, smoke = (get_profile(name) for name in ("quick", "paper", "smoke"))
    spec = RunSpec("cartpole", "pilco_hybrid", 0)
    # results/paper, median over its seeds (tests/test_eta_costs.py checks the whole table)
    assert paper.training_seconds(spec) == 176.2
    assert quick.expected_seconds(spec) < paper.expected_seconds(spec)
    # DDPG and SAC measured at leoc's budgets (21k steps on the cart-pole), none derived
    assert paper.training_seconds(RunSpec("cartpole", "ddpg_hybrid", 0)) == 101.2
    assert paper.training_seconds(RunSpec("mountaincar", "sac_hybrid", 0)) == 387.2
    # a user's system: the mean of the same controller elsewhere
    other = RunSpec("acrobot", "ddpg_hybrid", 0)
    assert paper.training_seconds(other) == pytest.approx((52.2 + 101.2 + 99.1) / 3)
    assert smoke.cost_model is None and quick.cost_model is not None
    assert smoke.training_seconds(spec) == FALLBACK_RUN_SECONDS["pilco"]
    # the proof and the protocol, which the measured studies did not run, come on top: their
    # system's and learner's cost, else the learner's mean elsewhere, else nothing
    costs = paper.evaluation_seconds
    assert paper.expected_seconds(spec) == 176.2 + costs["cartpole/pilco"]
    assert paper.evaluation_cost(other) == pytest.approx(
        sum(v for k, v in costs.items() if k.endswith("/ddpg")) / 3
    )
    assert smoke.evaluation_cost(spec) == 0.0 and smoke.evaluation_seconds == {}


def test_ablation_eta_scales_the_measured_cost_from_leocs_budget(monkeypatch) -> None:
    from leoc.experiments.ablation import (
        SAC_COST_FACTOR,
        AblationPlan,
        AblationSpec,
        expected_seconds,
    )
    from leoc.experiments.profiles import PAPER_RUN_SECONDS

    # the measured costs are at leoc's budgets (cart-pole 21k): half of it costs half, and
    # the budget leoc measured at costs what was measured
    half = expected_seconds(AblationPlan(budgets={"cartpole": 10_500}))
    spec = AblationSpec("cartpole", "ddpg_hybrid", "defaults", 0)
    assert half(spec) == pytest.approx(PAPER_RUN_SECONDS["cartpole/ddpg_hybrid"] / 2)
    full = expected_seconds(AblationPlan(budgets={"mountaincar": 20_000}))
    sac = AblationSpec("mountaincar", "sac_baseline", "defaults", 0)
    assert full(sac) == pytest.approx(PAPER_RUN_SECONDS["mountaincar/sac_baseline"])
    # a SAC kind nobody measured falls back on its DDPG controller's cost
    monkeypatch.delitem(PAPER_RUN_SECONDS, "mountaincar/sac_baseline")
    expected = SAC_COST_FACTOR * PAPER_RUN_SECONDS["mountaincar/ddpg_baseline"]
    assert full(sac) == pytest.approx(expected)
