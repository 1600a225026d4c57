"""Tests of leoc.policies.spec (HybridSpec, HybridDesign, hybrid_design, build_hybrid, the legacy
readers) and of the SB3 hybrid actor's legacy keywords (leoc.sb3.common.hybrid_arguments).

Every number is checked against a reference written here independently of the code under test:
the hybrid's formula in numpy, the ROA relevance's level and smootherstep in numpy, the
certificate of :func:`leoc.control.certify_lqr`, and actors built from the keywords that models
saved before HybridSpec used, written out by hand.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import torch
from stable_baselines3 import DDPG
from torch import nn

from leoc.control import certify_lqr, design_lqr
from leoc.pilco.config import PilcoConfig
from leoc.policies.spec import (
    DEFAULT_R_MIN,
    DEFAULT_RELEVANCE_POWER,
    RELEVANCE_DESIGNS,
    HybridDesign,
    HybridSpec,
    PaperRelevanceDesign,
    ROARelevanceDesign,
    as_hybrid_spec,
    build_hybrid,
    hybrid_design,
    legacy_hybrid_config,
    roa_hybrid,
    with_hybrid_overrides,
)
from leoc.sb3.common import hybrid_arguments, hybrid_policy_kwargs
from leoc.sb3.config import DDPGConfig
from leoc.sb3.td3 import HybridTD3Policy
from leoc.systems import make_env, make_system

pytestmark = pytest.mark.usefixtures("single_thread")

DTYPE = torch.float64
ATOL = 1e-12  # float64 hybrid against its numpy formula
#: The paper's relevance as published, r = (1 + d)^-2 unfloored (leoc's defaults floor it and
#: square d since issue 40): the tests of that formula name it.
PAPER = {"r_min": None, "relevance_power": 1.0}
NET = [16, 16]
# Sampled certificate only (no interval proof): the proof costs ~35 s on the pendulum and the
# arithmetic that turns a certificate into rho_in is the same for either.
CERTIFY = {"samples": 2_000, "seed": 0, "prove": False}


# ---------------------------------------------------------------------------------------------
# 1. Validation and the dict round trip
# ---------------------------------------------------------------------------------------------

BAD_FIELDS = [
    ({"relevance": "gaussian"}, "relevance"),
    ({"relevance": None}, "relevance"),
    ({"relevance_parametrisation": "cholesky"}, "relevance_parametrisation"),
    ({"lambda_init": 0.0}, "lambda_init"),
    ({"lambda_init": -1.0}, "lambda_init"),
    ({"lambda_init": math.inf}, "lambda_init"),
    ({"lambda_init": math.nan}, "lambda_init"),
    ({"lambda_init": True}, "lambda_init"),
    ({"lambda_init": "1.0"}, "lambda_init"),
    ({"lambda_init": (1.0, 0.0, 2.0)}, "lambda_init"),
    ({"lambda_init": (1.0, math.inf)}, "lambda_init"),
    ({"lambda_init": (1.0, False)}, "lambda_init"),
    ({"learn_lambda": 1}, "learn_lambda"),
    ({"learn_lambda": "yes"}, "learn_lambda"),
    ({"learn_width": 0}, "learn_width"),
    ({"relevance": "roa", "rho_in_fraction": 0.0}, "rho_in_fraction"),
    ({"relevance": "roa", "rho_in_fraction": -0.5}, "rho_in_fraction"),
    ({"relevance": "roa", "rho_in_fraction": 1.0 + 1e-12}, "rho_in_fraction"),
    ({"relevance": "roa", "rho_in_fraction": 2.0}, "rho_in_fraction"),
    ({"relevance": "roa", "rho_in_fraction": math.nan}, "rho_in_fraction"),
    ({"relevance": "roa", "rho_in_fraction": True}, "rho_in_fraction"),
    ({"relevance": "roa", "rho_in_fraction": "0.5"}, "rho_in_fraction"),
    ({"relevance": "roa", "width_init": 0.0}, "width_init"),
    ({"relevance": "roa", "width_init": -0.3}, "width_init"),
    ({"relevance": "roa", "width_init": math.inf}, "width_init"),
    ({"relevance": "roa", "width_init": True}, "width_init"),
    # the floor (r_min) and the Lyapunov relevance
    ({"r_min": 0.9, "relevance_parametrisation": "precision"}, "r_min"),
    ({"r_min": 0.9, "relevance_parametrisation": "precision", "relevance": "roa"}, "r_min"),
    ({"r_min": 0.0}, "r_min"),
    ({"r_min": 1.0}, "r_min"),
    ({"r_min": -0.5}, "r_min"),
    ({"r_min": math.nan}, "r_min"),
    ({"r_min": True}, "r_min"),
    ({"r_min": "0.9"}, "r_min"),
    ({"relevance": "lyapunov", "lambda_init": (1.0, 2.0, 3.0)}, "lambda_init"),
    ({"relevance": "lyapunov", "lambda_init": 0.0}, "lambda_init"),
    ({"relevance": "lyapunov", "r_min": 0.9}, "r_min"),
    # the relevance's power p of (1 + d^p)^-2
    ({"relevance_power": 0.5}, "relevance_power"),
    ({"relevance_power": 0.0}, "relevance_power"),
    ({"relevance_power": math.inf}, "relevance_power"),
    ({"relevance_power": math.nan}, "relevance_power"),
    ({"relevance_power": True}, "relevance_power"),
    ({"relevance_power": "2"}, "relevance_power"),
    ({"relevance_power": 2.0, "relevance_parametrisation": "precision"}, "relevance_power"),
    ({"relevance_power": 2.0, "relevance": "roa"}, "relevance_power"),
    ({"relevance_power": 2.0, "relevance": "lyapunov"}, "relevance_power"),
]


@pytest.mark.parametrize(("fields", "name"), BAD_FIELDS, ids=[str(f) for f, _ in BAD_FIELDS])
def test_each_bad_field_raises_naming_it(fields, name):
    with pytest.raises(ValueError, match=rf"^{name}: expected"):
        HybridSpec(**fields)
    # the same through from_dict, replace and the config readers
    with pytest.raises(ValueError, match=rf"^{name}: expected"):
        HybridSpec.from_dict(fields)
    with pytest.raises(ValueError, match=rf"^{name}: expected"):
        as_hybrid_spec(fields)
    with pytest.raises(ValueError, match=rf"^{name}: expected"):
        HybridSpec().replace(**fields)


def test_good_edge_values_are_accepted():
    assert HybridSpec(relevance="roa", rho_in_fraction=1.0).rho_in_fraction == 1.0
    assert HybridSpec(relevance="roa", rho_in_fraction=1e-9).rho_in_fraction == 1e-9
    assert HybridSpec(relevance="roa", rho_in_fraction=1).rho_in_fraction == 1
    assert HybridSpec(lambda_init=3).lambda_init == 3
    assert HybridSpec(lambda_init=1e-300).lambda_init == 1e-300
    assert HybridSpec(lambda_init=[0.5, 2]).lambda_init == (0.5, 2.0)  # a list becomes a tuple


def test_unknown_key_in_from_dict_raises_naming_it():
    with pytest.raises(ValueError, match=r"unknown fields \['roa_width'\]"):
        HybridSpec.from_dict({"relevance": "roa", "roa_width": 0.3})
    with pytest.raises(ValueError, match=r"unknown fields \['lambda', 'seed'\]"):
        HybridSpec.from_dict({"seed": 0, "lambda": 1.0})


def test_hybrid_config_value_not_a_spec_is_refused():
    for value in ("paper", 1, 0, [1.0]):
        with pytest.raises(ValueError, match="^hybrid: expected"):
            as_hybrid_spec(value)
    assert as_hybrid_spec(None) is None and as_hybrid_spec(False) is None
    assert as_hybrid_spec(True) == HybridSpec()


def test_the_floor_and_the_power_default_to_the_designs_own():
    """leoc's default hybrid (issue 40): the paper relevance as log lambda is floored at r >= 0.5
    with p = 2; every other design takes no floor and p = 1, which it could not use."""
    spec = HybridSpec()
    assert (spec.r_min, spec.relevance_power) == (0.5, 2.0)
    assert (DEFAULT_R_MIN, DEFAULT_RELEVANCE_POWER) == (0.5, 2.0)
    others = [
        HybridSpec(relevance="roa"),
        HybridSpec(relevance="lyapunov"),
        HybridSpec(relevance_parametrisation="precision"),
        spec.replace(relevance="lyapunov"),  # a defaulted field follows the design
        spec.replace(relevance_parametrisation="precision"),
        spec.replace(relevance="roa").replace(
            relevance="paper", relevance_parametrisation="precision"
        ),
    ]
    for other in others:
        assert (other.r_min, other.relevance_power) == (None, 1.0), other
    assert spec.replace(relevance="roa").replace(relevance="paper") == spec
    # a value given is kept, and checked against the design
    assert HybridSpec(r_min=0.9).replace(relevance_power=3.0).r_min == 0.9
    assert HybridSpec(r_min=None).relevance_power == 2.0
    with pytest.raises(ValueError, match="^r_min: expected None with relevance='lyapunov'"):
        HybridSpec(r_min=0.5).replace(relevance="lyapunov")
    # equal specs whether a value was defaulted or given
    assert spec == HybridSpec(r_min=0.5, relevance_power=2.0)
    assert "_defaulted" not in spec.to_dict() and "_defaulted" not in HybridSpec.field_names()


def test_a_saved_spec_reads_as_it_ran_and_a_users_dict_takes_the_defaults():
    """A run saved before ``r_min`` and ``relevance_power`` existed trained the paper's
    relevance: its dict, without them, must not read as today's floored default."""
    saved = HybridSpec(**PAPER).to_dict()
    for missing in (["relevance_power"], ["r_min", "relevance_power"]):
        old = {key: value for key, value in saved.items() if key not in missing}
        assert HybridSpec.from_dict(old) == HybridSpec(**PAPER)
        assert legacy_hybrid_config({"hybrid": old})["hybrid"] == saved
    assert HybridSpec.from_dict(HybridSpec().to_dict()) == HybridSpec()
    assert as_hybrid_spec({"relevance": "paper"}) == HybridSpec()
    assert as_hybrid_spec({}) == HybridSpec()
    with pytest.raises(ValueError, match=r"unknown fields \['floor'\]"):
        as_hybrid_spec({"floor": 0.5})


ROUND_TRIP_SPECS = [
    HybridSpec(),
    HybridSpec(lambda_init=(0.25, 2.0, 7.5), learn_lambda=False),
    HybridSpec(relevance_parametrisation="precision", lambda_init=0.5),
    HybridSpec(relevance="roa", rho_in_fraction=0.5, width_init=0.3, learn_width=False),
]


@pytest.mark.parametrize("spec", ROUND_TRIP_SPECS)
def test_to_dict_from_dict_round_trip_through_json(spec):
    data = spec.to_dict()
    text = json.dumps(data)  # JSON-friendly: no tuples, no numpy scalars left
    back = HybridSpec.from_dict(json.loads(text))
    assert back == spec
    assert back.to_dict() == data
    assert sorted(data) == sorted(HybridSpec.field_names())
    if isinstance(spec.lambda_init, tuple):
        assert isinstance(back.lambda_init, tuple)
        assert json.loads(text)["lambda_init"] == list(spec.lambda_init)


def test_relevance_designs_are_registered_by_name():
    assert isinstance(RELEVANCE_DESIGNS["paper"], PaperRelevanceDesign)
    assert isinstance(RELEVANCE_DESIGNS["roa"], ROARelevanceDesign)
    assert HybridSpec(relevance="roa").design is RELEVANCE_DESIGNS["roa"]


def test_hybrid_design_checks_shapes_and_round_trips():
    design = HybridDesign(gain=[[1.0, 2.0, 3.0]], bias=[0.5], operating_obs=[0.0, 1.0, 0.0])
    assert HybridDesign.from_dict(json.loads(json.dumps(design.to_dict()))) == design
    with pytest.raises(ValueError, match="^gain: expected shape"):
        HybridDesign(gain=[[1.0, 2.0]], bias=[0.5], operating_obs=[0.0, 1.0, 0.0])
    with pytest.raises(ValueError, match="^bias: expected finite"):
        HybridDesign(gain=[[1.0, 2.0, 3.0]], bias=[math.nan], operating_obs=[0.0, 1.0, 0.0])


# ---------------------------------------------------------------------------------------------
# 2. build_hybrid against the formula sat(r G + (1 - r) H), written in numpy
# ---------------------------------------------------------------------------------------------

RNG_SEED = 7
D, F = 3, 2
LAMBDA = (0.5, 2.0, 1.5)
BOX_CENTRE = np.array([0.5, -1.0])
BOX_HALF = np.array([2.0, 3.0])
LIMIT = 0.6  # |G(a)| = (0.2, 0.3) inside it; H and G reach beyond it away from a


def _random_design(centre: np.ndarray) -> HybridDesign:
    """Random W, a; b chosen so that G(a) = W a + b = centre + small (inside any box used)."""
    rng = np.random.default_rng(RNG_SEED)
    gain = rng.standard_normal((F, D))
    point = rng.standard_normal(D)
    bias = centre + np.array([0.2, -0.3]) - gain @ point
    return HybridDesign(gain=gain, bias=bias, operating_obs=point)


class _TanhLayer(nn.Module):
    """H(x) = tanh(M x + m), float64, with the weights kept for the numpy reference."""

    def __init__(self) -> None:
        super().__init__()
        rng = np.random.default_rng(RNG_SEED + 1)
        self.M = rng.standard_normal((F, D))
        self.m = rng.standard_normal(F)
        self.layer = nn.Linear(D, F, dtype=DTYPE)
        with torch.no_grad():
            self.layer.weight.copy_(torch.as_tensor(self.M))
            self.layer.bias.copy_(torch.as_tensor(self.m))

    def forward(self, x):
        return torch.tanh(self.layer(x))

    def numpy(self, x: np.ndarray) -> np.ndarray:
        return np.tanh(x @ self.M.T + self.m)


def _reference(design, H, x, lam, centre=None, half=None, limit=None):
    """sat(r G + (1 - r) H) in numpy, r = 1 / (1 + sum((x - a)^2 / lambda))^2."""
    W, b, a = (np.asarray(v) for v in (design.gain, design.bias, design.operating_obs))
    r = 1.0 / (1.0 + ((x - a) ** 2 / np.asarray(lam)).sum(axis=-1, keepdims=True)) ** 2
    G = x @ W.T + b
    if centre is not None:
        G = (G - centre) / half
    blend = r * G + (1.0 - r) * H.numpy(x)
    action = blend if limit is None else np.clip(blend, -limit, limit)
    return action, r


def _points(design, count=400):
    rng = np.random.default_rng(RNG_SEED + 2)
    a = np.asarray(design.operating_obs)
    scale = np.exp(rng.uniform(-3.0, 1.5, size=(count, 1)))  # r from ~1 down to ~0
    return a + scale * rng.standard_normal((count, D))


PARAMETRISATIONS = ["log_lambda", "precision"]


@pytest.mark.parametrize("parametrisation", PARAMETRISATIONS)
@pytest.mark.parametrize("learn", [True, False])
def test_build_hybrid_in_physical_units_is_the_formula(parametrisation, learn):
    design = _random_design(np.zeros(F))
    H = _TanhLayer()
    spec = HybridSpec(
        lambda_init=LAMBDA, learn_lambda=learn, relevance_parametrisation=parametrisation, **PAPER
    )
    policy = build_hybrid(spec, design, H, action_limit=LIMIT)
    x = _points(design)
    expected, r = _reference(design, H, x, LAMBDA, limit=LIMIT)
    with torch.no_grad():
        action, relevance = policy(torch.as_tensor(x), return_relevance=True)
    np.testing.assert_allclose(relevance.numpy(), r, rtol=0, atol=ATOL)
    np.testing.assert_allclose(action.numpy(), expected, rtol=0, atol=ATOL)
    assert np.any(np.abs(expected) == LIMIT) and np.any(np.abs(expected) < LIMIT)  # both cases
    assert r.min() < 0.01 and r.max() > 0.9
    # what training may change: the relevance's weights iff learn_lambda
    own = {name for name, _ in policy.named_parameters() if not name.startswith("nonlinear.")}
    expected_names = (
        {"log_lambda"} if parametrisation == "log_lambda" else {"relevance_module.precision"}
    )
    assert own == (expected_names if learn else set())


@pytest.mark.parametrize("parametrisation", PARAMETRISATIONS)
def test_build_hybrid_in_an_action_box_is_the_normalised_formula(parametrisation):
    design = _random_design(BOX_CENTRE)
    H = _TanhLayer()
    spec = HybridSpec(lambda_init=LAMBDA, relevance_parametrisation=parametrisation, **PAPER)
    policy = build_hybrid(spec, design, H, action_limit=1.0, action_box=(BOX_CENTRE, BOX_HALF))
    x = _points(design)
    expected, r = _reference(design, H, x, LAMBDA, BOX_CENTRE, BOX_HALF, limit=1.0)
    with torch.no_grad():
        action = policy(torch.as_tensor(x)).numpy()
    np.testing.assert_allclose(action, expected, rtol=0, atol=ATOL)
    assert np.any(np.abs(expected) == 1.0) and np.any(np.abs(expected) < 1.0)
    # the physical action c + h * action is the physical hybrid with H_phys = c + h H
    W, b = np.asarray(design.gain), np.asarray(design.bias)
    physical = np.clip(
        r * (x @ W.T + b) + (1 - r) * (BOX_CENTRE + BOX_HALF * H.numpy(x)),
        BOX_CENTRE - BOX_HALF,
        BOX_CENTRE + BOX_HALF,
    )
    np.testing.assert_allclose(BOX_CENTRE + BOX_HALF * action, physical, rtol=0, atol=1e-11)


@pytest.mark.parametrize("parametrisation", PARAMETRISATIONS)
@pytest.mark.parametrize("box", [False, True])
def test_identities_at_the_operating_point(parametrisation, box):
    centre = BOX_CENTRE if box else np.zeros(F)
    design = _random_design(centre)
    spec = HybridSpec(lambda_init=LAMBDA, relevance_parametrisation=parametrisation, **PAPER)
    kwargs = {"action_limit": 1.0, "action_box": (centre, BOX_HALF)} if box else {}
    policy = build_hybrid(spec, design, _TanhLayer(), **({"action_limit": LIMIT} | kwargs))
    W, b, a = (np.asarray(v) for v in (design.gain, design.bias, design.operating_obs))
    G_a, slope = W @ a + b, W
    if box:
        G_a, slope = (G_a - centre) / BOX_HALF, W / BOX_HALF[:, None]
    point = torch.as_tensor(a)
    with torch.no_grad():
        assert torch.equal(policy(point[None])[0], policy.linear(point))  # pi(a) = G(a) exactly
        np.testing.assert_allclose(policy(point[None])[0].numpy(), G_a, rtol=0, atol=ATOL)
    jacobian = torch.autograd.functional.jacobian(lambda x: policy(x[None])[0], point)
    np.testing.assert_allclose(jacobian.numpy(), slope, rtol=0, atol=ATOL)  # dpi/dx(a) = W


# ---------------------------------------------------------------------------------------------
# 3. The ROA relevance: rho_in from the certificate, flat on {V < rho_in}
# ---------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def pendulum_roa():
    system = make_system("pendulum")
    design = design_lqr(system)
    certificate = certify_lqr(system, design, **CERTIFY)
    assert certificate.certified
    return system, design, certificate


def _pendulum_obs(z: np.ndarray) -> np.ndarray:
    """Observation (cos theta, sin theta, theta_dot) of deviations z from the upright state."""
    return np.stack([np.cos(z[:, 0]), np.sin(z[:, 0]), z[:, 1]], axis=-1)


def _deviations_at_levels(P: np.ndarray, levels: np.ndarray, seed: int) -> np.ndarray:
    """z with z^T P z = level exactly (random directions): z = sqrt(level) L^-T u / |u|."""
    rng = np.random.default_rng(seed)
    u = rng.standard_normal((levels.shape[0], P.shape[0]))
    u /= np.linalg.norm(u, axis=-1, keepdims=True)
    L = np.linalg.cholesky(P)
    return np.sqrt(levels)[:, None] * np.linalg.solve(L.T, u.T).T


def test_hybrid_design_resolves_rho_in_from_the_certificate(pendulum_roa):
    system, design, certificate = pendulum_roa
    spec = HybridSpec(relevance="roa", rho_in_fraction=0.5)
    resolved = hybrid_design(spec, system, design, **CERTIFY)
    data = resolved.relevance_data
    assert data["rho_in"] == 0.5 * certificate.rho  # exactly
    assert np.array_equal(np.asarray(data["lyapunov_matrix"]), design.P)
    assert np.array_equal(np.asarray(data["operating_state"]), system.operating_state)
    assert data["obs_layout"] == [["cos", 0], ["sin", 0], ["state", 1]]
    assert np.array_equal(np.asarray(resolved.gain), design.W)
    assert np.array_equal(np.asarray(resolved.bias), design.b)
    assert resolved.operating_obs == (1.0, 0.0, 0.0)
    # a given certificate gives the same numbers; the paper's relevance needs none
    assert hybrid_design(spec, system, design, certificate=certificate) == resolved
    assert hybrid_design(HybridSpec(**PAPER), system, design).relevance_data == {}
    json.dumps(resolved.to_dict())


def test_roa_hybrid_is_flat_exactly_inside_rho_in_and_falls_in_the_band(pendulum_roa):
    system, design, certificate = pendulum_roa
    width = 0.3
    spec = HybridSpec(relevance="roa", rho_in_fraction=0.5, width_init=width)
    resolved = hybrid_design(spec, system, design, certificate=certificate)
    rho_in = 0.5 * certificate.rho
    H = nn.Sequential(nn.Linear(3, 1, dtype=DTYPE), nn.Tanh())
    policy = build_hybrid(spec, resolved, H, action_limit=system.action_limit)
    P = np.asarray(design.P)
    fractions = np.concatenate(
        [
            np.random.default_rng(0).uniform(0.0, 0.999, 300),  # flat top
            np.random.default_rng(1).uniform(1.001, 1.0 + width * 0.999, 300),  # the band
            np.random.default_rng(2).uniform(1.0 + width * 1.001, 1.0 + 2 * width, 100),
        ]
    )
    z = _deviations_at_levels(P, fractions * rho_in, seed=3)
    assert np.abs(z[:, 0]).max() < math.pi  # inside the angle chart: no wrap
    V = np.einsum("bi,ij,bj->b", z, P, z)
    np.testing.assert_allclose(V / rho_in, fractions, rtol=1e-12)
    obs = _pendulum_obs(z)
    with torch.no_grad():
        action, relevance = policy(torch.as_tensor(obs), return_relevance=True)
    r = relevance.numpy()[:, 0]
    inside, band, beyond = (
        V < rho_in,
        (V > rho_in) & (V < (1 + width) * rho_in),
        V > (1 + width) * rho_in,
    )
    assert inside.sum() == 300 and band.sum() == 300 and beyond.sum() == 100
    assert np.all(r[inside] == 1.0)
    assert np.all(r[~inside] < 1.0)
    assert np.all(r[beyond] == 0.0)
    # the band: 1 - smootherstep(t), t = (V / rho_in - 1) / w
    t = (V[band] / rho_in - 1.0) / width
    np.testing.assert_allclose(r[band], 1.0 - (10 * t**3 - 15 * t**4 + 6 * t**5), atol=1e-9)
    # on the flat top the hybrid is the clipped LQR: bit for bit, and the formula in numpy
    limit = system.action_limit
    with torch.no_grad():
        clipped = torch.clamp(policy.linear(torch.as_tensor(obs)), -limit, limit).numpy()
    assert np.array_equal(action.numpy()[inside], clipped[inside])
    G = obs @ np.asarray(design.W).T + np.asarray(design.b)
    np.testing.assert_allclose(action.numpy()[inside], np.clip(G[inside], -limit, limit), atol=ATOL)
    assert np.any(np.abs(G[inside]) > limit)  # the clip acts on the flat top too


def test_a_certificate_for_another_p_or_period_is_refused(pendulum_roa):
    system, design, certificate = pendulum_roa
    spec = HybridSpec(relevance="roa")
    for wrong in (
        certificate._replace(P=2.0 * certificate.P),
        certificate._replace(action_repeat=certificate.action_repeat + 1),
    ):
        with pytest.raises(ValueError, match="^certificate: expected one for the design's P"):
            hybrid_design(spec, system, design, certificate=wrong)
        with pytest.raises(ValueError, match="^certificate: expected"):
            roa_hybrid(system, design, nn.Linear(3, 1, dtype=DTYPE), certificate=wrong)
    with pytest.raises(ValueError, match="no certified region of attraction"):
        hybrid_design(spec, system, design, certificate=certificate._replace(rho=0.0))


def test_roa_hybrid_rho_in_must_lie_in_0_rho(pendulum_roa):
    system, design, certificate = pendulum_roa
    H = nn.Linear(3, 1, dtype=DTYPE)
    rho = certificate.rho
    for bad in (0.0, -1.0, rho * (1 + 1e-9), 2 * rho):
        with pytest.raises(ValueError, match="^rho_in: expected a level in"):
            roa_hybrid(system, design, H, certificate=certificate, rho_in=bad)
    for good, fraction in ((rho, 1.0), (0.25 * rho, 1.0), (0.1, 0.5)):
        policy = roa_hybrid(
            system, design, H, certificate=certificate, rho_in=good, rho_in_fraction=fraction
        )
        assert float(policy.relevance_module.rho_in) == good  # rho_in wins over the fraction
    policy = roa_hybrid(system, design, H, certificate=certificate, rho_in_fraction=0.25)
    assert float(policy.relevance_module.rho_in) == 0.25 * rho


# ---------------------------------------------------------------------------------------------
# 4. Configs and SB3 models saved before HybridSpec
# ---------------------------------------------------------------------------------------------

OLD_SETTINGS = {
    "system": "pendulum",
    "algo": "ddpg",
    "total_steps": 3_000,
    "batch_size": 32,
    "actor_hidden": [16, 16],
    "critic_hidden": [16, 16],
    "eval_interval": 500,
    "step_rules": {},
}


def _old_ddpg_dict(hybrid: bool) -> dict:
    """A DDPG config as saved before HybridSpec: ``hybrid`` a bool, its fields flat beside it."""
    return {
        **OLD_SETTINGS,
        "hybrid": hybrid,
        "lambda_init": 2.0,
        "learn_lambda": False,
        "relevance_parametrisation": "log_lambda",
        "relevance": "roa",
        "roa_rho_fraction": 0.5,
        "roa_width": 0.3,
        "learn_width": False,
        "seed": 4,  # saved beside the config in some runs
    }


FLAT_KEYS = (
    "lambda_init",
    "learn_lambda",
    "relevance_parametrisation",
    "relevance",
    "roa_rho_fraction",
    "roa_width",
    "learn_width",
)
EXPECTED_SPEC = {
    "relevance": "roa",
    "relevance_parametrisation": "log_lambda",
    "lambda_init": 2.0,
    "learn_lambda": False,
    "rho_in_fraction": 0.5,
    "width_init": 0.3,
    "learn_width": False,
    # fields added after these configs were saved: their defaults
    "r_min": None,
    "relevance_lr_scale": 1.0,
    "relevance_power": 1.0,
}


def test_legacy_hybrid_config_of_an_old_flat_ddpg_config():
    old = _old_ddpg_dict(True)
    snapshot = json.loads(json.dumps(old))
    new = legacy_hybrid_config(old)
    assert old == snapshot  # the input is not changed
    assert new["hybrid"] == EXPECTED_SPEC
    for key in FLAT_KEYS:
        assert key not in new
    assert {k: v for k, v in new.items() if k != "hybrid"} == {**OLD_SETTINGS, "seed": 4}
    baseline = legacy_hybrid_config(_old_ddpg_dict(False))
    assert baseline["hybrid"] is None
    assert not set(FLAT_KEYS) & set(baseline)
    # today's configs pass through as they are
    today = {**OLD_SETTINGS, "hybrid": EXPECTED_SPEC}
    assert legacy_hybrid_config(today) == today
    assert legacy_hybrid_config({**OLD_SETTINGS, "hybrid": None})["hybrid"] is None


def test_legacy_hybrid_config_refuses_a_bad_old_value():
    with pytest.raises(ValueError, match="^rho_in_fraction: expected"):
        legacy_hybrid_config({**_old_ddpg_dict(True), "roa_rho_fraction": 1.5})


@pytest.mark.parametrize("hybrid", [True, False])
def test_ddpg_config_from_an_old_dict_equals_for_system(hybrid):
    settings = {k: v for k, v in OLD_SETTINGS.items() if k not in ("system", "algo")}
    expected = DDPGConfig.for_system(
        "pendulum",
        hybrid=hybrid,
        lambda_init=2.0,
        learn_lambda=False,
        relevance="roa",
        rho_in_fraction=0.5,
        width_init=0.3,
        learn_width=False,
        **settings,
    )
    loaded = DDPGConfig.from_dict(_old_ddpg_dict(hybrid))
    assert loaded == expected
    if hybrid:
        assert loaded.hybrid == HybridSpec(**EXPECTED_SPEC)
    else:
        assert loaded.hybrid is None
    # and today's dict of it round-trips through JSON
    assert DDPGConfig.from_dict(json.loads(json.dumps(loaded.as_dict()))) == loaded


def test_pilco_config_from_an_old_dict_equals_for_system():
    # a config saved before the floor and the power existed: the paper's relevance, as it ran
    expected = PilcoConfig.for_system(
        "pendulum", hybrid=True, lambda_init=0.5, learn_lambda=False, **PAPER
    )
    old = expected.to_dict()
    old.update(hybrid=True, lambda_init=0.5, learn_lambda=False, relevance="paper")
    assert PilcoConfig.from_dict(old) == expected
    old.update(hybrid=False)
    assert PilcoConfig.from_dict(old).hybrid is None


def _ddpg(policy_kwargs: dict) -> DDPG:
    return DDPG(
        HybridTD3Policy,
        make_env("pendulum"),
        policy_kwargs={**policy_kwargs, "net_arch": list(NET)},
        buffer_size=1_000,
        seed=0,
        device="cpu",
    )


def _old_paper_keywords(system, design, parametrisation: str) -> dict:
    """The keywords a hybrid DDPG model saved before HybridSpec holds (paper relevance)."""
    return {
        "lqr_gain": design.W.tolist(),
        "lqr_bias": design.b.tolist(),
        "operating_obs": np.asarray(system.operating_obs).tolist(),
        "lambda_init": 2.0,
        "learn_lambda": False,
        "relevance": "paper",
        "relevance_parametrisation": parametrisation,
        "clip_output": True,
    }


ROA_RHO_IN = 10.0
ROA_WIDTH = 0.3


def _old_roa_keywords(system, design) -> dict:
    """The keywords of an ROA hybrid DDPG model saved before HybridSpec (rho_in resolved)."""
    return {
        "lqr_gain": design.W.tolist(),
        "lqr_bias": design.b.tolist(),
        "operating_obs": [1.0, 0.0, 0.0],
        "lambda_init": 1.0,
        "learn_lambda": True,
        "relevance": "roa",
        "relevance_parametrisation": "log_lambda",
        "roa_obs_layout": [["cos", 0], ["sin", 0], ["state", 1]],
        "roa_operating_state": [0.0, 0.0],
        "roa_lyapunov_matrix": design.P.tolist(),
        "roa_rho_in": ROA_RHO_IN,
        "roa_width_init": ROA_WIDTH,
        "learn_width": False,
        "clip_output": True,
    }


def _assert_same_actor(old_model, new_model):
    for old, new in (
        (old_model.actor, new_model.actor),
        (old_model.actor_target, new_model.actor_target),
    ):
        old_state, new_state = old.state_dict(), new.state_dict()
        assert list(old_state) == list(new_state)
        for key in old_state:
            assert torch.equal(old_state[key], new_state[key]), key
        assert old.hybrid_spec == new.hybrid_spec
        obs = torch.as_tensor(np.random.default_rng(5).uniform(-1, 1, (64, 3)), dtype=torch.float32)
        with torch.no_grad():
            assert torch.equal(old(obs), new(obs))
    old_params = old_model.policy._get_constructor_parameters()
    new_params = new_model.policy._get_constructor_parameters()
    for key in ("hybrid_spec", "hybrid_design", "clip_output"):
        assert old_params[key] == new_params[key], key


@pytest.mark.parametrize("parametrisation", PARAMETRISATIONS)
def test_sb3_actor_from_old_paper_keywords_is_the_new_one(parametrisation):
    system = make_system("pendulum")
    design = design_lqr(system)
    old_model = _ddpg(_old_paper_keywords(system, design, parametrisation))
    spec = HybridSpec(
        lambda_init=2.0, learn_lambda=False, relevance_parametrisation=parametrisation, **PAPER
    )
    new_model = _ddpg(hybrid_policy_kwargs(system, spec))
    _assert_same_actor(old_model, new_model)
    # and the old keywords reached the actor (not both routes dropping them alike)
    actor = old_model.actor
    if parametrisation == "log_lambda":
        assert torch.equal(actor.hybrid.log_lambda, torch.log(torch.tensor([2.0] * 3)))
        assert "log_lambda" not in dict(actor.named_parameters())
    else:
        precision = actor.hybrid.relevance_module.precision
        assert torch.equal(precision, torch.full((3,), 0.5))
        assert "hybrid.relevance_module.precision" not in dict(actor.named_parameters())
    np.testing.assert_array_equal(actor.physical_gain.numpy(), design.W)
    W_normalised = design.W / system.action_limit
    np.testing.assert_allclose(
        actor.hybrid.linear.W.numpy(), W_normalised.astype(np.float32), rtol=0, atol=0
    )


def test_sb3_actor_from_old_roa_keywords_is_the_new_one():
    system = make_system("pendulum")
    design = design_lqr(system)
    old_model = _ddpg(_old_roa_keywords(system, design))
    spec = HybridSpec(relevance="roa", width_init=ROA_WIDTH, learn_width=False)
    resolved = HybridDesign(
        gain=design.W,
        bias=design.b,
        operating_obs=system.operating_obs,
        relevance_data={
            "obs_layout": [["cos", 0], ["sin", 0], ["state", 1]],
            "operating_state": [0.0, 0.0],
            "lyapunov_matrix": design.P.tolist(),
            "rho_in": ROA_RHO_IN,
        },
    )
    new_model = _ddpg({"hybrid_spec": spec, "hybrid_design": resolved, "clip_output": True})
    _assert_same_actor(old_model, new_model)
    relevance = old_model.actor.hybrid.relevance_module
    assert float(relevance.rho_in) == ROA_RHO_IN
    assert math.isclose(float(relevance.width), ROA_WIDTH, rel_tol=1e-6)
    assert not any(name.endswith("width_param") for name, _ in relevance.named_parameters())
    assert old_model.actor.hybrid_design.relevance_data["rho_in"] == ROA_RHO_IN


def test_a_model_built_from_old_roa_keywords_saves_and_loads(tmp_path):
    system = make_system("pendulum")
    model = _ddpg(_old_roa_keywords(system, design_lqr(system)))
    model.save(tmp_path / "model.zip")
    loaded = DDPG.load(tmp_path / "model.zip", device="cpu")
    _assert_same_actor(model, loaded)
    saved = loaded.policy._get_constructor_parameters()
    assert not any(key.startswith(("lqr_", "roa_")) for key in saved)  # today's keywords


def test_old_keywords_beside_hybrid_spec_are_refused():
    system = make_system("pendulum")
    design = design_lqr(system)
    kwargs = hybrid_policy_kwargs(system)
    for key in ("lqr_gain", "relevance", "roa_rho_in"):
        mixed = {**kwargs, key: _old_roa_keywords(system, design)[key]}
        with pytest.raises(ValueError, match=rf"\['{key}'\] belong in hybrid_spec"):
            hybrid_arguments(dict(mixed))
    with pytest.raises(ValueError, match="belong in hybrid_spec"):
        _ddpg({**kwargs, "lqr_gain": design.W.tolist()})
    with pytest.raises(ValueError, match="needs hybrid_spec, hybrid_design"):
        hybrid_arguments({"net_arch": NET})


def test_hybrid_arguments_pops_its_keywords():
    kwargs = {**hybrid_policy_kwargs("pendulum"), "net_arch": NET}
    kwargs.pop("clip_output")
    out = hybrid_arguments(kwargs)
    assert kwargs == {"net_arch": NET}
    assert HybridSpec.from_dict(out["hybrid_spec"]) == HybridSpec()
    old = {
        **_old_paper_keywords(
            make_system("pendulum"), design_lqr(make_system("pendulum")), "precision"
        )
    }
    old.pop("clip_output")
    old["net_arch"] = NET
    out = hybrid_arguments(old)
    assert old == {"net_arch": NET}
    assert out["hybrid_spec"]["relevance_parametrisation"] == "precision"


# ---------------------------------------------------------------------------------------------
# 5. Overrides: HybridSpec fields among a learner's keywords
# ---------------------------------------------------------------------------------------------


def test_with_hybrid_overrides_pops_and_applies_the_spec_fields():
    overrides = {"relevance": "roa", "width_init": 0.4, "total_steps": 100, "lambda_init": 3.0}
    spec = with_hybrid_overrides(True, overrides)
    assert overrides == {"total_steps": 100}
    assert spec == HybridSpec(relevance="roa", width_init=0.4, lambda_init=3.0)
    base = HybridSpec(relevance_parametrisation="precision", learn_lambda=False)
    overrides = {"learn_lambda": True, "batch_size": 8}
    assert with_hybrid_overrides(base.to_dict(), overrides) == base.replace(learn_lambda=True)
    assert overrides == {"batch_size": 8}
    assert with_hybrid_overrides(base, {}) == base


def test_with_hybrid_overrides_drops_them_for_a_baseline_once_checked():
    overrides = {"lambda_init": 3.0, "relevance": "roa", "total_steps": 100}
    assert with_hybrid_overrides(None, overrides) is None
    assert overrides == {"total_steps": 100}
    for bad in (
        {"lambda_init": -1.0},
        {"learn_lambda": "no"},
        {"relevance": "nope"},
        {"relevance": "roa", "rho_in_fraction": 0.0},
    ):
        name = [key for key in bad if key != "relevance" or len(bad) == 1][0]
        with pytest.raises(ValueError, match=rf"^{name}: expected"):
            with_hybrid_overrides(None, dict(bad))
        with pytest.raises(ValueError, match=rf"^{name}: expected"):
            DDPGConfig.for_system("pendulum", **bad)


def test_config_for_system_with_spec_fields():
    config = DDPGConfig.for_system("pendulum", hybrid=True, relevance="roa")
    assert config.hybrid.relevance == "roa"
    assert config.hybrid == HybridSpec(relevance="roa")
    assert DDPGConfig.for_system("pendulum", relevance="roa").hybrid is None
    config = DDPGConfig.for_system("pendulum", hybrid=True, relevance_parametrisation="precision")
    assert config.hybrid.relevance_parametrisation == "precision"
    with pytest.raises(ValueError, match="unknown DDPGConfig fields"):
        DDPGConfig.for_system("pendulum", hybrid=True, roa_width=0.3)
    pilco = PilcoConfig.for_system("pendulum", hybrid=True, relevance="roa", rho_in_fraction=0.5)
    assert pilco.hybrid == HybridSpec(relevance="roa", rho_in_fraction=0.5)
    with pytest.raises(ValueError, match="^relevance_parametrisation: PILCO's hybrid"):
        PilcoConfig.for_system("pendulum", hybrid=True, relevance_parametrisation="precision")
    # a baseline PILCO run drops the field (the DDPG settings name it for baselines too)
    assert PilcoConfig.for_system("pendulum", relevance_parametrisation="precision").hybrid is None


@pytest.mark.parametrize(
    "fields",
    [
        {"relevance": "roa", "relevance_parametrisation": "cholesky"},
        {"rho_in_fraction": 5.0},
        {"width_init": -1.0},
    ],
    ids=str,
)
def test_a_field_of_the_other_design_is_checked_too(fields):
    name = [key for key in fields if key != "relevance"][0]
    with pytest.raises(ValueError, match=rf"^{name}: expected"):
        with_hybrid_overrides(None, dict(fields))  # "a bad value is an error for every run"


def test_a_run_folder_saved_before_the_spec_is_still_the_same_run(tmp_path):
    """A config.json written before HybridSpec (``hybrid`` a bool, the hybrid's fields flat
    beside it) is the same run as today's config of those settings, so the run resumes; a
    different setting is still refused, naming it."""
    from leoc.sb3 import DDPGConfig
    from leoc.training import CONFIG_FILE, same_run

    today = DDPGConfig.for_system("pendulum", hybrid=True, relevance="roa", rho_in_fraction=0.5)
    saved = {key: value for key, value in today.as_dict().items() if key != "hybrid"}
    saved.update(
        hybrid=True,
        lambda_init=1.0,
        learn_lambda=True,
        relevance_parametrisation="log_lambda",
        relevance="roa",
        roa_rho_fraction=0.5,
        roa_width=1.0,
        learn_width=True,
        seed=3,
    )
    (tmp_path / CONFIG_FILE).write_text(json.dumps(saved), encoding="utf-8")
    config = {**today.as_dict(), "seed": 3}
    with pytest.raises(ValueError, match="another configuration"):
        same_run(tmp_path, config)  # read as it is written, the layouts differ
    assert same_run(tmp_path, config, normalise=legacy_hybrid_config)
    other = {**config, "hybrid": HybridSpec(relevance="roa").to_dict()}
    with pytest.raises(ValueError, match="hybrid:"):
        same_run(tmp_path, other, normalise=legacy_hybrid_config)
