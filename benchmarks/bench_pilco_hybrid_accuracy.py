"""Accuracy of the hybrid policy's moment matching against Monte Carlo.

Compares, for Gaussian pendulum and cart-pole states, the action mean and standard deviation of
(a) Gauss-Hermite quadrature over the state (orders 3, 4, 5, 7), (b) the heuristic that
treats the relevance r as the constant r(E[o]) and (c) the authors' mixture heuristic (nrjc/LEOC
``HybridController.compute_action``), against 10^6 Monte Carlo samples. Policies:
LQR of the system + random RBF (the initialisation PILCO starts from), Lambda = I, sin squash.

Prints, per system, a table of each method's absolute error in the action's mean and standard
deviation (average and maximum over 10 random Gaussian states, in units of u_max). Measured on
the pendulum (commit b0b0c4f): the mixture's mean error 0.21 u_max on average (0.47 max), its
std error 0.27 (0.52), against 0.003 (0.012) for order-5 quadrature.

Usage::

    python benchmarks/bench_pilco_hybrid_accuracy.py
"""

from __future__ import annotations

import numpy as np
import torch

from leoc.pilco.config import PilcoConfig
from leoc.pilco.moments import observation_moments
from leoc.pilco.policy import build_policy, obs_layout
from leoc.pilco.propagate import action_moments, observe_torch
from leoc.systems import make_system

SAMPLES = 1_000_000
ORDERS = (3, 4, 5, 7)


def cases(system_name: str, rng: np.random.Generator, count: int):
    system = make_system(system_name)
    dim = system.state_dim
    for _ in range(count):
        mean = rng.normal(0.0, 1.0, dim) * np.where(
            np.isin(np.arange(dim), system.angle_indices), 1.2, 0.5
        )
        factor = rng.normal(0.0, 0.25, (dim, dim))
        yield mean, factor @ factor.T + 0.01 * np.eye(dim)


def main() -> None:
    torch.set_num_threads(1)
    rng = np.random.default_rng(0)
    for name in ("pendulum", "cartpole"):
        system = make_system(name)
        layout = obs_layout(system)
        config = PilcoConfig.for_system(name, hybrid=True)
        errors: dict[str, list[tuple[float, float]]] = {}
        for index, (mean_np, cov_np) in enumerate(cases(name, rng, 10)):
            gen = torch.Generator().manual_seed(index)
            policy = build_policy(system, config, gen)
            with torch.no_grad():
                policy.nonlinear.weights.mul_(10.0)  # a policy that uses its range
                mean = torch.as_tensor(mean_np)
                cov = torch.as_tensor(cov_np)
                noise = torch.randn(SAMPLES, len(mean), generator=gen, dtype=torch.float64)
                states = mean + noise @ torch.linalg.cholesky(cov).T
                actions = policy(observe_torch(states, layout))[:, 0]
                ref_mean, ref_std = float(actions.mean()), float(actions.std())
                obs = observation_moments(mean, cov, layout)
                methods = {f"quadrature order {k}": ("quadrature", k) for k in ORDERS}
                methods["constant r at the mean"] = ("constant_relevance", 0)
                methods["mixture (the authors')"] = ("mixture", 0)
                for label, (method, order) in methods.items():
                    out = action_moments(policy, mean, cov, obs, layout, method, order)
                    errors.setdefault(label, []).append(
                        (
                            abs(float(out.mean[0]) - ref_mean),
                            abs(float(out.cov[0, 0].sqrt()) - ref_std),
                        )
                    )
        limit = system.action_limit
        print(
            f"{name}: 10 random Gaussian states, |error| in units of u_max = {limit} "
            f"(MC standard error of the mean ~ {1 / np.sqrt(SAMPLES):.0e} u_max or less)"
        )
        print(f"  {'method':<24} {'mean err (avg/max)':>20} {'std err (avg/max)':>20}")
        for label, values in errors.items():
            arr = np.asarray(values) / limit
            print(
                f"  {label:<24} {arr[:, 0].mean():9.2e}/{arr[:, 0].max():9.2e} "
                f"{arr[:, 1].mean():9.2e}/{arr[:, 1].max():9.2e}"
            )


if __name__ == "__main__":
    main()
