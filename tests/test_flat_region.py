"""Flat regions (leoc.control.proof, **Flat regions**): where a controller says it is a simpler
one (the ROA hybrid: its linear part on the relevance's flat top), a proof evaluates the
simpler one on the boxes it shows to lie there.

References: the largest level of a box in V's own coordinates (|w|^2 at the farthest corner,
a closed form), V evaluated in NumPy on dense states of a box, and the proof of the LQR that
the hybrid equals on its flat top."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from torch import nn

from leoc.control import certify_level, certify_lqr, design_lqr
from leoc.control.intervals import box_jet
from leoc.control.proof import _flat_rows, _frame, _with_flat_region
from leoc.policies import lqr_controller, roa_hybrid
from leoc.policies.relevance import FlatRegion
from leoc.systems import make_system
from leoc.systems.base import DTYPE

LEVEL = 6.0
BOXES = 4000


def _region(P: np.ndarray, operating: np.ndarray, angles: tuple[int, ...]) -> FlatRegion:
    return FlatRegion(
        torch.as_tensor(P, dtype=DTYPE),
        torch.as_tensor(operating, dtype=DTYPE),
        LEVEL,
        angles,
        None,
    )


def _boxes(size: int, seed: int) -> tuple[torch.Tensor, torch.Tensor]:
    """Boxes in w about the ball |w|^2 <= 1.5 LEVEL: centres inside it, half-widths up to 0.4."""
    rng = np.random.default_rng(seed)
    direction = rng.standard_normal((BOXES, size))
    length = np.sqrt(1.5 * LEVEL) * rng.uniform(0.0, 1.0, (BOXES, 1))
    centre = direction / np.linalg.norm(direction, axis=1, keepdims=True) * length
    radius = rng.uniform(0.0, 0.4, (BOXES, size))
    return torch.as_tensor(centre), torch.as_tensor(radius)


def _states(frame, centre, radius) -> torch.Tensor:
    return box_jet(centre, radius, frame.inverse) + frame.operating


def test_in_v_own_coordinates_a_box_is_flat_exactly_when_its_farthest_corner_is():
    """V_r = V (the frame's P and centre a): a box is flat iff sum (|c| + h)^2 <= level, up to
    1e-9 relative (the frame's rounding), on the cart-pole (4 dimensions, one angle), with a
    box in every orthant that only its farthest corner keeps from being flat."""
    system = make_system("cartpole")
    P = design_lqr(system).P
    frame = _frame(system, P)
    region = _region(P, system.operating_state, tuple(system.angle_indices))
    centre, radius = _boxes(4, seed=0)
    # and in each of the 16 orthants a box whose farthest corner alone lies outside the level
    signs = torch.tensor(np.array(np.meshgrid(*[[-1.0, 1.0]] * 4)).reshape(4, -1).T)
    near, far = 0.99 * np.sqrt(LEVEL / 4), np.sqrt(1.01 * LEVEL / 4)
    centre = torch.cat([centre, near * signs])
    radius = torch.cat([radius, torch.full_like(signs, far - near)])
    flat = _flat_rows(region, frame, centre, radius, _states(frame, centre, radius))
    assert not torch.any(flat[-16:])
    farthest = ((centre.abs() + radius) ** 2).sum(-1)
    assert torch.all(flat[farthest <= LEVEL * (1.0 - 1e-9)])
    assert not torch.any(flat[farthest >= LEVEL * (1.0 + 1e-9)])
    assert 0.1 < float(flat.double().mean()) < 0.9  # both verdicts are exercised


@pytest.mark.parametrize("name", ["pendulum", "cartpole"])
def test_a_flat_box_has_every_state_inside_and_a_box_left_out_has_one_outside(name):
    """V_r with another P and centre than the frame's (as for a controller's own V about an
    offset equilibrium): every box called flat has V_r <= level at 200 states of it and at its
    corners (V_r in NumPy, angle deviations wrapped); every box not called flat has a corner
    with V_r >= level (1 - 1e-9), so the test loses nothing but rounding."""
    system = make_system(name)
    size = system.state_dim
    rng = np.random.default_rng(1)
    basis, _ = np.linalg.qr(rng.standard_normal((size, size)))
    P_r = (basis * np.logspace(0, 1.5, size)) @ basis.T
    P_r = 0.5 * (P_r + P_r.T)
    offset = 0.05 * rng.standard_normal(size)
    frame = _frame(system, design_lqr(system).P, system.operating_state + offset)
    angles = tuple(system.angle_indices)
    region = _region(P_r, system.operating_state, angles)
    centre, radius = _boxes(size, seed=2)
    flat = _flat_rows(region, frame, centre, radius, _states(frame, centre, radius))
    assert 0.05 < float(flat.double().mean()) < 0.95
    inverse, operating = frame.inverse.numpy(), frame.operating.numpy()
    corners = np.array(np.meshgrid(*[[-1.0, 1.0]] * size, indexing="ij")).reshape(size, -1).T
    for row in range(BOXES):
        c, h = centre[row].numpy(), radius[row].numpy()
        w = np.concatenate([c + h * corners, c + h * rng.uniform(-1, 1, (200, size))])
        deviation = w @ inverse.T + operating - system.operating_state
        for index in angles:
            deviation[:, index] = (deviation[:, index] + np.pi) % (2 * np.pi) - np.pi
        level = np.einsum("bi,ij,bj->b", deviation, P_r, deviation)
        if flat[row]:
            assert level.max() <= LEVEL * (1.0 + 1e-12)
        else:
            assert level[: len(corners)].max() >= LEVEL * (1.0 - 1e-9)


class _Wild(nn.Module):
    """A learned part no proof can get through: a bang-bang torque of the full limit whose
    interval enclosure is the whole range on any box."""

    def __init__(self, limit: float) -> None:
        super().__init__()
        self.limit = limit

    def forward(self, x):
        return self.limit * torch.sin(1e3 * x[..., :1])


@pytest.mark.slow
def test_the_roa_hybrid_proves_in_its_flat_top_what_its_lqr_does_in_as_many_boxes():
    """A cart-pole ROA hybrid flat on its LQR's proved level, with a learned part that ruins
    any enclosure it enters: its proof of the LQR's V to 0.3 of the flat top evaluates as many
    boxes as the LQR's own proof (measured: 35 834 both; its boxes never evaluate H), and
    without the flat region (the relevance's own enclosure of its level only) at least twice
    as many (measured 140 406: the state's intervals wrap the boxes of w)."""
    system = make_system("cartpole")
    design = design_lqr(system)
    certificate = certify_lqr(system, design)
    wild = _Wild(system.action_limit)
    hybrid = roa_hybrid(system, design, wild, certificate=certificate, learn_width=False)
    hybrid = hybrid.double().eval()
    target = 0.3 * float(hybrid.relevance_module.rho_in)
    options = dict(rho_max=target, samples=2000, max_boxes=400_000, max_seconds=900.0)
    proved_lqr = certify_level(system, design.P, lqr_controller(design), **options)
    proved = certify_level(system, design.P, hybrid, **options)
    assert proved_lqr.proof.limited_by == proved.proof.limited_by == "target"
    assert proved.rho >= proved_lqr.rho * (1.0 - 1e-9)
    assert proved.proof.boxes <= 1.05 * proved_lqr.proof.boxes
    hybrid.flat_region = lambda saturated=True: None  # the relevance's own enclosure only
    without = certify_level(system, design.P, hybrid, **options)
    assert without.proof.boxes >= 2 * proved.proof.boxes


def test_a_controller_without_a_flat_region_is_left_as_it_is():
    system = make_system("pendulum")
    frame = _frame(system, design_lqr(system).P)
    centre, radius = _boxes(2, seed=3)
    lqr = lqr_controller(design_lqr(system))
    assert _with_flat_region(lqr, frame, centre, radius, _states(frame, centre, radius)) is lqr


def _inside_and_outside(system, design, rho_in: float, count: int = 400):
    """Observations of ``count`` states with V <= 0.999 rho_in and as many with V in
    [1.5, 3] rho_in (V the design's, about a)."""
    rng = np.random.default_rng(4)
    size = system.state_dim
    direction = rng.standard_normal((2 * count, size))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    levels = np.concatenate([rng.uniform(0, 0.999, count), rng.uniform(1.5, 3.0, count)])
    w = direction * np.sqrt(levels * rho_in)[:, None]
    states = system.operating_state + w @ np.linalg.inv(np.linalg.cholesky(design.P))
    obs = system.observe(torch.as_tensor(states, dtype=DTYPE))
    return obs[:count], obs[count:]


def test_each_wrapper_s_flat_controller_is_its_output_on_the_flat_top():
    """On states of the flat top a hybrid's region controller gives the controller's own
    action (to 1e-12), for the three ways leoc runs one: a sin-saturated HybridPolicy (PILCO's),
    held at a period of 3 (HeldPolicy), and an unsaturated blend clipped to an action box
    (SB3's PhysicalPolicy, a box half the actuator's, so the clip acts); outside it they
    differ (the learned part acts there)."""
    from leoc.policies import HeldPolicy
    from leoc.sb3.physical import PhysicalPolicy

    system = make_system("pendulum")
    design = design_lqr(system)
    certificate = certify_lqr(system, design)
    limit = system.action_limit

    def hybrid(saturation, action_limit):
        built = roa_hybrid(
            system,
            design,
            _Wild(limit),
            certificate=certificate,
            learn_width=False,
            saturation=saturation,
            action_limit=action_limit,
        )
        return built.double().eval()

    sin = hybrid("sin", limit)
    plain = hybrid("clip", None)
    box = np.array([0.5 * limit])
    controllers = {
        "sin": sin,
        "held": HeldPolicy(sin, 3),
        "physical": PhysicalPolicy(plain, -box, box, hybrid=plain),
    }
    inside, outside = _inside_and_outside(system, design, float(sin.relevance_module.rho_in))
    for name, controller in controllers.items():
        region = controller.flat_region()
        with torch.no_grad():
            same = controller(inside) - region.inner(inside)
            apart = controller(outside) - region.inner(outside)
        assert float(same.abs().max()) <= 1e-12, name
        assert float(apart.abs().max()) > 1e-3, name
    with torch.no_grad():
        clipped = controllers["physical"](inside)
    assert float(clipped.abs().max()) == pytest.approx(0.5 * limit)  # the clip is exercised
