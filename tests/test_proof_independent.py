"""Proved regions of attraction (:func:`leoc.control.certify_controller`) checked by a closed
loop written here, independently of leoc (issue 42, item 5).

Independent: the equations of motion, integrators, actuator clips, observation maps and allowed
regions of the pendulum, the mountain car and the cart-pole are written below in numpy from the
physics and the constants of the paper's experiments (gymnasium's Pendulum-v1, the classic
cart-pole equations, the hilltop mountain car); the controllers are evaluated in numpy from
their numbers alone: the LQR's ``W, b``, and a torch module's ``state_dict`` (ReLU layers, the
actor's ``u_max tanh``, the paper's relevance ``(1 + d)^-2``, the ROA relevance's smootherstep,
the blend and the clip). Nothing of leoc's steps, observation maps, policies, relevance or
rollout code runs on the checked side; leoc builds and proves the controllers, and two small
tests compare both sides to 1e-12 so that a mismatch shows there first.

The check: states drawn uniformly in each proved set ``{V <= rho}`` and on its boundary
``V = rho`` (the unit ball mapped through the Cholesky factor of ``P``), pushed through one
control period of the numpy loop (the action held ``action_repeat`` steps), show ``V(next) <
V(x)`` wherever ``V(x)`` exceeds the excluded level, ``V(next) <= rho`` everywhere, and no
state (nor a held step) outside the allowed region. 2x10^4 + 4x10^3 states per set by default,
10^6 + 2x10^5 in the ``slow`` variant.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from typing import Any, NamedTuple

import numpy as np
import pytest
import scipy.linalg
import torch

from leoc.control import certify_controller, certify_lqr, design_lqr, lqr_closed_loop
from leoc.policies import (
    HybridDesign,
    HybridSpec,
    MLPActor,
    build_hybrid,
    roa_hybrid,
    with_control_period,
)
from leoc.systems import make_system

pytestmark = pytest.mark.usefixtures("single_thread")

STEP_ATOL = 1e-12
"""|numpy step - leoc step| and |numpy action - leoc action| allowed (both float64; the two
differ only by the order of a few roundings, about 1e-15)."""
LEVEL_ROUNDING = 1e-12
"""Relative slack on ``V(next) <= rho``: a boundary state's V is rho to the rounding of the map
from the ball (about 1e-16), far below the gaps the planted bugs of the report open."""
CHUNK = 20_000
"""States per batch of the numpy loop (a 400x300 actor's hidden layers: about 100 MB)."""
FAST_COUNTS = (20_000, 4_000)
SLOW_COUNTS = (1_000_000, 200_000)
"""States (uniform in the proved set, on its boundary) per controller."""
CHECK_SAMPLES = 20_000
"""Samples of certify_controller's estimate (the proof's target)."""
ACTOR_SEED = 3
"""Seed of the freshly initialised learned parts (torch generator)."""
BASELINE_SEED = 4
FIT_STATES = 4000
"""States (uniform in half the operating region) the baseline's last layer is fitted on."""
PAPER_LAMBDA = 1.0
"""Lambda of the paper hybrids: r falls to about 0.22 on their proved sets."""
ROA_FLAT_FRACTION = 0.2
"""The ROA hybrids' flat top, a fraction of the LQR's proved level (band width 1: r reaches 0
at twice it), so that r varies over their proved sets."""
VARYING_RELEVANCE = 0.8
"""A hybrid's proved set must hold states with r below this (the learned part acts there)."""
INFLATION = 1.01
"""The check's own test: a level 1 % above the proved one holds violations it finds."""
PROOF_SECONDS = 60.0
"""Wall-clock cap of a proof of a 400x300 actor (they end, limited by the decrease, in 10-30 s
on 2 busy cores; the cap only guards a slower machine, where the level is smaller, still
proved)."""


# ---------------------------------------------------------------- the plants, in numpy
class PendulumPhysics(NamedTuple):
    """Gymnasium's Pendulum-v1: a uniform rod about its end, theta = 0 upright."""

    gravity: float = 10.0  # m/s^2
    mass: float = 1.0  # kg
    length: float = 1.0  # m
    dt: float = 0.05  # s
    max_torque: float = 2.0  # N m
    max_speed: float = 8.0  # rad/s


class MountainCarPhysics(NamedTuple):
    """A car on the hill h(x) = 1.35 cos x + 1.65, hilltop at x = 0."""

    gravity: float = 9.8
    mass: float = 0.1  # kg
    hill: float = 1.35  # m, amplitude of h
    dt: float = 0.02
    max_force: float = 3.0  # N
    track: tuple[float, float] = (-3.6 - math.pi / 2.0, 2.2 - math.pi / 2.0)  # m


class CartPolePhysics(NamedTuple):
    """The classic cart-pole (Barto, Sutton & Anderson 1983), theta = 0 upright."""

    gravity: float = 9.8
    cart_mass: float = 0.05  # kg
    pole_mass: float = 0.005  # kg
    half_length: float = 0.5  # m
    dt: float = 0.02
    max_force: float = 2.5  # N
    x_limit: float = 2.4  # m


def pendulum_step(states: np.ndarray, actions: np.ndarray) -> np.ndarray:
    """theta_ddot = 3 g / (2 l) sin theta + 3 u / (m l^2), u clipped; semi-implicit Euler with
    the new speed clipped before the angle moves."""
    p = PendulumPhysics()
    theta, speed = states[:, 0], states[:, 1]
    torque = np.clip(actions[:, 0], -p.max_torque, p.max_torque)
    accel = 1.5 * p.gravity / p.length * np.sin(theta) + 3.0 * torque / (p.mass * p.length**2)
    speed = np.clip(speed + p.dt * accel, -p.max_speed, p.max_speed)
    return np.stack([theta + p.dt * speed, speed], axis=1)


def mountaincar_step(states: np.ndarray, actions: np.ndarray) -> np.ndarray:
    """x_ddot = F / m - g h'(x), h'(x) = -1.35 sin x, F clipped; semi-implicit Euler."""
    p = MountainCarPhysics()
    force = np.clip(actions[:, 0], -p.max_force, p.max_force)
    speed = states[:, 1] + p.dt * (force / p.mass + p.gravity * p.hill * np.sin(states[:, 0]))
    return np.stack([states[:, 0] + p.dt * speed, speed], axis=1)


def cartpole_step(states: np.ndarray, actions: np.ndarray) -> np.ndarray:
    """The cart-pole equations (pole half-length l, 4/3 for a rod about its centre), F clipped;
    explicit Euler (positions with the old speeds)."""
    p = CartPolePhysics()
    x, x_dot, theta, theta_dot = states.T
    force = np.clip(actions[:, 0], -p.max_force, p.max_force)
    total = p.cart_mass + p.pole_mass
    sin, cos = np.sin(theta), np.cos(theta)
    push = (force + p.pole_mass * p.half_length * theta_dot**2 * sin) / total
    theta_ddot = (p.gravity * sin - cos * push) / (
        p.half_length * (4.0 / 3.0 - p.pole_mass * cos**2 / total)
    )
    x_ddot = push - p.pole_mass * p.half_length * theta_ddot * cos / total
    rates = np.stack([x_dot, x_ddot, theta_dot, theta_ddot], axis=1)
    return states + p.dt * rates


def wrap(angle: np.ndarray) -> np.ndarray:
    """An angle in [-pi, pi)."""
    return np.mod(angle + math.pi, 2.0 * math.pi) - math.pi


class Plant(NamedTuple):
    """A system as the check sees it: step, observation, its inverse, allowed region."""

    step: Callable[[np.ndarray, np.ndarray], np.ndarray]
    observe: Callable[[np.ndarray], np.ndarray]
    state_of: Callable[[np.ndarray], np.ndarray]
    leaves: Callable[[np.ndarray], np.ndarray]
    angles: tuple[int, ...]


def _never(states: np.ndarray) -> np.ndarray:
    return np.zeros(states.shape[0], dtype=bool)


PLANTS = {
    "pendulum": Plant(
        pendulum_step,
        lambda s: np.stack([np.cos(s[:, 0]), np.sin(s[:, 0]), s[:, 1]], axis=1),
        lambda o: np.stack([np.arctan2(o[:, 1], o[:, 0]), o[:, 2]], axis=1),
        _never,
        (0,),
    ),
    "mountaincar": Plant(
        mountaincar_step,
        lambda s: s.copy(),
        lambda o: o.copy(),
        lambda s: (
            (s[:, 0] < MountainCarPhysics().track[0]) | (s[:, 0] > MountainCarPhysics().track[1])
        ),
        (),
    ),
    "cartpole": Plant(
        cartpole_step,
        lambda s: np.stack([s[:, 0], s[:, 1], np.cos(s[:, 2]), np.sin(s[:, 2]), s[:, 3]], axis=1),
        lambda o: np.stack([o[:, 0], o[:, 1], np.arctan2(o[:, 3], o[:, 2]), o[:, 4]], axis=1),
        lambda s: np.abs(s[:, 0]) > CartPolePhysics().x_limit,
        (2,),
    ),
}


# ---------------------------------------------------------------- the policies, in numpy
def _relu_network(weights: dict[str, np.ndarray], prefix: str, obs: np.ndarray) -> np.ndarray:
    """Affine layers ``{prefix}{k}.weight/bias`` in the order of k, ReLU between them."""
    layers = sorted(
        {int(key[len(prefix) :].split(".")[0]) for key in weights if key.startswith(prefix)}
    )
    hidden = obs
    for position, index in enumerate(layers):
        hidden = hidden @ weights[f"{prefix}{index}.weight"].T + weights[f"{prefix}{index}.bias"]
        if position < len(layers) - 1:
            hidden = np.maximum(hidden, 0.0)
    return hidden


def _actor(weights: dict[str, np.ndarray], prefix: str, obs: np.ndarray) -> np.ndarray:
    """``u_max tanh(z)`` of the network's output z (z itself without a limit)."""
    z = _relu_network(weights, f"{prefix}net.", obs)
    limit = weights.get(f"{prefix}action_limit")
    return z if limit is None else limit * np.tanh(z)


def _paper_relevance(weights: dict[str, np.ndarray], obs: np.ndarray) -> np.ndarray:
    """r = (1 + d)^-2, d = sum_i (o_i - a_i)^2 / lambda_i, lambda = exp(log_lambda)."""
    distance = ((obs - weights["operating_point"]) ** 2 / np.exp(weights["log_lambda"])).sum(1)
    return 1.0 / (1.0 + distance) ** 2


def _roa_relevance(weights: dict[str, np.ndarray], plant: Plant, obs: np.ndarray) -> np.ndarray:
    """r = 1 - S(t), t = clip((V / rho_in - 1) / w, 0, 1), S(t) = 10 t^3 - 15 t^4 + 6 t^5,
    V of the wrapped state deviation; w = w_max sigmoid(param) with angles (w_max: the band ends
    before an angle deviation of pi), exp(param) without."""
    P = weights["relevance_module.lyapunov_matrix"]
    rho_in = float(weights["relevance_module.rho_in"])
    param = float(weights["relevance_module.width_param"])
    centre = weights["relevance_module.deviation.operating_state"]
    value = lyapunov(P, centre, plant.angles, plant.state_of(obs))
    if plant.angles:
        spread = np.diag(np.linalg.inv(P))
        most = min(math.pi**2 / spread[s] for s in plant.angles) / rho_in - 1.0
        width = most / (1.0 + math.exp(-param))
    else:
        width = math.exp(param)
    t = np.clip((value / rho_in - 1.0) / width, 0.0, 1.0)
    return 1.0 - (10.0 * t**3 - 15.0 * t**4 + 6.0 * t**5)


class IndependentPolicy(NamedTuple):
    """A controller evaluated in numpy from its numbers (``weights``: a ``state_dict``, or the
    LQR's ``linear.W`` and ``linear.b`` alone)."""

    weights: dict[str, np.ndarray]
    plant: Plant

    @property
    def kind(self) -> str:
        if "nonlinear.net.0.weight" in self.weights:
            return "hybrid"
        return "actor" if "net.0.weight" in self.weights else "linear"

    def relevance(self, obs: np.ndarray) -> np.ndarray:
        """r (B,) of a hybrid (1 for the others)."""
        if self.kind != "hybrid":
            return np.ones(obs.shape[0])
        if "log_lambda" in self.weights:
            return _paper_relevance(self.weights, obs)
        return _roa_relevance(self.weights, self.plant, obs)

    def action(self, obs: np.ndarray) -> np.ndarray:
        """u (B, 1): the actor; the linear part; or clip(r G + (1 - r) H) of a hybrid."""
        if self.kind == "actor":
            return _actor(self.weights, "", obs)
        linear = obs @ self.weights["linear.W"].T + self.weights["linear.b"]
        if self.kind == "linear":
            return linear
        r = self.relevance(obs)[:, None]
        blend = r * linear + (1.0 - r) * _actor(self.weights, "nonlinear.", obs)
        limit = self.weights["action_limit"]
        return np.clip(blend, -limit, limit)


def independent_policy(controller: Any, design: Any, plant: Plant) -> IndependentPolicy:
    """The numbers of ``controller``: a module's ``state_dict`` (a held policy's own, its
    ``policy.`` prefix dropped) or, for leoc's plain LQR, the design's W and b."""
    if not isinstance(controller, torch.nn.Module):
        weights = {"linear.W": np.asarray(design.W), "linear.b": np.asarray(design.b)}
        return IndependentPolicy(weights, plant)
    weights = {
        key.removeprefix("policy."): value.detach().double().numpy()
        for key, value in controller.state_dict().items()
    }
    return IndependentPolicy(weights, plant)


# ---------------------------------------------------------------- V and the closed loop
def lyapunov(P: np.ndarray, centre: np.ndarray, angles, states: np.ndarray) -> np.ndarray:
    """V (B,) = z^T P z, z = x - centre with every angle entry wrapped."""
    z = states - centre
    for index in angles:
        z[:, index] = wrap(z[:, index])
    return np.einsum("bi,ij,bj->b", z, P, z)


def held_loop(
    plant: Plant, policy: IndependentPolicy, repeat: int, states: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """One control period: (next states, left the allowed region at the start or a held step)."""
    left = plant.leaves(states)
    action = policy.action(plant.observe(states))
    for _ in range(repeat):
        states = plant.step(states, action)
        left = left | plant.leaves(states)
    return states, left


def ellipsoid(
    P: np.ndarray, rho: float, count: int, rng: np.random.Generator, boundary: bool
) -> np.ndarray:
    """Deviations (count, S) uniform in {z^T P z <= rho} (or on z^T P z = rho): u uniform in the
    unit ball (Gaussian direction, radius U^(1/S)), z = sqrt(rho) L^-T u with P = L L^T."""
    size = P.shape[0]
    direction = rng.standard_normal((count, size))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    radius = 1.0 if boundary else rng.uniform(size=(count, 1)) ** (1.0 / size)
    factor = np.linalg.cholesky(P)
    return math.sqrt(rho) * scipy.linalg.solve_triangular(factor.T, (direction * radius).T).T


# ---------------------------------------------------------------- the controllers, by leoc
class Case(NamedTuple):
    """A controller to prove: its system, leoc's controller, LQR design, V choice, budget."""

    system: Any
    controller: Any
    design: Any
    lyapunov: str
    max_seconds: float


def _fresh_actor(system: Any, seed: int) -> MLPActor:
    """A freshly initialised 400x300 ReLU actor, ``u_max tanh`` at the actuator limit."""
    generator = torch.Generator().manual_seed(seed)
    return MLPActor(system.obs_dim, 1, action_limit=system.action_limit, generator=generator)


def _paper_hybrid(name: str) -> Case:
    """The paper's hybrid: G the LQR, H a fresh actor, r = (1 + d)^-2 with Lambda fixed."""
    system = make_system(name)
    design = design_lqr(system)
    spec = HybridSpec(r_min=None, relevance_power=1.0, lambda_init=PAPER_LAMBDA, learn_lambda=False)
    resolved = HybridDesign(design.W, design.b, system.operating_obs, {})
    actor = _fresh_actor(system, ACTOR_SEED)
    hybrid = build_hybrid(spec, resolved, actor, action_limit=system.action_limit)
    return Case(system, hybrid.double().eval(), design, "lqr", PROOF_SECONDS)


def _roa_hybrid(name: str, repeat: int) -> Case:
    """The ROA hybrid (H a fresh actor) at a control period, flat on ``ROA_FLAT_FRACTION`` of
    the LQR's proved level."""
    system = make_system(name)
    design = design_lqr(system, action_repeat=repeat)
    certificate = certify_lqr(system, design, samples=CHECK_SAMPLES)
    actor = _fresh_actor(system, ACTOR_SEED)
    hybrid = roa_hybrid(
        system,
        design,
        actor,
        certificate=certificate,
        rho_in_fraction=ROA_FLAT_FRACTION,
        width_init=1.0,
        learn_width=False,
    )
    held = with_control_period(hybrid.double().eval(), repeat)
    return Case(system, held, design, "lqr", PROOF_SECONDS)


def _baseline(name: str) -> Case:
    """A baseline actor (a fresh actor) whose last layer is fitted by least squares to
    atanh(G / u_max) on half the operating region: near a it approximates the LQR, and its own
    equilibrium is off a (the fit is not exact)."""
    system = make_system(name)
    design = design_lqr(system)
    actor = _fresh_actor(system, BASELINE_SEED)
    rng = np.random.default_rng(BASELINE_SEED)
    half = 0.5 * np.asarray(system.operating_region)
    states = system.operating_state + rng.uniform(-1.0, 1.0, (FIT_STATES, system.state_dim)) * half
    obs = system.observe(torch.as_tensor(states))
    target = (obs.numpy() @ design.W.T + design.b)[:, 0] / system.action_limit
    assert np.max(np.abs(target)) < 1.0
    with torch.no_grad():
        features = actor.net[:-1](obs).numpy()
        basis = np.hstack([features, np.ones((features.shape[0], 1))])
        coef = np.linalg.lstsq(basis, np.arctanh(target), rcond=None)[0]
        actor.net[-1].weight.copy_(torch.as_tensor(coef[None, :-1]))
        actor.net[-1].bias.copy_(torch.as_tensor(coef[-1:]))
    return Case(system, actor.eval(), design, "own", PROOF_SECONDS)


def _lqr(name: str, repeat: int, max_seconds: float) -> Case:
    """leoc's LQR at a control period (the cart-pole's 4-D proof is cut by its budget: a
    smaller level, still proved)."""
    system = make_system(name)
    design = design_lqr(system, action_repeat=repeat)
    return Case(system, lqr_closed_loop(design), design, "lqr", max_seconds)


CASES: dict[str, Callable[[], Case]] = {
    "pendulum-lqr": lambda: _lqr("pendulum", 1, 30.0),
    "mountaincar-lqr-repeat3": lambda: _lqr("mountaincar", 3, 30.0),
    "cartpole-lqr": lambda: _lqr("cartpole", 1, 10.0),
    "pendulum-hybrid-paper": lambda: _paper_hybrid("pendulum"),
    "mountaincar-hybrid-paper": lambda: _paper_hybrid("mountaincar"),
    "pendulum-hybrid-roa": lambda: _roa_hybrid("pendulum", 1),
    "mountaincar-hybrid-roa-repeat3": lambda: _roa_hybrid("mountaincar", 3),
    "pendulum-baseline": lambda: _baseline("pendulum"),
    "mountaincar-baseline": lambda: _baseline("mountaincar"),
}


@functools.cache
def _case(name: str) -> Case:
    return CASES[name]()


@functools.cache
def _proved(name: str) -> Any:
    """certify_controller of the case (small budgets: seconds), once per process."""
    case = _case(name)
    return certify_controller(
        case.system,
        case.controller,
        case.design,
        lyapunov=case.lyapunov,
        samples=CHECK_SAMPLES,
        max_seconds=case.max_seconds,
    )


# ---------------------------------------------------------------- the check
class Tally(NamedTuple):
    """What the numpy loop found on a proved set."""

    states: int
    moving: int  # states with V > the excluded level
    increases: int  # of those, V(next) >= V(x)
    above: int  # V(next) > rho (1 + LEVEL_ROUNDING)
    exits: int  # left the allowed region (or a non-finite next state)
    worst_ratio: float  # max V(next) / V(x) over the moving states
    relevance: tuple[float, float]  # min, max r (1, 1 without a relevance)


def _tally_chunk(
    name: str, policy: IndependentPolicy, level: float, deviations: np.ndarray
) -> Tally:
    """The numpy loop on ``centre + deviations`` of case ``name``'s proved set, ``level`` the
    set's (the proved rho but in the check's own test)."""
    certificate = _proved(name).certificate
    plant = policy.plant
    centre, P = certificate.operating_state, certificate.P
    states = centre + deviations
    following, left = held_loop(plant, policy, certificate.action_repeat, states)
    before = lyapunov(P, centre, plant.angles, states)
    after = lyapunov(P, centre, plant.angles, following)
    moving = before > certificate.proof.excluded_level
    left = left | ~np.isfinite(following).all(axis=1)
    relevance = policy.relevance(plant.observe(states))
    ratio = after[moving] / before[moving]
    return Tally(
        states.shape[0],
        int(moving.sum()),
        int(np.sum(~(after[moving] < before[moving]))),
        int(np.sum(~(after <= level * (1.0 + LEVEL_ROUNDING)))),
        int(left.sum()),
        float(ratio.max()) if ratio.size else -math.inf,
        (float(relevance.min()), float(relevance.max())),
    )


def _merge(first: Tally, second: Tally) -> Tally:
    return Tally(
        *(a + b for a, b in zip(first[:5], second[:5], strict=True)),
        max(first.worst_ratio, second.worst_ratio),
        (
            min(first.relevance[0], second.relevance[0]),
            max(first.relevance[1], second.relevance[1]),
        ),
    )


def check_proved_set(
    name: str, count: int, boundary: bool, seed: int, inflation: float = 1.0
) -> Tally:
    """``count`` states uniform in case ``name``'s proved set (or on its boundary), in chunks;
    ``inflation`` scales the level (1: the proved set)."""
    case, certificate = _case(name), _proved(name).certificate
    policy = independent_policy(case.controller, case.design, PLANTS[case.system.name])
    level = inflation * certificate.rho
    rng = np.random.default_rng(seed)
    total = Tally(0, 0, 0, 0, 0, -math.inf, (math.inf, -math.inf))
    for start in range(0, count, CHUNK):
        size = min(CHUNK, count - start)
        deviations = ellipsoid(certificate.P, level, size, rng, boundary)
        total = _merge(total, _tally_chunk(name, policy, level, deviations))
    return total


def _assert_sound(name: str, counts: tuple[int, int]) -> None:
    """No increase of V outside the excluded level, no V above rho, no exit, for ``counts``
    states uniform in the proved set and on its boundary; the set is not empty, and a hybrid's
    relevance varies over it (the learned part acts there)."""
    proved = _proved(name)
    assert proved.rho > 0.0 and proved.equilibrium.found, proved.summary(_case(name).system)
    uniform = check_proved_set(name, counts[0], boundary=False, seed=11)
    edge = check_proved_set(name, counts[1], boundary=True, seed=12)
    for tally in (uniform, edge):
        assert tally.moving >= 0.99 * tally.states, (name, tally)
        assert tally.increases == 0 and tally.above == 0 and tally.exits == 0, (name, tally)
    if "hybrid" in name:
        low, high = _merge(uniform, edge).relevance
        assert low < VARYING_RELEVANCE and high > 0.99, (name, low, high)
    if "baseline" in name:
        assert np.max(np.abs(proved.equilibrium.offset(_case(name).system))) > 1e-7


# ---------------------------------------------------------------- the tests
@pytest.mark.parametrize("name", sorted(PLANTS))
def test_the_numpy_plants_step_observe_and_leave_as_leoc_does(name):
    """Random states past the speed clip and actions past the actuator limit: the numpy step,
    observation and allowed region agree with leoc's (to STEP_ATOL)."""
    system, plant = make_system(name), PLANTS[name]
    rng = np.random.default_rng(2)
    spread = 4.0 * np.asarray(system.operating_region) + np.asarray(system.start_spread)
    states = system.operating_state + rng.uniform(-1.0, 1.0, (5000, system.state_dim)) * spread
    states[:100, 1] = np.linspace(-9.0, 9.0, 100)  # past the pendulum's speed clip
    actions = rng.uniform(-2.0, 2.0, (5000, 1)) * system.action_limit
    reference = system.step_fn(torch.as_tensor(states), torch.as_tensor(actions)).numpy()
    np.testing.assert_allclose(plant.step(states, actions), reference, rtol=0, atol=STEP_ATOL)
    observed = system.observe(torch.as_tensor(states)).numpy()
    np.testing.assert_allclose(plant.observe(states), observed, rtol=0, atol=STEP_ATOL)
    np.testing.assert_allclose(
        plant.state_of(observed)[:, plant.angles],
        wrap(states[:, plant.angles]),
        rtol=0,
        atol=STEP_ATOL,
    )
    wide = states * np.where(np.arange(system.state_dim) == 0, 4.0, 1.0)
    leaving = system.out_of_bounds(torch.as_tensor(wide)).numpy()
    np.testing.assert_array_equal(plant.leaves(wide), leaving)
    assert leaving.any() == (name != "pendulum")


@pytest.mark.slow
@pytest.mark.parametrize("name", list(CASES))
def test_the_numpy_policies_act_as_leoc_does(name):
    """On states over three times the operating region (where a hybrid's relevance falls), the
    numpy policy equals the controller leoc proves, to STEP_ATOL."""
    case = _case(name)
    system = case.system
    plant = PLANTS[system.name]
    rng = np.random.default_rng(3)
    region = 3.0 * np.asarray(system.operating_region)
    states = system.operating_state + rng.uniform(-1.0, 1.0, (5000, system.state_dim)) * region
    obs = system.observe(torch.as_tensor(states))
    with torch.no_grad():
        expected = torch.as_tensor(case.controller(obs)).numpy()
    policy = independent_policy(case.controller, case.design, plant)
    assert policy.kind == (
        "linear" if "lqr" in name else "actor" if "baseline" in name else "hybrid"
    )
    np.testing.assert_allclose(
        policy.action(plant.observe(states)), expected, rtol=0, atol=STEP_ATOL
    )


FAST_CASES = ("pendulum-lqr", "mountaincar-lqr-repeat3", "pendulum-hybrid-roa")
"""The fast suite's soundness cases (the slow one checks every case): two LQR, one limited by
the decrease and one by the track, and the ROA hybrid, whose level the remainder terms of the
box bound decide (dropping them proved too much only there)."""


@pytest.mark.slow
@pytest.mark.parametrize("name", FAST_CASES)
def test_no_state_of_a_proved_set_increases_v_or_leaves(name):
    _assert_sound(name, FAST_COUNTS)


@pytest.mark.slow
@pytest.mark.parametrize("name", list(CASES))
def test_no_state_of_a_million_in_a_proved_set_increases_v_or_leaves(name):
    _assert_sound(name, SLOW_COUNTS)


def test_the_check_finds_the_violations_just_past_a_proved_level():
    """A level ``INFLATION`` above the proved one: the pendulum LQR's set (limited by the
    decrease) then holds states whose V increases, the mountain car's (limited by the track)
    states that leave the track: the check can fail."""
    pendulum = check_proved_set("pendulum-lqr", FAST_COUNTS[1], True, 12, INFLATION)
    assert pendulum.increases > 0 and pendulum.exits == 0, pendulum
    car = check_proved_set("mountaincar-lqr-repeat3", FAST_COUNTS[1], True, 12, INFLATION)
    assert car.exits > 0 and car.increases == 0, car
