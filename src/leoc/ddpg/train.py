"""Training glue: ``train_ddpg`` runs SB3's DDPG/TD3 (baseline or LEOC hybrid) on one system.

Run folder (every file written atomically: temporary file, then ``os.replace``)::

    config.json         DDPGConfig + seed + library versions
    model.zip           SB3 save of the final model
    best_model.zip      SB3 save of the model with the best evaluation mean return
    curve.json          learning curve + summary (held/reached steps, final and best returns)
    curve.csv           learning curve: steps, interaction_seconds, mean_return, std_return,
                        held_fraction
    learning_curve.png  mean return (+/- std) against interaction time in simulated seconds

"Reached" and "held" (:mod:`leoc.ddpg.rollout` defines the per-episode test):
``reached_steps`` is the first evaluation at which every evaluation episode holds the operating
point; ``held_steps`` the first evaluation from which every later evaluation holds it too.
"""

from __future__ import annotations

import io
import json
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import torch

from leoc.ddpg.algorithms import LeocDDPG, LeocTD3
from leoc.ddpg.callbacks import LearningCurveCallback
from leoc.ddpg.config import DDPGConfig
from leoc.ddpg.noise import SeededOUNoise
from leoc.ddpg.physical import physical_policy
from leoc.ddpg.policies import HybridTD3Policy, hybrid_policy_kwargs
from leoc.io import (
    save_figure_atomic,
    write_bytes_atomic,
    write_csv_atomic,
    write_json_atomic,
    write_text_atomic,
)

__all__ = [
    "DDPGResult",
    "build_model",
    "held_and_reached",
    "load_ddpg_controller",
    "load_ddpg_model",
    "train_ddpg",
]

DEFAULT_RUN_ROOT = Path("runs") / "ddpg"
# Seed offsets: the evaluation env and the exploration noise get their own streams.
EVAL_SEED_OFFSET = 10_000
NOISE_SEED_OFFSET = 20_000
CURVE_COLUMNS = ("steps", "interaction_seconds", "mean_return", "std_return", "held_fraction")
MODEL_FILES = {"final": "model.zip", "best": "best_model.zip"}


class DDPGResult(NamedTuple):
    """Outcome of :func:`train_ddpg`.

    Attributes
    ----------
    policy : torch.nn.Module
        float64 physical-units policy (B, O) -> (B, 1) of the best evaluated model (a
        :class:`~leoc.ddpg.PhysicalPolicy`; for the hybrid pi(a) = G(a), Jacobian W).
    run_dir : Path
    curve : list of dict
        Per evaluation: steps, interaction_seconds, mean_return, std_return, held_fraction,
        returns.
    config : dict
        The run's configuration (DDPGConfig fields + seed).
    held_steps : int or None
        First evaluation step from which every evaluation holds the operating point.
    reached_steps : int or None
        First evaluation step at which every evaluation episode holds the operating point.
    final_return, best_return : float
        Mean evaluation return of the final and of the best model.
    model : stable_baselines3 DDPG or TD3
        The trained SB3 model (final parameters).
    """

    policy: torch.nn.Module
    run_dir: Path
    curve: list[dict[str, Any]]
    config: dict[str, Any]
    held_steps: int | None
    reached_steps: int | None
    final_return: float
    best_return: float
    model: Any


def _atomic_save_model(model: Any, path: Path) -> None:
    buffer = io.BytesIO()
    model.save(buffer)
    write_bytes_atomic(path, buffer.getvalue())


def held_and_reached(curve: list[dict[str, Any]]) -> tuple[int | None, int | None]:
    """``(held_steps, reached_steps)`` of a learning curve (see the module docstring)."""
    reached = next((row["steps"] for row in curve if row["held_fraction"] >= 1.0), None)
    held = None
    for row in reversed(curve):
        if row["held_fraction"] < 1.0:
            break
        held = row["steps"]
    return held, reached


def build_model(config: DDPGConfig, seed: int, env: Any) -> Any:
    """The SB3 model (:class:`LeocDDPG` or :class:`LeocTD3`) of ``config`` on ``env``."""
    from leoc.systems import make_system

    system = make_system(config.system)
    action_dim = int(np.prod(env.action_space.shape))
    policy_kwargs: dict[str, Any] = {
        "net_arch": {"pi": list(config.actor_hidden), "qf": list(config.critic_hidden)}
    }
    policy: Any = "MlpPolicy"
    if config.hybrid:
        policy = HybridTD3Policy
        policy_kwargs = hybrid_policy_kwargs(
            system,
            lambda_init=config.lambda_init,
            learn_lambda=config.learn_lambda,
            lqr_method=config.lqr_method,
            relevance=config.relevance,
            rho_in_fraction=config.roa_rho_fraction,
            width_init=config.roa_width,
            learn_width=config.learn_width,
            **policy_kwargs,
        )
    common: dict[str, Any] = {
        "learning_rate": config.critic_learning_rate,
        "actor_learning_rate": config.actor_learning_rate,
        "buffer_size": config.buffer_size,
        "learning_starts": config.learning_starts,
        "batch_size": config.batch_size,
        "tau": config.polyak,
        "gamma": config.discount,
        "train_freq": config.train_freq,
        "gradient_steps": config.gradient_steps,
        "action_noise": SeededOUNoise(
            action_dim, config.ou_theta, config.ou_sigma, seed + NOISE_SEED_OFFSET
        ),
        "target_update_interval": config.target_update_interval,
        "policy_kwargs": policy_kwargs,
        "seed": seed,
        "device": "cpu",
        "verbose": 0,
    }
    if config.algo == "td3":
        return LeocTD3(
            policy,
            env,
            policy_delay=config.td3_policy_delay,
            target_policy_noise=config.td3_target_noise,
            target_noise_clip=config.td3_target_noise_clip,
            **common,
        )
    return LeocDDPG(policy, env, **common)


def _plot_curve(curve: list[dict[str, Any]], title: str, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    seconds = np.array([row["interaction_seconds"] for row in curve])
    mean = np.array([row["mean_return"] for row in curve])
    std = np.array([row["std_return"] for row in curve])
    fig, axis = plt.subplots(figsize=(6.0, 4.0))
    axis.plot(seconds, mean, marker="o")
    axis.fill_between(seconds, mean - std, mean + std, alpha=0.25)
    axis.set_xlabel("interaction time [simulated s]")
    axis.set_ylabel("evaluation return")
    axis.set_title(title)
    axis.grid(True, alpha=0.3)
    save_figure_atomic(fig, path)


def _write_curve(run_dir: Path, curve: list[dict[str, Any]], summary: dict[str, Any]) -> None:
    write_json_atomic(run_dir / "curve.json", {"curve": curve, "summary": summary}, indent=2)
    write_csv_atomic(run_dir / "curve.csv", curve, CURVE_COLUMNS)


def _versions() -> dict[str, str]:
    import gymnasium
    import stable_baselines3

    return {
        "torch": torch.__version__,
        "stable_baselines3": stable_baselines3.__version__,
        "gymnasium": gymnasium.__version__,
        "numpy": np.__version__,
    }


def train_ddpg(
    system: str,
    algo: str = "ddpg",
    hybrid: bool = False,
    seed: int = 0,
    run_dir: str | Path | None = None,
    total_steps: int | None = None,
    progress: bool = True,
    **overrides: Any,
) -> DDPGResult:
    """Train DDPG or TD3 (baseline MLP actor or LEOC hybrid) on ``system`` and save the run.

    Parameters
    ----------
    system : str
        ``pendulum``, ``cartpole`` or ``mountaincar``.
    algo : {"ddpg", "td3"}
    hybrid : bool
        LEOC hybrid actor (LQR blended with the MLP) instead of the plain MLP.
    seed : int
        The only seed: SB3 (torch, numpy, random, action space), training env, exploration
        noise (``seed + 20000``) and evaluation starts (``seed + 10000 + k``).
    run_dir : str or Path, optional
        Output folder; default ``runs/ddpg/{system}-{algo}-{hybrid|baseline}-seed{seed}``.
    total_steps : int, optional
        Environment steps; default per system (10k, 15k for the cart-pole).
    progress : bool
        Show a progress bar.
    **overrides
        Any :class:`DDPGConfig` field (``actor_learning_rate=1e-4``, ``eval_interval=500``...).

    Returns
    -------
    DDPGResult
    """
    from leoc.systems import make_env, make_system

    if total_steps is not None:
        overrides["total_steps"] = total_steps
    config = DDPGConfig.for_system(system, algo, hybrid=hybrid, **overrides)
    kind = "hybrid" if hybrid else "baseline"
    run_path = Path(run_dir or DEFAULT_RUN_ROOT / f"{system}-{algo}-{kind}-seed{seed}")
    run_path.mkdir(parents=True, exist_ok=True)
    config_dict = {**config.as_dict(), "seed": seed}
    write_text_atomic(
        run_path / "config.json",
        json.dumps({**config_dict, "versions": _versions()}, indent=2),
    )

    system_obj = make_system(system)
    env = make_env(system)
    eval_env = make_env(system)
    model = build_model(config, seed, env)
    eval_seeds = [seed + EVAL_SEED_OFFSET + k for k in range(config.eval_episodes)]
    callback = LearningCurveCallback(
        eval_env,
        system_obj,
        eval_seeds,
        config.eval_interval,
        config.hold_band,
        config.min_hold_steps,
        save_best=lambda m: _atomic_save_model(m, run_path / MODEL_FILES["best"]),
        progress=progress,
        total_steps=config.total_steps,
    )
    model.learn(total_timesteps=config.total_steps, callback=callback)
    _atomic_save_model(model, run_path / MODEL_FILES["final"])

    curve = callback.curve
    held, reached = held_and_reached(curve)
    summary = {
        "held_steps": held,
        "held_seconds": None if held is None else held * system_obj.dt,
        "reached_steps": reached,
        "reached_seconds": None if reached is None else reached * system_obj.dt,
        "final_return": curve[-1]["mean_return"],
        "best_return": callback.best_return,
        "dt": system_obj.dt,
    }
    _write_curve(run_path, curve, summary)
    _plot_curve(
        curve, f"{system} {algo.upper()} {kind} (seed {seed})", run_path / "learning_curve.png"
    )
    policy = (
        callback.best_policy if callback.best_policy is not None else physical_policy(model.actor)
    )
    env.close()
    eval_env.close()
    return DDPGResult(
        policy,
        run_path,
        curve,
        config_dict,
        held,
        reached,
        float(curve[-1]["mean_return"]),
        float(callback.best_return),
        model,
    )


def load_ddpg_model(run_dir: str | Path, which: str = "best") -> Any:
    """Load the SB3 model of a run folder (``which``: ``"best"`` or ``"final"``), on the CPU."""
    if which not in MODEL_FILES:
        raise ValueError(f"which: expected one of {tuple(MODEL_FILES)}, found {which!r}")
    run_path = Path(run_dir)
    config = json.loads((run_path / "config.json").read_text())
    algo_class = LeocTD3 if config["algo"] == "td3" else LeocDDPG
    return algo_class.load(run_path / MODEL_FILES[which], device="cpu")


def load_ddpg_controller(run_dir: str | Path, which: str = "best") -> torch.nn.Module:
    """float64 physical-units policy of a run folder (best model by default).

    Returns
    -------
    PhysicalPolicy
        Maps float64 observations (B, O) to physical actions (B, 1); for a hybrid run
        ``pi(a) = G(a)`` and ``d pi / dx (a) = W``.
    """
    return physical_policy(load_ddpg_model(run_dir, which).actor)
