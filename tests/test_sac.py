"""Tests of leoc.sb3.sac: the LEOC hybrid as the squashed mean of Stable-Baselines3's SAC.

References are independent of the code under test: the LQR design recomputed with
``design_lqr``, the blend recomputed from its formula, autograd Jacobians, Monte Carlo moments
of SAC's own sampler, closed forms (atanh, tanh).
"""

from __future__ import annotations

import copy
import json
import math

import numpy as np
import pytest
import torch
from gymnasium import spaces
from stable_baselines3 import SAC
from stable_baselines3.common.torch_layers import FlattenExtractor
from torch import nn

from leoc.control import design_lqr
from leoc.policies import FlooredRelevance, HybridDesign, HybridSpec
from leoc.sb3 import (
    SAC_DEFAULTS,
    DDPGConfig,
    HybridSACActor,
    HybridSACPolicy,
    LeocSAC,
    LeocSACPolicy,
    SeededOUNoise,
    build_model,
    hybrid_policy_kwargs,
    load_ddpg_controller,
    physical_policy,
    train_ddpg,
)
from leoc.sb3 import sac as sac_module
from leoc.sb3.common import SplitCritic, critic_loss_fn
from leoc.sb3.noise import exploration_noise
from leoc.sb3.sac import SquashedMean, squashed_blend_mean
from leoc.systems import SYSTEM_NAMES, make_env, make_system

SMALL_NET = [32, 32]
F64_ATOL = 1e-12
F32_ATOL = 2e-5
ROA_LEVEL = 0.5  # a flat-top level for the identity tests (certification is not under test)
LOG_STD_WEIGHT_SCALE = 1e-3  # random log-std head: weights (the hidden features are large)
LOG_STD_BIAS_SCALE = 0.5  # and bias, so std = exp(N(0, 0.5^2)) roughly
TINY_RUN = {
    "total_steps": 240,
    "learning_starts": 60,
    "batch_size": 32,
    "actor_hidden": (16, 16),
    "critic_hidden": (16, 16),
    "eval_interval": 120,
    "eval_episodes": 1,
    "progress": False,
}


pytestmark = pytest.mark.usefixtures("single_thread")

#: The paper's relevance as published, r = (1 + d)^-2 with ``log_lambda`` on the HybridPolicy
#: itself (leoc's default before issue 40), as HybridSpec fields. "default" below is leoc's
#: default HybridSpec() since issue 40: r = (1 + d^2)^-2 with Lambda floored (FlooredRelevance:
#: lambda = floor (1 + e^q), q its ``log_excess``) so that r >= 0.5 on the LQR's proved region
#: of attraction.
PAPER_FIELDS = {"r_min": None, "relevance_power": 1.0}
#: The parameter Lambda is learned through, by relevance.
RELEVANCE_PARAMETER = {
    "paper": "hybrid.log_lambda",
    "default": "hybrid.relevance_module.log_excess",
}


def _roa_kwargs(system, design) -> dict:
    """The ROA hybrid's spec and design at a fixed level (the proof of the level is
    leoc.control's, not ours)."""
    data = {
        "obs_layout": system.observation.to_list(),
        "operating_state": np.asarray(system.operating_state).tolist(),
        "lyapunov_matrix": np.asarray(design.P).tolist(),
        "rho_in": ROA_LEVEL,
    }
    return {
        "hybrid_spec": HybridSpec(relevance="roa", width_init=1.0, learn_width=True).to_dict(),
        "hybrid_design": HybridDesign(design.W, design.b, system.operating_obs, data).to_dict(),
    }


def _sac_model(system_name: str, relevance: str = "paper", seed: int = 0, **kw) -> SAC:
    """The SAC hybrid with relevance "paper" (PAPER_FIELDS), "default" (HybridSpec()'s,
    floored p = 2, on the floor its design resolves from the LQR's certificate) or "roa"."""
    system = make_system(system_name)
    fields = {} if relevance == "default" else PAPER_FIELDS  # roa: replaced below, unproved
    kwargs = hybrid_policy_kwargs(system, net_arch=SMALL_NET, **fields)
    if relevance == "roa":
        kwargs.update(_roa_kwargs(system, design_lqr(system)))
    env = make_env(system_name)
    model = SAC(HybridSACPolicy, env, policy_kwargs=kwargs, seed=seed, device="cpu", **kw)
    module = model.actor.hybrid.relevance_module
    if relevance == "paper":
        assert module is None
    elif relevance == "default":
        assert isinstance(module, FlooredRelevance) and module.power == 2.0
        floor = model.actor.hybrid_design.relevance_data["lambda_floor"]
        np.testing.assert_allclose(module.floor.double().numpy(), floor, rtol=1e-7, atol=0)
    return model


def _randomise(actor: HybridSACActor, generator: torch.Generator) -> None:
    """Random H (mean head and hidden layers far from their initialisation), a random log-std
    head (small weights: a std of order 1, neither vanishing nor at SB3's cap) and random
    relevance parameters (Lambda, the floored relevance's excess q over its floor, or the ROA
    band width)."""
    with torch.no_grad():
        for param in actor.hybrid.nonlinear.parameters():
            param.copy_(torch.randn(param.shape, generator=generator))
        weight, bias = actor.log_std.weight, actor.log_std.bias
        weight.copy_(LOG_STD_WEIGHT_SCALE * torch.randn(weight.shape, generator=generator))
        bias.copy_(LOG_STD_BIAS_SCALE * torch.randn(bias.shape, generator=generator))
        module = actor.hybrid.relevance_module
        if module is None:
            actor.hybrid.log_lambda.copy_(torch.randn(actor.hybrid.log_lambda.shape))
        elif isinstance(module, FlooredRelevance):
            module.log_excess.copy_(torch.randn(module.log_excess.shape, generator=generator))
        else:
            width = module.width_param
            width.copy_(torch.randn(width.shape, generator=generator))


def _deterministic64(actor: HybridSACActor):
    """The SB3 actor's own deterministic action in float64, physical units: its mean and
    log-std heads, then SAC's distribution's deterministic action (tanh of the mean).

    The float64 copy takes observations as its features (SB3's preprocessing would cast them to
    float32), and its normalised LQR (W / h, (b - c) / h) and operating point are recomputed in
    float64 from the actor's float64 buffers of W, b and a (the float32 actor holds them rounded
    to float32)."""
    actor64 = copy.deepcopy(actor).double()
    actor64.extract_features = lambda obs, extractor=None: obs
    low = torch.as_tensor(actor.action_space.low, dtype=torch.float64)
    high = torch.as_tensor(actor.action_space.high, dtype=torch.float64)
    centre, half = (high + low) / 2, (high - low) / 2
    with torch.no_grad():
        actor64.hybrid.linear.W.copy_(actor.physical_gain / half[:, None])
        actor64.hybrid.linear.b.copy_((actor.physical_bias - centre) / half)
        actor64.hybrid.operating_point.copy_(actor.operating_obs)
        module = actor64.hybrid.relevance_module
        if module is not None and hasattr(module, "operating_point"):  # precision, floored
            module.operating_point.copy_(actor.operating_obs)

    def action(obs: torch.Tensor) -> torch.Tensor:
        mean, log_std, _ = actor64.get_action_dist_params(obs)
        squashed = actor64.action_dist.actions_from_params(mean, log_std, deterministic=True)
        return centre + half * squashed

    return action


# ------------------------------------------------------------------------------- identities


@pytest.mark.parametrize(
    ("system_name", "relevance"),
    [(name, relevance) for relevance in ("paper", "default") for name in SYSTEM_NAMES]
    + [("mountaincar", "roa"), ("cartpole", "roa")],
)
def test_identities_at_the_operating_point_after_squashing(system_name, relevance):
    system = make_system(system_name)
    design = design_lqr(system)  # independent reference for G(x) = W x + b
    model = _sac_model(system_name, relevance)
    _randomise(model.actor, torch.Generator().manual_seed(7))
    point = torch.as_tensor(system.operating_obs, dtype=torch.float64)
    expected = design.W @ system.operating_obs + design.b
    for action in (physical_policy(model.actor), _deterministic64(model.actor)):
        value = action(point[None, :])[0]
        np.testing.assert_allclose(value.detach().numpy(), expected, rtol=0, atol=F64_ATOL)
        jacobian = torch.autograd.functional.jacobian(lambda x, f=action: f(x[None, :])[0], point)
        np.testing.assert_allclose(jacobian.numpy(), design.W, rtol=0, atol=1e-10)
    # SAC's float32 actor inside SB3: the same identities in normalised units u / u_max
    limit = system.action_limit
    point32 = point.float()[None, :]
    with torch.no_grad():
        value32 = model.actor(point32, deterministic=True)[0].double() * limit
    np.testing.assert_allclose(value32.numpy(), expected, rtol=0, atol=F32_ATOL)
    jacobian32 = torch.autograd.functional.jacobian(
        lambda x: model.actor(x[None, :], deterministic=True)[0], point32[0]
    )
    np.testing.assert_allclose(jacobian32.double().numpy() * limit, design.W, rtol=1e-4, atol=1e-4)


#: A floor on Lambda for a hand-made design (any positive floor keeps the identities; the
#: LQR's certificate is not under test here).
HAND_MADE_FLOOR = [0.2, 1.5, 0.4]


def test_identities_with_an_asymmetric_box_where_g_of_a_is_not_zero():
    """G(a) = 1.3 in a box [-1, 3] (normalised G(a) = 0.15): value and slope survive the
    atanh / tanh pair, for the paper's relevance in both parametrisations and for leoc's
    default (Lambda floored, p = 2; the floor hand-made)."""
    generator = torch.Generator().manual_seed(5)
    gain = np.array([[0.7, -1.1, 0.4]])
    point = np.array([0.2, -0.5, 1.0])
    bias = np.array([1.3]) - gain @ point
    box = spaces.Box(low=-1.0, high=3.0, shape=(1,), dtype=np.float32)
    obs_space = spaces.Box(low=-10.0, high=10.0, shape=(3,), dtype=np.float32)
    cases = [
        (HybridSpec(lambda_init=0.3, **PAPER_FIELDS), {}),
        (HybridSpec(lambda_init=0.3, relevance_parametrisation="precision"), {}),
        (HybridSpec(lambda_init=0.3), {"lambda_floor": HAND_MADE_FLOOR}),  # leoc's default
    ]
    for spec, data in cases:
        actor = HybridSACActor(
            obs_space,
            box,
            SMALL_NET,
            FlattenExtractor(obs_space),
            3,
            hybrid_spec=spec,
            hybrid_design=HybridDesign(gain, bias, point, data),
        )
        if data:  # the default relevance: floored, p = 2
            module = actor.hybrid.relevance_module
            assert isinstance(module, FlooredRelevance) and module.power == 2.0
            with torch.no_grad():
                module.log_excess.copy_(torch.randn(3, generator=generator))
        with torch.no_grad():
            for param in actor.hybrid.nonlinear.parameters():
                param.copy_(2.0 * torch.randn(param.shape, generator=generator))
        point64 = torch.as_tensor(point)
        for action in (physical_policy(actor), _deterministic64(actor)):
            np.testing.assert_allclose(
                action(point64[None])[0].detach().numpy(), [1.3], rtol=0, atol=F64_ATOL
            )
            jacobian = torch.autograd.functional.jacobian(
                lambda x, f=action: f(x[None])[0], point64
            )
            np.testing.assert_allclose(jacobian.numpy(), gain, rtol=0, atol=1e-10)


@pytest.mark.parametrize("kind", ["paper", "default"])
def test_squashed_mean_is_the_ddpg_blend_away_from_the_operating_point(kind):
    """tanh(mu) = clip(r G~ + (1 - r) tanh M), recomputed from the formula (relevance from
    Lambda, G from the LQR design, M from SB3's layers), on states far and near: the paper's
    r = (1 + d)^-2 with lambda = exp(log_lambda), and leoc's default r = (1 + d^2)^-2 with
    lambda = floor (1 + exp(q))."""
    system = make_system("cartpole")
    design = design_lqr(system)
    model = _sac_model("cartpole", kind)
    generator = torch.Generator().manual_seed(3)
    _randomise(model.actor, generator)
    actor = model.actor
    obs = torch.as_tensor(system.operating_obs) + torch.randn(
        256, system.obs_dim, generator=generator, dtype=torch.float64
    ) * torch.logspace(-2, 0.5, 256, dtype=torch.float64).unsqueeze(1)
    if kind == "paper":
        lam, power = torch.exp(actor.hybrid.log_lambda.detach()).double(), 1
    else:
        module = actor.hybrid.relevance_module
        excess = torch.exp(module.log_excess.detach().double())
        lam, power = module.floor.double() * (1.0 + excess), 2
    distance = ((obs - torch.as_tensor(system.operating_obs)) ** 2 / lam).sum(1, keepdim=True)
    relevance = 1.0 / (1.0 + distance**power) ** 2
    limit = system.action_limit
    linear = (obs @ torch.as_tensor(design.W).T + torch.as_tensor(design.b)) / limit
    layers = copy.deepcopy(actor.hybrid.nonlinear).double()
    with torch.no_grad():
        pre_squash = layers.mean(layers.latent(obs))
        expected = (relevance * linear + (1 - relevance) * torch.tanh(pre_squash)).clamp(-1, 1)
        inside_sb3 = actor(obs.float(), deterministic=True).double()
        physical = physical_policy(actor)(obs) / limit
    np.testing.assert_allclose(inside_sb3.numpy(), expected.numpy(), rtol=0, atol=F32_ATOL)
    np.testing.assert_allclose(physical.numpy(), expected.numpy(), rtol=0, atol=F32_ATOL)
    assert float((expected.abs() > 0.999).double().mean()) > 0  # the clip is exercised
    assert float(((relevance > 0.05) & (relevance < 0.95)).double().mean()) > 0.1  # the blend


def test_squashed_blend_mean_known_answers():
    g = torch.linspace(-0.99, 0.99, 41, dtype=torch.float64).unsqueeze(1)
    m = torch.linspace(-8.0, 8.0, 41, dtype=torch.float64).unsqueeze(1)
    ones, zeros = torch.ones_like(g), torch.zeros_like(g)
    # r = 1: atanh(G~) exactly, whatever M; r = 0: SB3's own mean M
    np.testing.assert_allclose(
        squashed_blend_mean(g, m, ones), torch.atanh(g), rtol=1e-14, atol=1e-15
    )
    np.testing.assert_allclose(squashed_blend_mean(g, m, zeros), m, rtol=1e-13, atol=1e-13)
    # float32 keeps M to relative round-off where atanh(tanh(M)) has lost its digits
    m32 = torch.tensor([[6.5], [7.5], [-7.9]])
    kept = squashed_blend_mean(torch.zeros_like(m32), m32, torch.zeros_like(m32))
    np.testing.assert_allclose(kept, m32, rtol=1e-5)
    assert float((torch.atanh(torch.tanh(m32)) - m32).abs().max()) > 1e-2  # the naive way
    # G~ outside the box: the clip, |mu| = atanh(1 - eps), and no NaN with or without blend
    outside = torch.tensor([[3.0], [-5.0]], dtype=torch.float64)
    r = torch.tensor([[1.0], [0.9]], dtype=torch.float64)
    mu = squashed_blend_mean(outside, torch.zeros_like(outside), r)
    bound = math.atanh(1.0 - torch.finfo(torch.float64).eps)
    np.testing.assert_allclose(mu.abs().numpy(), [[bound], [bound]], rtol=1e-6)
    assert torch.all(torch.sign(mu) == torch.sign(outside))


@pytest.mark.parametrize("system_name", ["cartpole", "mountaincar"])
def test_the_flat_top_action_is_g_exactly(system_name):
    """ROA relevance: r == 1 on V <= rho_in; where also |G| is inside the limits, SAC's own
    deterministic action (float64) and the physical policy are G to 1e-12."""
    system = make_system(system_name)
    design = design_lqr(system)
    model = _sac_model(system_name, "roa")
    _randomise(model.actor, torch.Generator().manual_seed(3))
    rng = np.random.default_rng(0)
    directions = rng.standard_normal((512, system.state_dim))
    levels = rng.uniform(0.0, 0.999, 512) * ROA_LEVEL
    scales = np.sqrt(levels / np.einsum("bi,ij,bj->b", directions, design.P, directions))
    states = system.operating_state + scales[:, None] * directions
    obs = system.observe(torch.as_tensor(states))
    linear = obs.numpy() @ design.W.T + design.b
    inside = np.abs(linear[:, 0]) < 0.95 * system.action_limit
    assert inside.sum() > 100
    obs, linear = obs[inside], linear[inside]
    with torch.no_grad():
        assert torch.equal(model.actor.relevance(obs.float()), torch.ones(len(obs), 1))
        for action in (physical_policy(model.actor), _deterministic64(model.actor)):
            np.testing.assert_allclose(action(obs).numpy(), linear, rtol=0, atol=F64_ATOL)


# ------------------------------------------------------------------------------ exploration


@pytest.mark.parametrize("relevance", ["paper", "default"])
def test_sampled_actions_are_sacs_gaussian_around_the_deterministic_one(relevance):
    """Monte Carlo: the pre-tanh samples have mean atanh(deterministic action) and SAC's std
    exp(log_std head), at the operating point and away from it."""
    system = make_system("pendulum")
    model = _sac_model("pendulum", relevance)
    _randomise(model.actor, torch.Generator().manual_seed(11))
    actor = model.actor
    samples = 40_000
    for state in (system.operating_state, np.array([0.8, -1.5])):
        obs = system.observe(torch.as_tensor(state)[None]).float()
        with torch.no_grad():
            deterministic = actor(obs, deterministic=True)  # (1, 1), normalised
            latent = actor.hybrid.nonlinear.latent(obs)
            std = torch.exp(actor.log_std(latent).clamp(-20, 2))  # SB3's clamp of the head
            torch.manual_seed(0)
            sampled = actor(obs.expand(samples, -1), deterministic=False)
            pre_tanh = actor.action_dist.gaussian_actions
        centre = torch.atanh(deterministic.double())
        assert torch.allclose(torch.tanh(pre_tanh), sampled)
        mean = pre_tanh.double().mean(0)
        spread = pre_tanh.double().std(0)
        standard_error = float(std) / math.sqrt(samples)
        assert abs(float(mean - centre)) < 5 * standard_error, (mean, centre, std)
        assert abs(float(spread / std) - 1.0) < 0.02
        assert float(std) > 0.05  # the head is random, not vanishing: the check has teeth


# ------------------------------------------------------------------------ training, saving


@pytest.mark.parametrize("relevance", ["paper", "default"])
def test_training_moves_mean_log_std_lambda_and_entropy_and_repeats_exactly(tmp_path, relevance):
    def run():
        model = _sac_model("pendulum", relevance, seed=4, learning_starts=20, batch_size=16)
        before = copy.deepcopy(model.actor.state_dict())
        coef_before = float(model.log_ent_coef.detach())
        model.learn(60)
        return model, before, coef_before

    model, before, coef_before = run()
    after = model.actor.state_dict()
    moved = (RELEVANCE_PARAMETER[relevance], "log_std.weight", "hybrid.nonlinear.mean.weight")
    for name in moved:
        assert not torch.equal(before[name], after[name]), name
    assert float(model.log_ent_coef.detach()) != coef_before
    again, _, _ = run()
    for name, value in after.items():
        assert torch.equal(value, again.actor.state_dict()[name]), name
    # SB3's save/load rebuilds the hybrid actor with its learned parameters
    model.save(tmp_path / "sac.zip")
    loaded = LeocSAC.load(tmp_path / "sac.zip", device="cpu")
    assert isinstance(loaded.actor, HybridSACActor)
    probe = torch.randn(16, 3, generator=torch.Generator().manual_seed(1))
    with torch.no_grad():
        assert torch.equal(loaded.actor(probe, True), model.actor(probe, True))


def test_actor_learning_rate_and_target_update_interval():
    env = make_env("pendulum")
    model = LeocSAC(
        "MlpPolicy",
        env,
        learning_rate=1e-3,
        actor_learning_rate=2e-4,
        target_update_interval=3,
        learning_starts=16,
        batch_size=8,
        policy_kwargs={"net_arch": [8]},
        seed=0,
        device="cpu",
    )
    model.learn(16)  # fill the buffer; no update yet
    assert model._n_updates == 0
    changed = []
    for _ in range(6):
        target = [p.detach().clone() for p in model.critic_target.parameters()]
        model.train(gradient_steps=1, batch_size=8)
        moved = any(
            not torch.equal(a, b)
            for a, b in zip(target, model.critic_target.parameters(), strict=True)
        )
        changed.append(moved)
    assert changed == [False, False, True, False, False, True]
    assert model.actor.optimizer.param_groups[0]["lr"] == pytest.approx(2e-4)
    assert model.critic.optimizer.param_groups[0]["lr"] == pytest.approx(1e-3)
    assert model.tau == model.polyak


def _filled_sac_pair(critic_loss: str, **kw) -> list[LeocSAC]:
    """Two identical hybrid SAC models (mountain car: it can leave, so the buffer holds an
    exit's large reward) whose buffers hold the same 48 steps, no update yet."""
    models = []
    for _ in range(2):
        system = make_system("mountaincar")
        model = LeocSAC(
            HybridSACPolicy,
            make_env(system),
            policy_kwargs=hybrid_policy_kwargs(system, net_arch=SMALL_NET),
            learning_starts=48,
            batch_size=16,
            critic_loss=critic_loss,
            seed=3,
            device="cpu",
            **kw,
        )
        model.learn(48)
        models.append(model)
    return models


def _same_state(first: LeocSAC, second: LeocSAC) -> bool:
    state_a, state_b = first.policy.state_dict(), second.policy.state_dict()
    coefs = torch.equal(first.log_ent_coef, second.log_ent_coef)
    return coefs and all(torch.equal(state_a[key], state_b[key]) for key in state_a)


@pytest.mark.parametrize("interval", [1, 3])
def test_own_sac_step_with_mse_is_sb3_bit_for_bit_and_huber_changes_the_critics(
    interval, monkeypatch
):
    """``critic_loss="mse"`` runs SB3's ``SAC.train``; the own step that ``"huber"`` runs
    (:meth:`LeocSAC._train_step`), given the MSE loss, leaves the same parameters, entropy
    coefficient and targets, update for update, with the targets' interval counted alike."""
    sb3, own = _filled_sac_pair("mse", target_update_interval=interval)
    huber, _ = _filled_sac_pair("huber", target_update_interval=interval)
    assert _same_state(sb3, own) and _same_state(sb3, huber)
    for model in (sb3, huber):
        _seed_global(0)
        model.train(gradient_steps=5, batch_size=16)
    assert not _same_state(sb3, huber)  # the Huber loss changes the update
    own.critic_loss = "huber"  # the own step's path ...
    monkeypatch.setattr(sac_module, "critic_loss_fn", lambda _: critic_loss_fn("mse"))  # ... MSE
    _seed_global(0)
    own.train(gradient_steps=5, batch_size=16)
    assert own._n_updates == sb3._n_updates == 5
    assert _same_state(sb3, own)


def _seed_global(seed: int) -> None:
    """SB3's replay buffer samples with numpy's *global* generator, SAC's actions with torch's."""
    np.random.seed(seed)  # noqa: NPY002 (SB3's sampling uses the legacy global generator)
    torch.manual_seed(seed)


def test_sacs_loss_is_huber_on_sb3s_critics_by_default_and_options():
    sac = DDPGConfig.for_system("cartpole", algo="sac")
    assert sac.critic_loss == "huber"  # DDPG's loss (issue 20) on SB3's critics
    assert sac.network_kwargs() == {
        "critic_action_layer": 0,
        "critic_action_units": "normalised",
        "hidden_init": "torch",
        "last_layer_init": None,
    }
    assert DDPGConfig.for_system("cartpole", algo="sac", critic_loss="mse").critic_loss == "mse"
    with pytest.raises(ValueError, match="critic_loss: expected one of"):
        LeocSAC("MlpPolicy", make_env("pendulum"), critic_loss="l1")


@pytest.mark.parametrize("hybrid", [False, True])
def test_sac_critic_layout_and_tf_agents_initialisation(hybrid):
    """The DDPG critic options on SAC's twin critics and actor: obs -> 400 -> concat(physical
    action) -> 300 -> 1 for each critic, TF-Agents' initialisation (hidden layers
    U(+/- 1/sqrt(fan_in)), zero biases, output U(+/-0.003)) on the critics and on the actor's
    hidden layers and mean head; SB3's log-std head; a hybrid keeps its identities."""
    system = make_system("cartpole")
    env = make_env(system)
    limit = 0.003
    kwargs = {
        "net_arch": [400, 300],
        "critic_action_layer": 1,
        "critic_action_units": "physical",
        "hidden_init": "tf_agents",
        "last_layer_init": limit,
    }
    if hybrid:
        kwargs = hybrid_policy_kwargs(system, **kwargs)
    model = LeocSAC(HybridSACPolicy if hybrid else LeocSACPolicy, env, policy_kwargs=kwargs, seed=0)
    critic = model.critic
    assert isinstance(critic, SplitCritic) and len(critic.q_networks) == 2
    for q_net in critic.q_networks:
        linears = [m for m in q_net.modules() if isinstance(m, nn.Linear)]
        shapes = [(m.in_features, m.out_features) for m in linears]
        assert shapes == [(5, 400), (401, 300), (300, 1)]
        _assert_tf_agents_init(linears, limit)
    actor = model.actor
    mean = actor.nonlinear if hybrid else SquashedMean(actor.latent_pi, actor.mu)
    _assert_tf_agents_init([m for m in mean.modules() if isinstance(m, nn.Linear)], limit)
    bound = 1.0 / math.sqrt(300)  # PyTorch's default on the log-std head, not TF-Agents'
    assert float(actor.log_std.bias.detach().abs().max()) > 0.0
    assert float(actor.log_std.weight.detach().abs().max()) <= bound
    for key, value in critic.state_dict().items():  # the targets start as copies
        assert torch.equal(model.critic_target.state_dict()[key], value)
    probe = torch.randn(4, 5, generator=torch.Generator().manual_seed(0))
    with torch.no_grad():  # the critic sees the physical action: c + h * normalised
        features = critic.extract_features(probe, critic.features_extractor)
        action = torch.full((4, 1), 0.5)
        first = critic.q_networks[0]
        joint = torch.cat([first.head(features), action * system.action_limit], dim=1)
        torch.testing.assert_close(critic(probe, action)[0], first.tail(joint), rtol=0, atol=0)
    if hybrid:  # pi(a) = G(a) and d pi / dx (a) = W, G from an independent LQR design
        design = design_lqr(system)
        policy = physical_policy(actor)
        point = torch.as_tensor(system.operating_obs, dtype=torch.float64)
        value = policy(point[None, :])[0].detach().numpy()
        np.testing.assert_allclose(value, design.W @ system.operating_obs + design.b, atol=1e-12)
        jacobian = torch.autograd.functional.jacobian(lambda x: policy(x[None, :])[0], point)
        np.testing.assert_allclose(jacobian.numpy(), design.W, rtol=0, atol=1e-10)


def _assert_tf_agents_init(linears: list, limit: float) -> None:
    for layer in linears[:-1]:
        bound = 1.0 / math.sqrt(layer.in_features)  # VarianceScaling(1/3, fan_in, uniform)
        weights = layer.weight.detach().abs()
        assert 0.9 * bound < float(weights.max()) <= bound
        assert torch.equal(layer.bias.detach(), torch.zeros_like(layer.bias))
    assert float(linears[-1].weight.detach().abs().max()) <= limit
    assert torch.equal(linears[-1].bias.detach(), torch.zeros_like(linears[-1].bias))


def test_sac_action_noise_adds_ddpgs_ou_process_to_sacs_samples():
    """With ``sac_action_noise`` the action SAC applies (and stores) is its own sample plus
    DDPG's OU noise (physical units: divided by the half-width in SB3's normalised action),
    clipped to the box; without it, SAC's sample alone."""
    nets = {"actor_hidden": (16, 16), "critic_hidden": (16, 16)}
    config = DDPGConfig.for_system("cartpole", algo="sac", sac_action_noise=True, **nets)
    env = make_env("cartpole")
    noisy = build_model(config, seed=5, env=env)
    assert isinstance(noisy.action_noise, SeededOUNoise)
    assert (noisy.action_noise.theta, noisy.action_noise.sigma) == (0.2, 1.0)  # DDPG's
    reference = exploration_noise(config, env.action_space, seed=5)  # the same stream
    plain_config = DDPGConfig.for_system("cartpole", algo="sac", **nets)
    plain = build_model(plain_config, seed=5, env=make_env("cartpole"))
    assert plain.action_noise is None
    plain.policy.load_state_dict(noisy.policy.state_dict())
    obs = np.array([[0.1, 0.0, -1.0, 0.0, 0.5]], dtype=np.float32)  # hanging, spinning
    for model in (plain, noisy):
        model.num_timesteps = 10_000  # past the warm-up: SAC's own samples
        model._last_obs = obs
    steps = []
    for _ in range(6):
        torch.manual_seed(11)
        _, own = plain._sample_action(0, None)
        torch.manual_seed(11)
        _, applied = noisy._sample_action(0, noisy.action_noise)
        step = reference()
        steps.append(float(step[0]))
        np.testing.assert_allclose(applied, np.clip(own + step, -1.0, 1.0), rtol=0, atol=1e-6)
    half = make_system("cartpole").action_limit
    assert max(abs(value) for value in steps) * half > 0.5  # the noise is there (newtons)


def test_train_ddpg_sac_writes_a_run_that_loads(tmp_path):
    result = train_ddpg(
        "mountaincar", algo="sac", hybrid=True, seed=2, run_dir=tmp_path, **TINY_RUN
    )
    config = json.loads((tmp_path / "config.json").read_text())
    assert config["algo"] == "sac" and config["hybrid"] == HybridSpec().to_dict()
    assert config["polyak"] == SAC_DEFAULTS["polyak"] and config["total_steps"] == 240
    assert [row["steps"] for row in result.curve] == [0, 120, 240]
    policy = load_ddpg_controller(tmp_path)
    assert policy.is_hybrid
    obs = torch.randn(8, 2, dtype=torch.float64)
    torch.testing.assert_close(policy(obs), result.policy(obs), rtol=0, atol=0)


def test_baseline_physical_policy_is_sacs_deterministic_action():
    model = SAC("MlpPolicy", make_env("cartpole"), policy_kwargs={"net_arch": SMALL_NET}, seed=1)
    obs = torch.randn(32, 5, generator=torch.Generator().manual_seed(2), dtype=torch.float64)
    limit = make_system("cartpole").action_limit
    policy = physical_policy(model.actor)
    assert not policy.is_hybrid
    with torch.no_grad():
        expected = model.actor(obs.float(), deterministic=True).double() * limit
        predicted = model.predict(obs.float().numpy(), deterministic=True)[0]  # physical
        np.testing.assert_allclose(policy(obs).numpy(), expected.numpy(), rtol=0, atol=F32_ATOL)
    np.testing.assert_allclose(policy(obs).numpy(), predicted, rtol=0, atol=F32_ATOL)


# ----------------------------------------------------------------------------- config, CLI


def test_variants_give_sac_their_lqr_and_rules_but_no_ddpg_settings():
    from leoc.experiments.variants import AUTHORS, LEOC

    assert LEOC.training_settings("sac", "cartpole", True, 400) == {"total_steps": 400}
    settings = AUTHORS.training_settings("sac", "cartpole", True, 400)
    assert settings["lqr_method"] == "authors" and settings["total_steps"] == 400
    assert settings["step_rules"]["exit_penalty"] == -100.0
    config = DDPGConfig.for_system("cartpole", "sac", hybrid=True, **settings)
    assert config.ou_sigma == DDPGConfig.ou_sigma and config.batch_size == 256
    with pytest.raises(ValueError, match="framework: expected one of"):
        LEOC.training_settings("ppo", "cartpole", True)


def test_sac_config_defaults_leave_ddpg_unchanged():
    ddpg = DDPGConfig.for_system("cartpole")
    sac = DDPGConfig.for_system("cartpole", algo="sac")
    assert sac.total_steps == ddpg.total_steps == 21_000  # the same budgets
    assert sac.step_rules == ddpg.step_rules == {"reward_on_next_state": True}  # the same rules
    assert sac.model_selection == ddpg.model_selection == "best_held"
    assert (sac.warmup, sac.learning_starts) == ("uniform", 200)  # SB3's start, not DDPG's
    for name, value in SAC_DEFAULTS.items():
        assert getattr(sac, name) == value
    assert (ddpg.batch_size, ddpg.polyak, ddpg.actor_learning_rate) == (64, 0.05, 5e-4)
    assert sac.actor_hidden == sac.critic_hidden == (400, 300)
    assert sac.sac_entropy_coef == "auto"
    assert DDPGConfig.for_system("pendulum", algo="sac", batch_size=64).batch_size == 64
    assert DDPGConfig.from_dict(sac.as_dict()) == sac


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        ({"algo": "ppo"}, "algo: expected one of"),
        ({"algo": "sac", "ou_sigma": 0.3}, "ou_sigma: SAC uses the OU exploration only with"),
        ({"algo": "sac", "sac_action_noise": 1}, "sac_action_noise: expected a bool"),
        ({"algo": "ddpg", "sac_action_noise": True}, "sac_action_noise: only SAC uses it"),
        ({"algo": "sac", "actor_output_clip": False}, "actor_output_clip: only DDPG and TD3"),
        ({"algo": "td3", "sac_entropy_coef": 0.1}, "sac_entropy_coef: only SAC uses it"),
        ({"algo": "sac", "sac_entropy_coef": "auto_x"}, "sac_entropy_coef: expected 'auto'"),
        ({"algo": "sac", "sac_entropy_coef": -1.0}, "sac_entropy_coef: expected 'auto'"),
        ({"algo": "sac", "sac_target_entropy": "low"}, "sac_target_entropy: expected"),
        ({"algo": "sac", "hybrid": "yes"}, "hybrid: expected None"),
    ],
)
def test_bad_config_is_an_error_naming_the_field(overrides, message):
    algo = overrides.pop("algo")
    with pytest.raises(ValueError, match=message):
        DDPGConfig.for_system("pendulum", algo=algo, **overrides)


def test_what_cannot_be_a_sac_hybrid_is_refused():
    kwargs = hybrid_policy_kwargs("pendulum", net_arch=SMALL_NET)
    with pytest.raises(ValueError, match="use_sde: the SAC hybrid needs"):
        SAC(HybridSACPolicy, make_env("pendulum"), policy_kwargs=kwargs, use_sde=True)
    with pytest.raises(ValueError, match="clip_output: the SAC hybrid"):
        SAC(HybridSACPolicy, make_env("pendulum"), policy_kwargs={**kwargs, "clip_output": False})
    with pytest.raises(ValueError, match="relevance: expected one of"):
        SAC(
            HybridSACPolicy,
            make_env("pendulum"),
            policy_kwargs={**kwargs, "hybrid_spec": {"relevance": "flat"}},
        )
    with pytest.raises(ValueError, match="algo: expected one of"):
        train_ddpg("pendulum", algo="pilco", hybrid=True, run_dir=None, progress=False)


def test_cli_trains_a_sac_hybrid_that_simulate_reads(tmp_path, monkeypatch, capsys):
    from leoc.cli import main

    # tiny networks and batches through the command's own defaults
    tiny = {"actor_hidden": (16, 16), "critic_hidden": (16, 16), "batch_size": 32}
    for name, value in tiny.items():
        monkeypatch.setitem(SAC_DEFAULTS, name, value)
    out = tmp_path / "sac"
    argv = ["train", "pendulum", "--algo", "sac", "--hybrid", "--steps", "300", "--out", str(out)]
    assert main([*argv, "--quiet", "--seed", "3"]) == 0
    config = json.loads((out / "config.json").read_text())
    assert (config["algo"], config["hybrid"], config["actor_hidden"]) == (
        "sac",
        HybridSpec().to_dict(),
        [16, 16],
    )
    capsys.readouterr()
    assert main(["simulate", str(out), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert (report["system"], report["controller"]) == ("pendulum", str(out))
    assert len(report["deviation"]) == make_system("pendulum").episode_steps + 1
    assert "steady_state_error" in report["metrics"]


@pytest.mark.parametrize(
    ("argv", "expected"),
    [
        (["--algo", "sac", "--iterations", "3"], "--iterations: only for --algo pilco"),
        (["--algo", "pilco", "--steps", "300"], "--steps: only for --algo ddpg/td3/sac"),
        (["--algo", "ppo"], "invalid choice: 'ppo'"),
    ],
)
def test_cli_budget_and_algo_errors_name_the_argument(argv, expected, capsys):
    from leoc.cli import main

    try:
        status = main(["train", "pendulum", *argv])
    except SystemExit as stop:
        status = stop.code
    assert status == 2
    assert expected in capsys.readouterr().err


def test_progress_lines_name_sac_and_the_eta_reads_them():
    from leoc.experiments.eta import trainer_progress
    from leoc.sb3.callbacks import LearningCurveCallback

    callback = LearningCurveCallback(
        make_system("pendulum"),
        np.zeros((1, 2)),
        500,
        progress="lines",
        total_steps=1000,
        label="sac",
    )
    callback.num_timesteps = 250
    line = callback.progress_line()
    assert line.startswith("[sac] step 250/1000 (25%)")
    assert trainer_progress(line) == 0.25


# ---------------------------------------------------------------------------------- reproduce


def test_sac_controllers_are_named_but_not_default():
    from leoc.experiments.profiles import LINEAR_REFERENCE, RunSpec
    from leoc.names import CONTROLLERS, DEFAULT_CONTROLLERS

    for name in ("sac_baseline", "sac_hybrid", "sac_hybrid_roa"):
        assert name in CONTROLLERS and name not in DEFAULT_CONTROLLERS
    spec = RunSpec("cartpole", "sac_hybrid_roa", 1)
    controller = spec.controller_spec
    assert (controller.learner, controller.hybrid.relevance) == ("sac", "roa") and spec.hybrid
    assert LINEAR_REFERENCE["sac"] == "linear"


@pytest.mark.slow
def test_reproduce_smoke_gives_a_sac_hybrid_row(tmp_path):
    from leoc.experiments.reproduce import reproduce

    path = reproduce(
        tmp_path,
        profile_name="smoke",
        systems=["pendulum"],
        controllers=["linear", "sac_hybrid"],
        jobs=1,
        echo=lambda _: None,
    )
    results = json.loads((tmp_path / "results.json").read_text())
    rows = [row for row in results["responses"] if row["controller"] == "sac_hybrid"]
    assert {row["test"] for row in rows} == {"impulse", "step"}
    run = json.loads(
        (tmp_path / "runs" / "pendulum" / "sac_hybrid" / "seed0" / "evaluation.json").read_text()
    )
    assert run["spec"]["controller"] == "sac_hybrid" and run["curve"]["seconds"]
    train_config = json.loads(
        (
            tmp_path / "runs" / "pendulum" / "sac_hybrid" / "seed0" / "train" / "config.json"
        ).read_text()
    )
    assert train_config["algo"] == "sac" and train_config["total_steps"] == 400
    report = path.read_text()
    assert "SAC hybrid" in report
