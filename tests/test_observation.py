"""The observation map: observe/invert, bounds, Jacobian and Gaussian moments."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from leoc.systems import make_system, system_names
from leoc.systems.observation import ObservationMap, angle_entries, state_entry

DTYPE = torch.float64
# Central differences with step h have error O(h^2) times the third derivative (<= 1 here).
FD_STEP = 1e-6
FD_ATOL = 1e-8
MC_SAMPLES = 400_000
# Monte Carlo standard error of a mean of bounded (|o| <= ~3) values: ~3 / sqrt(4e5) = 0.005.
MC_ATOL = 0.02
LAYOUT = (state_entry(0), *angle_entries(1), *angle_entries(2), state_entry(3))


def test_observe_invert_roundtrip_and_bounds() -> None:
    obs_map = ObservationMap(LAYOUT)
    state = torch.tensor([[0.3, 2.0, -1.0, 4.0], [-1.0, -3.0, 3.1, 0.0]], dtype=DTYPE)
    obs = obs_map.observe(state)
    assert obs.shape == (2, 6)
    torch.testing.assert_close(obs_map.invert(obs), state)
    np.testing.assert_array_equal(obs_map.bounds(), [np.inf, 1, 1, 1, 1, np.inf])
    assert obs_map.angle_indices == (1, 2)
    assert [tuple(a) for a in obs_map.angle_columns()] == [(1, 1, 2), (2, 3, 4)]
    assert ObservationMap(obs_map.to_list()) == obs_map


@pytest.mark.parametrize(
    "layout, message",
    [
        ([("cos", 0)], "must be observed as itself or as both its cos and sin"),
        ([("angle", 0)], "expected \\(kind, state_index\\) with kind in"),
        ([("state", 0), ("state", 0)], "appears twice"),
        ([], "at least one observation entry"),
    ],
)
def test_bad_layouts_are_rejected(layout: list, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        ObservationMap(layout)


def test_jacobian_matches_finite_differences() -> None:
    obs_map = ObservationMap(LAYOUT)
    rng = np.random.default_rng(0)
    state = rng.uniform(-3.0, 3.0, size=4)
    numeric = np.zeros((obs_map.obs_dim, 4))
    for index in range(4):
        step = np.zeros(4)
        step[index] = FD_STEP
        plus = obs_map.observe(torch.as_tensor(state + step)).numpy()
        minus = obs_map.observe(torch.as_tensor(state - step)).numpy()
        numeric[:, index] = (plus - minus) / (2.0 * FD_STEP)
    np.testing.assert_allclose(obs_map.jacobian(state), numeric, atol=FD_ATOL)


@pytest.mark.parametrize("name", system_names())
def test_linear_gain_has_jacobian_minus_k(name: str) -> None:
    """W J(a) = -K: the observation gain has the state gain's slope at the operating point."""
    system = make_system(name)
    obs_map = system.observation
    K = np.arange(1.0, system.state_dim + 1.0)[None, :]
    W = obs_map.linear_gain(K, system.operating_state)
    np.testing.assert_allclose(W @ obs_map.jacobian(system.operating_state), -K, atol=1e-12)


def test_moments_match_monte_carlo() -> None:
    obs_map = ObservationMap(LAYOUT)
    mean = torch.tensor([0.2, 0.5, -2.0, 1.0], dtype=DTYPE)
    root = torch.tensor(
        [[0.5, 0, 0, 0], [0.2, 0.6, 0, 0], [-0.1, 0.3, 0.4, 0], [0.3, 0.0, 0.2, 0.7]], dtype=DTYPE
    )
    cov = root @ root.T
    moments = obs_map.moments(mean, cov)
    generator = torch.Generator().manual_seed(0)
    samples = mean + torch.randn(MC_SAMPLES, 4, generator=generator, dtype=DTYPE) @ root.T
    obs = obs_map.observe(samples)
    torch.testing.assert_close(moments.mean, obs.mean(0), atol=MC_ATOL, rtol=0)
    torch.testing.assert_close(moments.cov, torch.cov(obs.T), atol=MC_ATOL, rtol=0)
    cross = ((samples - samples.mean(0)).T @ (obs - obs.mean(0))) / (MC_SAMPLES - 1)
    torch.testing.assert_close(cov @ moments.io, cross, atol=MC_ATOL, rtol=0)
