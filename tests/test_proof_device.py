"""Proofs on a chosen device (``prove_level(device=...)``, ``leoc roa --prove --device``).

On the CPU: the device is checked in one line, and the CLI refuses ``--device`` without
``--prove``. Where torch sees a GPU (never in CI), the same proofs run there and must agree with
the CPU's: the LQR's level on the pendulum and the cart-pole, and a hybrid whose learned part is
a 400x300 actor; a destabilised hybrid's GPU level stays below the first Monte Carlo violation
(sampled on the CPU), and the caller's controller stays on the CPU.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from leoc.cli import main
from leoc.control import certify_controller, design_lqr, lqr_closed_loop
from leoc.control.proof import check_device, prove_level
from leoc.control.roa import _decrease, _uniform_ellipsoid, certify_level
from leoc.policies import HybridDesign, HybridSpec, RBFNetwork, build_hybrid
from leoc.policies.mlp import MLPActor
from leoc.systems import make_system

pytestmark = pytest.mark.usefixtures("single_thread")

GPU = pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device")
AGREEMENT = 1e-3
"""Relative difference allowed between a CPU and a GPU proved level: the box search is the
same, but a box whose bound is within rounding of 0 may pass on one device and fail on the
other (the GPU's sin and cos get a wider libm allowance, and its sums run in another order)."""


def test_a_device_is_checked_in_one_line():
    assert check_device("cpu") == torch.device("cpu")
    assert check_device(torch.device("cpu")).type == "cpu"
    with pytest.raises(ValueError, match=r"device: expected one of \('cpu', 'cuda'\)"):
        check_device("tpu")
    with pytest.raises(ValueError, match="device: expected one of"):
        check_device("meta")
    with pytest.raises(ValueError, match="device: expected an available GPU, found 'cuda:64'"):
        check_device("cuda:64")


@pytest.mark.skipif(torch.cuda.is_available(), reason="a CUDA device is available")
def test_cuda_without_a_gpu_is_refused_before_any_work():
    system = make_system("pendulum")
    design = design_lqr(system)
    with pytest.raises(ValueError, match="device: expected an available GPU, found 'cuda'"):
        prove_level(system, design.P, lqr_closed_loop(design), 1, 1.0, device="cuda")
    with pytest.raises(ValueError, match="device: expected an available GPU"):
        certify_controller(system, lqr_closed_loop(design), design, device="cuda")


def test_roa_refuses_a_device_without_prove_or_a_bad_one(capsys):
    assert main(["roa", "pendulum", "--device", "cuda"]) == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert "--device: expected only with --prove, found --device cuda" in line
    assert main(["roa", "pendulum", "--controller", "x", "--prove", "--device", "tpu"]) == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert "--device: expected one of" in line and "'tpu'" in line


def _lqr_level(name: str, device: str) -> float:
    system = make_system(name)
    design = design_lqr(system)
    controller = lqr_closed_loop(design)
    certificate = certify_level(system, design.P, controller, samples=20_000, device=device)
    return certificate.rho


@GPU
@pytest.mark.parametrize("name", ["pendulum", "cartpole"])
def test_the_lqr_proves_the_same_level_on_a_gpu(name):
    cpu, gpu = _lqr_level(name, "cpu"), _lqr_level(name, "cuda")
    assert cpu > 0.0 and math.isclose(gpu, cpu, rel_tol=AGREEMENT)


def _mlp_hybrid(system, design):
    """The paper's hybrid around a seeded 400x300 actor (leoc's DDPG/TD3 size)."""
    generator = torch.Generator().manual_seed(3)
    learned = MLPActor(3, 1, (400, 300), action_limit=2.0, generator=generator)
    spec = HybridSpec(r_min=None, relevance_power=1.0, lambda_init=1.0)
    resolved = HybridDesign(design.W, design.b, system.operating_obs, {})
    hybrid = build_hybrid(spec, resolved, learned, action_limit=2.0, saturation="clip")
    return hybrid.double().eval()


@GPU
def test_a_400x300_hybrid_proves_the_same_level_on_a_gpu_and_stays_on_the_cpu():
    system = make_system("pendulum")
    design = design_lqr(system)
    hybrid = _mlp_hybrid(system, design)
    options = {"lyapunov": "lqr", "samples": 20_000, "max_seconds": 120.0}
    cpu = certify_controller(system, hybrid, design, **options)
    gpu = certify_controller(system, hybrid, design, **options, device="cuda")
    assert cpu.rho > 0.0 and math.isclose(gpu.rho, cpu.rho, rel_tol=AGREEMENT)
    assert {parameter.device.type for parameter in hybrid.parameters()} == {"cpu"}


@GPU
def test_a_destabilised_hybrid_proved_on_a_gpu_stays_below_the_first_violation():
    system = make_system("pendulum")
    design = design_lqr(system)
    learned = RBFNetwork(3, 1, 10, weight_std=4.0, generator=torch.Generator().manual_seed(8))
    spec = HybridSpec(r_min=None, relevance_power=1.0, lambda_init=0.3)
    resolved = HybridDesign(design.W, design.b, system.operating_obs, {})
    hybrid = build_hybrid(spec, resolved, learned, action_limit=2.0, saturation="clip")
    hybrid = hybrid.double().eval()
    proved = certify_controller(system, hybrid, design, lyapunov="lqr", device="cuda")
    z = _uniform_ellipsoid(design.P, 2.0 * proved.rho, 200_000, np.random.default_rng(0))
    states = torch.as_tensor(z) + torch.as_tensor(system.operating_state)
    with torch.no_grad():
        value, violates = _decrease(
            system, torch.as_tensor(design.P), hybrid, 1, states, system.operating_state
        )
    assert 0.0 < proved.rho < float(value[violates].min())
