"""The relevance's own learning rate (``HybridSpec.relevance_lr_scale``) in leoc's SB3 learners.

References are closed forms: Adam's first step moves a parameter with gradient ``g`` by
``lr * m_hat / (sqrt(v_hat) + eps) = lr * g / (|g| + eps)``, i.e. by ``lr`` against the sign
of ``g`` (to a relative ``eps / |g|``); SB3 sets every optimiser group's rate to its schedule's
(leoc's actor to ``actor_learning_rate``) on each ``train`` call, after which the relevance's
group must run at that rate times the scale.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch
from stable_baselines3.common.callbacks import BaseCallback

from leoc.pilco.config import PilcoConfig
from leoc.policies import HybridSpec
from leoc.sb3 import DDPGConfig, LeocDDPG, LeocSAC, LeocTD3, build_model, train_ddpg
from leoc.sb3.checkpoint import CHECKPOINT_FILE
from leoc.sb3.train import load_ddpg_model
from leoc.systems import make_env

pytestmark = pytest.mark.usefixtures("single_thread")

SCALE = 8.0
ACTOR_LR = 1e-3
CRITIC_LR = 2e-3  # not the actor's, so a group left at the critic's rate shows
MOVE_RTOL = 1e-3  # Adam's eps / |g| and float32 round-off of the difference
GRAD_FLOOR = 1e-4  # coordinates whose gradient is this large: eps / |g| <= 1e-4
NEAR_STD = 0.5  # spread of the replayed states about the operating point
TINY = {
    "actor_hidden": (8,),
    "critic_hidden": (8, 8),
    "learning_starts": 60,
    "batch_size": 32,
    "buffer_size": 1_000,
    "actor_learning_rate": ACTOR_LR,
    "critic_learning_rate": CRITIC_LR,
    # PyTorch's initialisation: TF-Agents' 0.003 output layer leaves the hidden layers' first
    # gradients too small for the closed form to read (below GRAD_FLOOR)
    "hidden_init": "torch",
    "last_layer_init": None,
}
ALGO_CLASSES = {"ddpg": LeocDDPG, "td3": LeocTD3, "sac": LeocSAC}
# (algo, relevance, config overrides): leoc's own update (Huber loss) and SB3's (MSE)
CASES = [
    ("ddpg", "paper", {}),
    ("ddpg", "paper", {"critic_loss": "mse", "target_update_interval": 1}),
    ("ddpg", "roa", {}),
    ("td3", "paper", {}),
    ("td3", "paper", {"critic_loss": "mse"}),
    ("sac", "paper", {}),
    ("sac", "paper", {"critic_loss": "mse"}),
    ("sac", "roa", {}),
]


def _model(algo: str, relevance: str = "paper", scale: float = SCALE, **overrides):
    spec = HybridSpec(relevance=relevance, relevance_lr_scale=scale, **overrides.pop("spec", {}))
    config = DDPGConfig.for_system("pendulum", algo, hybrid=spec, **{**TINY, **overrides})
    return build_model(config, seed=0, env=make_env("pendulum"))


def _is_relevance(name: str) -> bool:
    """The relevance's parameters by their state-dict names (paper: the policy's own
    ``log_lambda``; any other relevance: the ``relevance_module`` submodule)."""
    return name.endswith("hybrid.log_lambda") or ".relevance_module." in name


def _one_actor_update(model) -> tuple[dict, dict, dict]:
    """Fill the buffer without an update, then train until the actor has had exactly one
    update (TD3: ``policy_delay`` gradient steps). Returns the actor's parameters before,
    after, and their gradients."""
    model.learn(total_timesteps=model.learning_starts)
    assert model._n_updates == 0
    # the stored states near the operating point, so that an ROA relevance's band (where its
    # width has a gradient) holds some of them; the hanging pendulum's own states lie far out
    buffer = model.replay_buffer
    noise = np.random.default_rng(0).normal(0.0, NEAR_STD, buffer.observations[: buffer.pos].shape)
    buffer.observations[: buffer.pos] = model.actor.operating_obs.numpy() + noise
    before = {name: p.detach().clone() for name, p in model.actor.named_parameters()}
    model.train(gradient_steps=getattr(model, "policy_delay", 1), batch_size=model.batch_size)
    after = {name: p.detach().clone() for name, p in model.actor.named_parameters()}
    grads = {name: p.grad for name, p in model.actor.named_parameters()}
    return before, after, grads


def _group_rates(optimizer) -> list[float]:
    return [group["lr"] for group in optimizer.param_groups]


@pytest.mark.parametrize(("algo", "relevance", "overrides"), CASES)
def test_one_update_moves_the_relevance_by_the_scaled_rate(algo, relevance, overrides):
    """After the actor's first Adam step every coordinate with a gradient moved by its group's
    rate: ``ACTOR_LR * SCALE`` for the relevance, ``ACTOR_LR`` for every other actor weight."""
    model = _model(algo, relevance, **overrides)
    before, after, grads = _one_actor_update(model)
    checked = {True: 0, False: 0}
    for name, grad in grads.items():
        if grad is None:
            continue
        rate = ACTOR_LR * SCALE if _is_relevance(name) else ACTOR_LR
        mask = grad.abs() > GRAD_FLOOR
        moved = (before[name] - after[name])[mask]
        expected = rate * torch.sign(grad[mask])
        torch.testing.assert_close(moved, expected, rtol=MOVE_RTOL, atol=0.0, msg=name)
        checked[_is_relevance(name)] += int(mask.sum())
    assert checked[True] > 0 and checked[False] > 0, checked


@pytest.mark.parametrize("algo", ["ddpg", "td3", "sac"])
def test_group_rates_after_sb3_resets_them(algo):
    """Two groups, ``[ACTOR_LR, ACTOR_LR * SCALE]`` after every train call (no compounding),
    and under a schedule both follow it; the critics (and SAC's entropy coefficient) keep one
    group at the critic's rate."""
    model = _model(algo)
    groups = model.actor.optimizer.param_groups
    assert len(groups) == 2 and "lr_scale" not in groups[0] and groups[1]["lr_scale"] == SCALE
    assert [id(p) for p in groups[1]["params"]] == [
        id(p) for name, p in model.actor.named_parameters() if _is_relevance(name)
    ]
    _one_actor_update(model)
    model.train(gradient_steps=3, batch_size=model.batch_size)
    assert _group_rates(model.actor.optimizer) == [ACTOR_LR, ACTOR_LR * SCALE]
    others = [model.critic.optimizer]
    if algo == "sac":
        others.append(model.ent_coef_optimizer)
    for optimizer in others:
        assert _group_rates(optimizer) == [CRITIC_LR]
        assert "lr_scale" not in optimizer.param_groups[0]
    model.lr_schedule = lambda progress: CRITIC_LR * progress
    model._current_progress_remaining = 0.25
    model._update_learning_rate([model.actor.optimizer, *others])
    rates = _group_rates(model.actor.optimizer)
    assert rates == pytest.approx([0.25 * ACTOR_LR, 0.25 * ACTOR_LR * SCALE], rel=1e-12)
    assert _group_rates(model.critic.optimizer) == pytest.approx([0.25 * CRITIC_LR], rel=1e-12)


@pytest.mark.parametrize("algo", ["ddpg", "td3", "sac"])
@pytest.mark.parametrize(
    ("scale", "spec"), [(1.0, {}), (1.0, {"relevance": "roa"}), (SCALE, {"learn_lambda": False})]
)
def test_scale_one_or_nothing_to_scale_keeps_sb3s_single_group(algo, scale, spec):
    """Scale 1 (or a frozen paper relevance, which has no parameter to scale) leaves SB3's
    optimiser: one group over the actor's parameters in their order, at one rate."""
    model = _model(algo, spec.pop("relevance", "paper"), scale=scale, spec=spec)
    (group,) = model.actor.optimizer.param_groups
    assert "lr_scale" not in group
    assert [id(p) for p in group["params"]] == [id(p) for p in model.actor.parameters()]
    _one_actor_update(model)
    assert _group_rates(model.actor.optimizer) == [ACTOR_LR]


@pytest.mark.parametrize("algo", ["ddpg", "td3", "sac"])
def test_a_saved_model_loads_its_groups_and_trains_on(tmp_path, algo):
    """SB3's zip keeps both groups, their scale and Adam's state; the loaded model's relevance
    group holds its own relevance parameters and trains on at the scaled rate."""
    model = _model(algo)
    _one_actor_update(model)
    model.save(tmp_path / "model.zip")
    loaded = ALGO_CLASSES[algo].load(tmp_path / "model.zip", env=make_env("pendulum"))
    saved, back = model.actor.optimizer.state_dict(), loaded.actor.optimizer.state_dict()
    assert back["param_groups"] == saved["param_groups"]
    for index, state in saved["state"].items():
        for key, value in state.items():
            assert torch.equal(back["state"][index][key], value)
    relevance = [p for name, p in loaded.actor.named_parameters() if _is_relevance(name)]
    groups = loaded.actor.optimizer.param_groups
    assert [id(p) for p in groups[1]["params"]] == [id(p) for p in relevance]
    start = [p.detach().clone() for p in relevance]
    loaded.learn(total_timesteps=5, reset_num_timesteps=False)
    assert _group_rates(loaded.actor.optimizer) == [ACTOR_LR, ACTOR_LR * SCALE]
    assert any(not torch.equal(a, p) for a, p in zip(start, relevance, strict=True))


class _StopAt(BaseCallback):
    """Interrupts training (as Ctrl-C does) once ``steps`` environment steps are done."""

    def __init__(self, steps: int) -> None:
        super().__init__()
        self.steps = steps

    def _on_step(self) -> bool:
        if self.num_timesteps == self.steps:
            raise KeyboardInterrupt
        return True


@pytest.mark.slow
@pytest.mark.parametrize("algo", ["ddpg", "sac"])
def test_a_run_with_the_scale_resumes_exactly_and_loads(tmp_path, algo):
    """``train_ddpg`` with the scale: interrupted after its checkpoint and rerun it ends with the
    uninterrupted run's weights and optimiser to the last bit, and its saved model loads with
    both groups."""
    spec = HybridSpec(relevance_lr_scale=SCALE)
    tiny = {
        **TINY,
        "total_steps": 200,
        "learning_starts": 40,
        "eval_interval": 100,
        "eval_episodes": 1,
        "checkpoint_interval": 100,
        "progress": False,
    }
    whole = train_ddpg("pendulum", algo, hybrid=spec, seed=2, run_dir=tmp_path / "w", **tiny)
    cut = tmp_path / "cut"
    with pytest.raises(KeyboardInterrupt):
        train_ddpg("pendulum", algo, spec, 2, cut, callbacks=[_StopAt(150)], **tiny)
    assert (cut / CHECKPOINT_FILE).is_file()
    resumed = train_ddpg("pendulum", algo, hybrid=spec, seed=2, run_dir=cut, **tiny)
    for a, b in zip(
        whole.model.policy.parameters(), resumed.model.policy.parameters(), strict=True
    ):
        assert torch.equal(a, b)
    assert (
        resumed.model.actor.optimizer.state_dict()["param_groups"]
        == (whole.model.actor.optimizer.state_dict()["param_groups"])
    )
    loaded = load_ddpg_model(cut)
    assert _group_rates(loaded.actor.optimizer) == [ACTOR_LR, ACTOR_LR * SCALE]
    assert loaded.actor.optimizer.param_groups[1]["lr_scale"] == SCALE


@pytest.mark.parametrize(
    ("changes", "field"),
    [
        ({"relevance_lr_scale": 2.0}, "relevance_lr_scale"),
        ({"relevance": "lyapunov"}, "relevance"),
    ],
)
def test_pilco_refuses_what_its_hybrid_does_not_implement(changes, field):
    """PILCO's config refuses the scale and the Lyapunov relevance, one line naming the field,
    the expectation and what it found (the floor it takes: test_cli_relevance's
    test_a_floored_pilco_hybrid_from_the_command_line)."""
    spec = HybridSpec()
    for key, value in changes.items():  # "lyapunov" may not be a design here yet
        object.__setattr__(spec, key, value)
    with pytest.raises(ValueError) as error:
        PilcoConfig.for_system("pendulum", hybrid=spec)
    message = str(error.value)
    assert message.startswith(f"{field}: ") and "expected" in message and "\n" not in message
    assert repr(changes[field]) in message
    PilcoConfig.for_system("pendulum", hybrid=dataclasses.replace(spec, **_defaults(changes)))


def _defaults(changes: dict) -> dict:
    fields = {f.name: f.default for f in dataclasses.fields(HybridSpec)}
    return {key: fields[key] for key in changes}
