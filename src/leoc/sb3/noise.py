r"""Seeded Ornstein-Uhlenbeck exploration noise (Lillicrap et al., 2016).

.. math::

    n_{t+1} = n_t + \theta (\mu - n_t) + \sigma \varepsilon_t, \qquad
    \varepsilon_t \sim \mathcal N(0, I), \qquad n_0 = \mu

with unit time step. SB3 adds the returned noise to the *normalised* action in [-1, 1] (then
clips); ``scale`` maps the process's own units to those: ``scale = 1`` (default) runs the
process on the normalised action (leoc: theta 0.15, sigma 0.2, as in the DDPG paper), and
``scale = 1 / h`` with ``h`` the half-width of the action box runs it in *physical* action units,
as TF-Agents' ``OUProcess`` does inside ``OUNoisePolicy`` (``x <- (1 - damping) x +
N(0, stddev^2)``, i.e. theta = damping, sigma = stddev, mu = 0; nrjc/LEOC uses damping 0.2,
stddev 1.0 in newtons or newton-metres). The stationary standard deviation of the process is
:math:`\sigma / \sqrt{1 - (1 - \theta)^2} = \sigma / \sqrt{\theta (2 - \theta)}` (about 0.38
for leoc's, 1.67 for the authors'), its correlation time about :math:`1 / \theta` steps.

SB3 calls ``reset`` at every episode end; ``reset_each_episode=False`` makes that a no-op, so the
process runs on across episodes (TF-Agents never resets it). Unlike SB3's
``OrnsteinUhlenbeckActionNoise``, which draws from numpy's global generator, this process owns a
``numpy.random.Generator`` seeded by the run's seed.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
from stable_baselines3.common.noise import ActionNoise

from leoc.sb3.common import action_box

if TYPE_CHECKING:
    from leoc.sb3.config import DDPGConfig

__all__ = ["NOISE_SEED_OFFSET", "SeededOUNoise", "exploration_noise"]

#: Seed offset of the exploration noise's own stream (evaluation: :mod:`leoc.training`).
NOISE_SEED_OFFSET = 20_000


class SeededOUNoise(ActionNoise):
    """Ornstein-Uhlenbeck process with its own seeded generator.

    Parameters
    ----------
    size : int
        Action dimension F.
    theta : float
        Mean reversion per step (> 0; TF-Agents' ``damping``).
    sigma : float
        Scale of the per-step innovation (>= 0; TF-Agents' ``stddev``).
    seed : int
        Seed of the process's ``numpy.random.Generator``.
    mean : float
        Long-run mean mu (in the process's units).
    scale : float or array-like (F,)
        Positive factor from the process's units to the normalised action SB3 adds the noise
        to: 1 (the process is on the normalised action) or ``1 / h`` (physical units).
    reset_each_episode : bool
        Whether :meth:`reset` (called by SB3 at each episode end) restarts the process at its
        mean; False: the process is never reset.
    """

    def __init__(
        self,
        size: int,
        theta: float,
        sigma: float,
        seed: int,
        mean: float = 0.0,
        scale: float | np.ndarray = 1.0,
        reset_each_episode: bool = True,
    ) -> None:
        super().__init__()
        if not theta > 0 or not sigma >= 0:
            raise ValueError(f"theta > 0 and sigma >= 0 expected, found {theta}, {sigma}")
        self.size, self.theta, self.sigma, self.mean = int(size), theta, sigma, mean
        factor = np.broadcast_to(np.asarray(scale, dtype=np.float64), (self.size,)).copy()
        if not np.all(np.isfinite(factor) & (factor > 0)):
            raise ValueError(f"scale: expected positive finite numbers, found {factor.tolist()}")
        self.scale = factor
        self.reset_each_episode = bool(reset_each_episode)
        self.rng = np.random.default_rng(seed)
        self.state = np.full(self.size, mean)

    def reset(self) -> None:
        """Restart the process at its mean, unless ``reset_each_episode`` is False."""
        if self.reset_each_episode:
            self.state = np.full(self.size, self.mean)

    def __call__(self) -> np.ndarray:
        """Advance the process one step; the new state in normalised action units (float32)."""
        innovation = self.rng.standard_normal(self.size)
        self.state = self.state + self.theta * (self.mean - self.state) + self.sigma * innovation
        return (self.state * self.scale).astype(np.float32)

    def __repr__(self) -> str:
        return (
            f"SeededOUNoise(size={self.size}, theta={self.theta}, sigma={self.sigma}, "
            f"scale={self.scale.tolist()}, reset_each_episode={self.reset_each_episode})"
        )


def exploration_noise(config: DDPGConfig, action_space: Any, seed: int) -> SeededOUNoise:
    """The run's OU exploration noise (DDPG and TD3; SAC with ``sac_action_noise``):
    ``ou_theta``, ``ou_sigma`` in ``noise_units`` (physical units divide by the action box's
    half-width h, since SB3 adds it to the normalised action), reset at episode ends if
    ``noise_reset``, seeded by ``seed +`` :data:`NOISE_SEED_OFFSET`."""
    _, half = action_box(action_space)
    scale = 1.0 / half if config.noise_units == "physical" else np.ones_like(half)
    return SeededOUNoise(
        half.size,
        config.ou_theta,
        config.ou_sigma,
        seed + NOISE_SEED_OFFSET,
        scale=scale,
        reset_each_episode=config.noise_reset,
    )
