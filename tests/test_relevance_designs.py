"""The floored paper relevance (``HybridSpec(r_min=...)``) and the Lyapunov relevance
(``HybridSpec(relevance="lyapunov")``), each against a reference computed here in numpy from
the states themselves: the floor keeps r >= r_min on states sampled in the LQR's proved set (and
is not vacuous), the Lyapunov relevance is the LQR's V to second order, smooth across an angle
deviation of pi, and both keep the hybrid's identities pi(a) = G(a), dpi/dx(a) = W.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import scipy.linalg
import torch
from torch import nn

from leoc.control import certify_lqr, design_lqr
from leoc.policies import (
    FlooredRelevance,
    HybridPolicy,
    HybridSpec,
    LyapunovRelevance,
    ObservationDeviation,
    build_hybrid,
    hybrid_design,
    relevance_floor,
)
from leoc.policies.relevance import FLOOR_MARGIN
from leoc.systems import make_system

pytestmark = pytest.mark.usefixtures("single_thread")

DTYPE = torch.float64
# Sampled certificate only (no interval proof), as in test_hybrid_spec: the floor's arithmetic
# is the same for a proved level.
CERTIFY = {"samples": 2_000, "seed": 0, "prove": False}
SYSTEMS = ("pendulum", "cartpole", "mountaincar")  # angle + plain, angle + plain, plain only
R_MINS = (0.5, 0.9, 0.99)


@pytest.fixture(scope="module")
def plants():
    """``{name: (system, LQR design, certificate)}`` for the three systems, certified."""
    out = {}
    for name in SYSTEMS:
        system = make_system(name)
        design = design_lqr(system)
        certificate = certify_lqr(system, design, **CERTIFY)
        assert certificate.certified
        out[name] = (system, design, certificate)
    return out


# ---------------------------------------------------------------------------------------------
# numpy references
# ---------------------------------------------------------------------------------------------


def _proved_set_deviations(P: np.ndarray, rho: float, count: int, seed: int) -> np.ndarray:
    """z with z^T P z <= rho: half uniform in the ellipsoid, half on its boundary."""
    rng = np.random.default_rng(seed)
    size = P.shape[0]
    u = rng.standard_normal((count, size))
    u /= np.linalg.norm(u, axis=-1, keepdims=True)
    radius = np.ones(count)
    radius[: count // 2] = rng.uniform(0.0, 1.0, count // 2) ** (1.0 / size)
    L = np.linalg.cholesky(P)
    z = math.sqrt(rho) * radius[:, None] * np.linalg.solve(L.T, u.T).T
    V = np.einsum("bi,ij,bj->b", z, P, z)
    assert np.all(V <= rho * (1 + 1e-12)) and np.allclose(V[count // 2 :], rho, rtol=1e-12)
    return z


def _observe(system, z: np.ndarray) -> np.ndarray:
    """Observations of the states a + z through the system's own observation map."""
    state = torch.as_tensor(np.asarray(system.operating_state) + z, dtype=DTYPE)
    return system.observation.observe(state).numpy()


def _paper_r(obs: np.ndarray, point: np.ndarray, lam: np.ndarray) -> np.ndarray:
    distance = ((obs - point) ** 2 / lam).sum(axis=-1)
    return 1.0 / (1.0 + distance) ** 2


def _relevance(module: nn.Module, obs: np.ndarray) -> np.ndarray:
    with torch.no_grad():
        return module(torch.as_tensor(obs, dtype=DTYPE)).numpy()[:, 0]


def _r_at(module: nn.Module, point: torch.Tensor) -> float:
    """r at one observation (D,), without autograd."""
    with torch.no_grad():
        return float(module(point[None]))


def _smooth_V(system, P: np.ndarray, z: np.ndarray) -> np.ndarray:
    """V~ from the state deviations: y_s = sin(z_s) for an angle, z_s otherwise, plus
    P_ss (1 - cos z_s)^2 per angle (trigonometry of the state, not of observation entries)."""
    angles = list(system.observation.angle_indices)
    y = z.copy()
    y[:, angles] = np.sin(z[:, angles])
    extra = sum(P[s, s] * (1.0 - np.cos(z[:, s])) ** 2 for s in angles)
    return np.einsum("bi,ij,bj->b", y, P, y) + extra


# ---------------------------------------------------------------------------------------------
# 1. The floor: r >= r_min on the proved set, for every lambda >= floor
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", SYSTEMS)
@pytest.mark.parametrize("r_min", R_MINS)
def test_floor_keeps_r_above_r_min_on_the_proved_set(plants, name, r_min):
    system, design, certificate = plants[name]
    P, rho = np.asarray(certificate.P), certificate.rho
    floor = relevance_floor(system.observation.to_list(), P, rho, r_min)
    z = _proved_set_deviations(P, rho, 6_000, seed=1)
    obs = _observe(system, z)
    point = np.asarray(system.operating_obs)
    assert _paper_r(obs, point, floor).min() >= r_min
    rng = np.random.default_rng(2)
    for _ in range(20):
        assert _paper_r(obs, point, floor * np.exp(rng.uniform(0.0, 3.0, floor.shape))).min() >= (
            r_min
        )
    # the module, at the floor itself (e^q = 0) and at random q, gives the same
    module = FlooredRelevance(point, floor)
    for q in (np.full(floor.shape, -1e3), rng.normal(0.0, 3.0, floor.shape)):
        with torch.no_grad():
            module.log_excess.copy_(torch.as_tensor(q))
        lam = module.lambda_.detach().numpy()
        assert np.all(lam >= floor)
        r = _relevance(module, obs)
        np.testing.assert_allclose(r, _paper_r(obs, point, lam), rtol=1e-12)
        assert r.min() >= r_min


@pytest.mark.parametrize("name", SYSTEMS)
def test_floor_is_not_vacuous(plants, name):
    system, design, certificate = plants[name]
    P, rho, r_min = np.asarray(certificate.P), certificate.rho, 0.9
    floor = relevance_floor(system.observation.to_list(), P, rho, r_min)
    z = _proved_set_deviations(P, rho, 6_000, seed=3)
    obs = _observe(system, z)
    point = np.asarray(system.operating_obs)
    assert _paper_r(obs, point, floor / 3.0).min() < r_min
    # and close to tight: some sampled state comes within a factor 2 of d_max
    d_max = r_min**-0.5 - 1.0
    assert ((obs - point) ** 2 / floor).sum(axis=-1).max() > 0.5 * d_max


def test_floor_is_tight_without_angles(plants):
    """Mountain car (plain entries only): the bound is exact, r = r_min at the worst point of
    the boundary (the top generalised eigenvector of (W, P)), up to the margin."""
    system, design, certificate = plants["mountaincar"]
    P, rho, r_min = np.asarray(certificate.P), certificate.rho, 0.9
    floor = relevance_floor(system.observation.to_list(), P, rho, r_min)
    values, vectors = scipy.linalg.eigh(np.diag(1.0 / floor), P)
    worst = vectors[:, -1] * math.sqrt(rho / (vectors[:, -1] @ P @ vectors[:, -1]))
    obs = _observe(system, worst[None, :])
    r = _paper_r(obs, np.asarray(system.operating_obs), floor)[0]
    assert r >= r_min
    np.testing.assert_allclose(r, r_min, rtol=1e-8)


@pytest.mark.parametrize("name", SYSTEMS)
def test_floor_reaches_d_max_on_the_ellipsoid(plants, name):
    """At the floor, max over {z^T P z <= rho} of z^T diag(w) z is d_max (the generalised
    eigenvalue problem, solved by scipy), and an angle's cos and sin share their floor."""
    system, design, certificate = plants[name]
    P, rho, r_min = np.asarray(certificate.P), certificate.rho, 0.99
    layout = system.observation.to_list()
    floor = relevance_floor(layout, P, rho, r_min)
    per_state = np.empty(P.shape[0])
    for column, (_, state) in enumerate(layout):
        per_state[state] = floor[column]
    for column, (_, state) in enumerate(layout):
        assert floor[column] == per_state[state]
    top = scipy.linalg.eigh(np.diag(1.0 / per_state), P, eigvals_only=True)[-1]
    np.testing.assert_allclose(rho * top * (1.0 + FLOOR_MARGIN), r_min**-0.5 - 1.0, rtol=1e-10)


def test_floored_relevance_module():
    point = np.array([1.0, 0.0, 0.5])
    floor = np.array([2.0, 2.0, 0.1])
    start = FlooredRelevance(point, floor, lambda_init=1.0).lambda_.detach().numpy()
    np.testing.assert_allclose(start, [4.0, 4.0, 1.0], rtol=1e-14)  # max(lambda_init, 2 f)
    start = FlooredRelevance(point, floor, lambda_init=(10.0, 1.0, 0.1)).lambda_.detach()
    np.testing.assert_allclose(start.numpy(), [10.0, 4.0, 0.2], rtol=1e-14)
    frozen = FlooredRelevance(point, floor, learn_lambda=False)
    assert not list(frozen.parameters()) and "log_excess" in dict(frozen.named_buffers())
    learned = FlooredRelevance(point, floor)
    assert [name for name, _ in learned.named_parameters()] == ["log_excess"]
    for dtype in (torch.float64, torch.float32):
        module = FlooredRelevance(point, floor, dtype=dtype)
        assert _r_at(module, torch.as_tensor(point, dtype=dtype)) == 1.0
    # training cannot pass the floor: a long walk down the gradient of r at some x
    x = torch.tensor([[0.0, 1.0, 3.0]], dtype=DTYPE)
    optimiser = torch.optim.SGD(learned.parameters(), lr=100.0)
    for _ in range(200):
        optimiser.zero_grad()
        learned(x).sum().backward()  # minimise r: shrink lambda
        optimiser.step()
    assert torch.all(learned.lambda_ >= learned.floor)
    assert _r_at(learned, x[0]) >= float(_paper_r(x.numpy(), point, floor)[0])
    for bad in ([1.0, 0.0, 1.0], [1.0, -1.0, 1.0], [1.0, 1.0]):
        with pytest.raises(ValueError, match="floor"):
            FlooredRelevance(point, bad)


# ---------------------------------------------------------------------------------------------
# 2. The floor through HybridSpec: resolved from the certificate, built, and r_min=None unchanged
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", SYSTEMS)
def test_spec_with_r_min_builds_the_floored_relevance(plants, name):
    system, design, certificate = plants[name]
    spec = HybridSpec(r_min=0.95, lambda_init=0.5, relevance_power=1.0)
    resolved = hybrid_design(spec, system, design, certificate=certificate)
    data = resolved.relevance_data
    expected = relevance_floor(system.observation.to_list(), design.P, certificate.rho, 0.95)
    assert data["lambda_floor"] == expected.tolist()
    assert data["rho"] == certificate.rho and data["r_min"] == 0.95
    json.dumps(resolved.to_dict())
    obs_dim = len(system.observation.to_list())
    H = nn.Sequential(nn.Linear(obs_dim, 8, dtype=DTYPE), nn.Tanh(), nn.Linear(8, 1, dtype=DTYPE))
    policy = build_hybrid(spec, resolved, H, action_limit=system.action_limit)
    module = policy.relevance_module
    assert isinstance(module, FlooredRelevance)
    np.testing.assert_allclose(module.lambda_.detach().numpy(), 2.0 * expected, rtol=1e-14)
    obs = _observe(system, _proved_set_deviations(design.P, certificate.rho, 2_000, seed=4))
    with torch.no_grad():
        module.log_excess.fill_(-50.0)  # as if trained down to the floor
        r = policy.relevance(torch.as_tensor(obs)).numpy()
    assert r.min() >= 0.95
    # frozen: no parameters in the relevance
    frozen = build_hybrid(spec.replace(learn_lambda=False), resolved, H)
    assert not list(frozen.relevance_module.parameters())


@pytest.mark.parametrize("name", SYSTEMS)
def test_the_default_spec_is_the_squared_relevance_floored_at_one_half(plants, name):
    """``HybridSpec()``: r = (1 + d^2)^-2 (numpy, from the module's lambda), Lambda never below
    the floor that keeps r >= 0.5 on the LQR's proved set (sampled: inside and on the boundary),
    and the floor not vacuous (r well below 1 there, and below 0.5 beyond the set)."""
    system, design, certificate = plants[name]
    spec = HybridSpec()
    resolved = hybrid_design(spec, system, design, certificate=certificate)
    assert resolved.relevance_data["r_min"] == 0.5
    policy = build_hybrid(spec, resolved, nn.Linear(len(system.operating_obs), 1, dtype=DTYPE))
    module, point = policy.relevance_module, np.asarray(system.operating_obs)
    assert isinstance(module, FlooredRelevance)
    with torch.no_grad():
        module.log_excess.fill_(-50.0)  # trained down to the floor
    lam = module.lambda_.detach().numpy()
    np.testing.assert_allclose(lam, resolved.relevance_data["lambda_floor"], rtol=1e-12)
    obs = _observe(system, _proved_set_deviations(design.P, certificate.rho, 2_000, seed=11))
    r = policy.relevance(torch.as_tensor(obs)).detach().numpy()[:, 0]
    d = ((obs - point) ** 2 / lam).sum(axis=-1)
    np.testing.assert_allclose(r, 1.0 / (1.0 + d**2) ** 2, rtol=1e-12)
    assert r.min() >= 0.5 and r.min() < 0.9
    outside = _observe(
        system, 3.0 * _proved_set_deviations(design.P, certificate.rho, 200, seed=12)
    )
    assert policy.relevance(torch.as_tensor(outside)).detach().numpy().min() < 0.5


def test_r_min_none_is_todays_paper_relevance(plants):
    system, design, certificate = plants["pendulum"]

    def no_proof():
        raise AssertionError("the paper relevance without r_min needs no certificate")

    for spec in (
        HybridSpec(r_min=None, relevance_power=1.0),
        HybridSpec(r_min=None, relevance_power=1.0, lambda_init=(1.0, 2.0, 3.0)),
    ):
        resolved = hybrid_design(spec, system, design, certificate=no_proof)
        assert resolved.relevance_data == {}
        torch.manual_seed(0)
        H = nn.Linear(3, 1, dtype=DTYPE)
        policy = build_hybrid(spec, resolved, H, action_limit=system.action_limit)
        direct = HybridPolicy(
            policy.linear,
            H,
            system.operating_obs,
            action_limit=system.action_limit,
            lambda_init=spec.lambda_init,
        )
        assert policy.relevance_module is None
        assert list(policy.state_dict()) == list(direct.state_dict())
        for key, value in policy.state_dict().items():
            assert torch.equal(value, direct.state_dict()[key]), key


# ---------------------------------------------------------------------------------------------
# 3. The Lyapunov relevance
# ---------------------------------------------------------------------------------------------


def _lyapunov_module(plants, name, lambda_init=1.0):
    system, design, certificate = plants[name]
    spec = HybridSpec(relevance="lyapunov", lambda_init=lambda_init)
    resolved = hybrid_design(spec, system, design, certificate=certificate)
    module = spec.design.build(spec, resolved.relevance_data, system.operating_obs, DTYPE)
    return module["relevance"]


@pytest.mark.parametrize("lambda_init", [1.0, 0.3, 7.0])
def test_lyapunov_relevance_without_angles_is_the_formula(plants, lambda_init):
    system, design, certificate = plants["mountaincar"]
    module = _lyapunov_module(plants, "mountaincar", lambda_init)
    assert isinstance(module, LyapunovRelevance)
    assert module.lambda_.shape == () and float(module.lambda_.detach()) == pytest.approx(
        lambda_init
    )
    P, rho = np.asarray(design.P), certificate.rho
    z = np.concatenate(
        [
            _proved_set_deviations(P, rho, 500, seed=5),
            np.random.default_rng(6).normal(0, 2, (500, 2)),
        ]
    )
    obs = _observe(system, z)
    expected = 1.0 / (1.0 + np.einsum("bi,ij,bj->b", z, P, z) / (lambda_init * rho)) ** 2
    np.testing.assert_allclose(_relevance(module, obs), expected, rtol=0, atol=1e-12)


@pytest.mark.parametrize("name", ["pendulum", "cartpole", "mountaincar"])
def test_lyapunov_function_is_v_to_second_order_and_the_smooth_formula(plants, name):
    system, design, certificate = plants[name]
    module = _lyapunov_module(plants, name)
    P = np.asarray(design.P)
    a = torch.as_tensor(system.operating_state, dtype=DTYPE)

    def smooth_v(state):
        return module.lyapunov(system.observation.observe(state)[None])[0, 0]

    hessian = torch.autograd.functional.hessian(smooth_v, a).numpy()
    np.testing.assert_allclose(hessian, 2.0 * P, rtol=1e-10, atol=1e-10 * np.abs(P).max())
    z = np.random.default_rng(7).uniform(-4.0, 4.0, (500, P.shape[0]))
    with torch.no_grad():
        value = module.lyapunov(torch.as_tensor(_observe(system, z))).numpy()[:, 0]
    np.testing.assert_allclose(value, _smooth_V(system, P, z), rtol=1e-10)


def test_lyapunov_function_with_an_operating_angle_off_zero():
    """A layout whose operating angle is 0.7 rad and a random P: the sin a, cos a terms."""
    rng = np.random.default_rng(8)
    root = rng.normal(size=(3, 3))
    P = root @ root.T + 0.5 * np.eye(3)
    layout = [("state", 0), ("cos", 1), ("sin", 1), ("state", 2)]
    a = np.array([0.3, 0.7, -1.2])
    point = np.array([0.3, math.cos(0.7), math.sin(0.7), -1.2])
    module = LyapunovRelevance(layout, point, P, rho=2.0, lambda_init=0.5)

    def observe(state):
        return torch.stack([state[0], torch.cos(state[1]), torch.sin(state[1]), state[2]])

    def smooth_v(state):
        return module.lyapunov(observe(state)[None])[0, 0]

    hessian = torch.autograd.functional.hessian(smooth_v, torch.as_tensor(a)).numpy()
    np.testing.assert_allclose(hessian, 2.0 * P, rtol=1e-10, atol=1e-10)
    z = rng.uniform(-4.0, 4.0, (300, 3))
    obs = np.stack([a[0] + z[:, 0], np.cos(a[1] + z[:, 1]), np.sin(a[1] + z[:, 1]), a[2] + z[:, 2]])
    y = np.stack([z[:, 0], np.sin(z[:, 1]), z[:, 2]], axis=-1)
    V = np.einsum("bi,ij,bj->b", y, P, y) + P[1, 1] * (1 - np.cos(z[:, 1])) ** 2
    r = _relevance(module, obs.T)
    np.testing.assert_allclose(r, 1.0 / (1.0 + V / (0.5 * 2.0)) ** 2, rtol=1e-10)
    assert _r_at(module, torch.as_tensor(point)) == 1.0
    with pytest.raises(ValueError, match="^operating_point: expected .* unit circle"):
        LyapunovRelevance(layout, [0.3, 1.0, 0.5, -1.2], P, rho=2.0)


@pytest.mark.parametrize("name", ["pendulum", "cartpole"])
def test_lyapunov_relevance_is_continuous_across_an_angle_deviation_of_pi(plants, name):
    system, design, certificate = plants[name]
    module = _lyapunov_module(plants, name)
    P = np.asarray(design.P)
    angle = system.observation.angle_indices[0]
    rng = np.random.default_rng(9)
    z = rng.normal(0.0, 0.5, (200, P.shape[0]))
    below, above = z.copy(), z.copy()
    below[:, angle], above[:, angle] = math.pi - 1e-7, -math.pi + 1e-7
    r_below = _relevance(module, _observe(system, below))
    r_above = _relevance(module, _observe(system, above))
    np.testing.assert_allclose(r_below, r_above, rtol=1e-5, atol=1e-9)
    # the wrapped V = z^T P z jumps there (P's cross terms change sign): what V~ avoids
    deviation = ObservationDeviation(system.observation.to_list(), system.operating_state)
    with torch.no_grad():
        wrapped = [
            deviation(torch.as_tensor(_observe(system, side))).numpy() for side in (below, above)
        ]
    jump = [np.einsum("bi,ij,bj->b", w, P, w) for w in wrapped]
    assert np.abs(jump[0] - jump[1]).max() > 1.0
    # at delta = pi and every other deviation 0, V~ = 4 P_ss > 0
    flipped = np.zeros((1, P.shape[0]))
    flipped[0, angle] = math.pi
    with torch.no_grad():
        value = module.lyapunov(torch.as_tensor(_observe(system, flipped)))
    np.testing.assert_allclose(float(value), 4.0 * P[angle, angle], rtol=1e-12)


@pytest.mark.parametrize("name", SYSTEMS)
def test_lyapunov_relevance_is_one_only_at_the_operating_point(plants, name):
    system, design, certificate = plants[name]
    module = _lyapunov_module(plants, name)
    for dtype in (torch.float64, torch.float32):
        point = torch.as_tensor(system.operating_obs, dtype=dtype)
        assert _r_at(module.to(dtype), point) == 1.0
    module = module.to(DTYPE)
    z = np.random.default_rng(10).uniform(-3.0, 3.0, (2_000, len(system.operating_state)))
    z = np.concatenate([z, 1e-3 * z[:100]])
    r = _relevance(module, _observe(system, z))
    assert np.all(r < 1.0) and np.all(r > 0.0)
    frozen = build_hybrid(
        HybridSpec(relevance="lyapunov", learn_lambda=False),
        hybrid_design(HybridSpec(relevance="lyapunov"), system, design, certificate=certificate),
        nn.Linear(len(system.operating_obs), 1, dtype=DTYPE),
    )
    assert not list(frozen.relevance_module.parameters())


# ---------------------------------------------------------------------------------------------
# 3b. The power p of r = (1 + d^p)^-2
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", SYSTEMS)
@pytest.mark.parametrize("r_min", (0.5, 0.9))
def test_power_two_floor_keeps_r_above_r_min_and_is_tight(plants, name, r_min):
    """The floor for p = 2 keeps (1 + d^2)^-2 >= r_min on the proved set, the numpy formula
    at the floor's own Lambda; it is narrower than p = 1's (d may reach sqrt(d_max) > d_max),
    and without angles (the mountain car) r_min is reached on the boundary (tight)."""
    system, design, certificate = plants[name]
    P, rho = np.asarray(certificate.P), certificate.rho
    layout = system.observation.to_list()
    floor = relevance_floor(layout, P, rho, r_min, power=2.0)
    np.testing.assert_allclose(
        relevance_floor(layout, P, rho, r_min) / floor,
        # f ~ 1 / d_max and d_max(p = 2) = sqrt(d_max(p = 1)): f(1) / f(2) = 1 / sqrt(d_max(1))
        1.0 / math.sqrt(r_min**-0.5 - 1.0),
        rtol=1e-12,
    )
    obs = _observe(system, _proved_set_deviations(P, rho, 6_000, seed=7))
    point = np.asarray(system.operating_obs)
    distance = ((obs - point) ** 2 / floor).sum(axis=-1)
    r = 1.0 / (1.0 + distance**2) ** 2
    assert r.min() >= r_min
    if name == "mountaincar":
        assert r.min() == pytest.approx(r_min, rel=1e-6)
    module = FlooredRelevance(point, floor, power=2.0)
    with torch.no_grad():
        module.log_excess.fill_(-60.0)  # at the floor
    np.testing.assert_allclose(_relevance(module, obs), r, rtol=1e-9)


def test_power_leaks_at_fourth_order_near_the_operating_point(plants):
    """Along a ray x = a + t v: 1 - r ~ 2 d(t) = O(t^2) for the paper's relevance and
    2 d(t)^2 = O(t^4) for p = 2, measured on the built hybrid's relevance (log-log slope of
    1 - r against t between t = 1e-2 and 1e-3), and a hybrid with p = 2 keeps r = 1 only at a."""
    system, design, certificate = plants["cartpole"]
    point = torch.as_tensor(system.operating_obs, dtype=DTYPE)
    direction = torch.linspace(0.3, 1.0, point.shape[0], dtype=DTYPE)
    H = nn.Linear(point.shape[0], 1, dtype=DTYPE)
    slopes = {}
    for power in (1.0, 2.0):
        spec = HybridSpec(relevance_power=power)
        policy = build_hybrid(spec, hybrid_design(spec, system, design, certificate=certificate), H)
        with torch.no_grad():
            leak = [1.0 - float(policy.relevance(point + t * direction)) for t in (1e-2, 1e-3)]
        slopes[power] = math.log10(leak[0] / leak[1])
        assert leak[1] > 0.0  # r < 1 off a
    assert slopes[1.0] == pytest.approx(2.0, abs=0.01)
    assert slopes[2.0] == pytest.approx(4.0, abs=0.01)


def test_power_spec_builds_its_relevance_and_power_one_is_todays(plants):
    """p = 2 without a floor: a PaperRelevance(power=2) with Lambda = lambda_init; p = 1: the
    hybrid's own log lambda, as before the option (no relevance module)."""
    from leoc.policies import PaperRelevance

    system, design, certificate = plants["pendulum"]
    H = nn.Linear(3, 1, dtype=DTYPE)
    for power, kind in ((2.0, PaperRelevance), (1.0, type(None))):
        spec = HybridSpec(relevance_power=power, lambda_init=0.7, r_min=None)
        policy = build_hybrid(spec, hybrid_design(spec, system, design, certificate=certificate), H)
        assert isinstance(policy.relevance_module, kind)
        obs = _observe(system, _proved_set_deviations(design.P, certificate.rho, 500, seed=9))
        d = ((obs - np.asarray(system.operating_obs)) ** 2 / 0.7).sum(axis=-1)
        with torch.no_grad():
            r = policy.relevance(torch.as_tensor(obs)).numpy()[:, 0]
        np.testing.assert_allclose(r, 1.0 / (1.0 + d**power) ** 2, rtol=1e-12)


# ---------------------------------------------------------------------------------------------
# 4. The hybrid's identities, with both designs
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", ["pendulum", "cartpole"])
@pytest.mark.parametrize(
    "spec",
    [
        HybridSpec(),  # leoc's default: p = 2, floored at r >= 0.5
        HybridSpec(r_min=0.9, relevance_power=1.0),
        HybridSpec(relevance="lyapunov", lambda_init=0.2),
        HybridSpec(relevance_power=2.0, lambda_init=0.3, r_min=None),
        HybridSpec(relevance_power=1.5, r_min=0.5),
    ],
)
def test_identities_at_the_operating_point(plants, name, spec):
    system, design, certificate = plants[name]
    resolved = hybrid_design(spec, system, design, certificate=certificate)
    obs_dim = len(system.operating_obs)
    torch.manual_seed(1)
    H = nn.Sequential(nn.Linear(obs_dim, 8, dtype=DTYPE), nn.Tanh(), nn.Linear(8, 1, dtype=DTYPE))
    policy = build_hybrid(spec, resolved, H, action_limit=system.action_limit)
    a = torch.as_tensor(system.operating_obs, dtype=DTYPE)
    G = a @ torch.as_tensor(design.W).T + torch.as_tensor(design.b)
    with torch.no_grad():
        assert torch.equal(policy(a[None])[0], policy.linear(a[None])[0])
        np.testing.assert_allclose(policy(a[None])[0].numpy(), G.numpy(), atol=1e-12)
        assert not torch.allclose(H(a[None]), policy.linear(a[None]))  # H would show
    jacobian = torch.autograd.functional.jacobian(lambda x: policy(x[None])[0], a)
    np.testing.assert_allclose(jacobian.numpy(), np.asarray(design.W), atol=1e-12)


# ---------------------------------------------------------------------------------------------
# 5. Spec errors (the bad fields are in test_hybrid_spec.BAD_FIELDS)
# ---------------------------------------------------------------------------------------------


def test_good_specs_round_trip():
    for spec in (
        HybridSpec(r_min=0.99),
        HybridSpec(r_min=0.5, relevance_power=2.0),
        HybridSpec(relevance_power=3),
        HybridSpec(relevance="lyapunov", lambda_init=3.0, learn_lambda=False),
        HybridSpec(relevance="roa", r_min=0.5),  # the ROA relevance ignores r_min
        HybridSpec(relevance="paper", lambda_init=(1.0, 2.0), r_min=0.5),
    ):
        assert HybridSpec.from_dict(json.loads(json.dumps(spec.to_dict()))) == spec


def test_without_a_certified_set_both_designs_refuse(plants):
    system, design, certificate = plants["pendulum"]
    empty = certificate._replace(rho=0.0)
    with pytest.raises(ValueError, match="^r_min: expected an LQR with a certified region"):
        hybrid_design(HybridSpec(r_min=0.9), system, design, certificate=empty)
    with pytest.raises(ValueError, match="^relevance='lyapunov': .* no certified region"):
        hybrid_design(HybridSpec(relevance="lyapunov"), system, design, certificate=empty)
    wrong = certificate._replace(P=2.0 * certificate.P)
    for spec in (HybridSpec(r_min=0.9), HybridSpec(relevance="lyapunov")):
        with pytest.raises(ValueError, match="^certificate: expected one for the design's P"):
            hybrid_design(spec, system, design, certificate=wrong)
