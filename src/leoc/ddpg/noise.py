r"""Seeded Ornstein-Uhlenbeck exploration noise (Lillicrap et al., 2016).

.. math::

    n_{t+1} = n_t + \theta (\mu - n_t) + \sigma \varepsilon_t, \qquad
    \varepsilon_t \sim \mathcal N(0, I), \qquad n_0 = \mu

on the normalised action in [-1, 1] (unit time step, as in the DDPG paper: theta 0.15,
sigma 0.2). Its stationary standard deviation is :math:`\sigma / \sqrt{\theta (2 - \theta)}`
(about 0.38) and its correlation time about :math:`1 / \theta` steps. Unlike SB3's
``OrnsteinUhlenbeckActionNoise``, which draws from numpy's global generator, this process owns a
``numpy.random.Generator`` seeded by the run's seed.
"""

from __future__ import annotations

import numpy as np
from stable_baselines3.common.noise import ActionNoise

__all__ = ["SeededOUNoise"]


class SeededOUNoise(ActionNoise):
    """Ornstein-Uhlenbeck process with its own seeded generator; reset at every episode end.

    Parameters
    ----------
    size : int
        Action dimension F.
    theta : float
        Mean reversion per step (> 0).
    sigma : float
        Scale of the per-step innovation (>= 0).
    seed : int
        Seed of the process's ``numpy.random.Generator``.
    mean : float
        Long-run mean mu.
    """

    def __init__(self, size: int, theta: float, sigma: float, seed: int, mean: float = 0.0) -> None:
        super().__init__()
        if not theta > 0 or not sigma >= 0:
            raise ValueError(f"theta > 0 and sigma >= 0 expected, found {theta}, {sigma}")
        self.size, self.theta, self.sigma, self.mean = int(size), theta, sigma, mean
        self.rng = np.random.default_rng(seed)
        self.state = np.full(self.size, mean)

    def reset(self) -> None:
        """Restart the process at its mean (called by SB3 at the end of each episode)."""
        self.state = np.full(self.size, self.mean)

    def __call__(self) -> np.ndarray:
        innovation = self.rng.standard_normal(self.size)
        self.state = self.state + self.theta * (self.mean - self.state) + self.sigma * innovation
        return self.state.astype(np.float32)

    def __repr__(self) -> str:
        return f"SeededOUNoise(size={self.size}, theta={self.theta}, sigma={self.sigma})"
