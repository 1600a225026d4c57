"""The LQR reference a controller's proved region is compared with
(:func:`leoc.evaluation.proved_regions.lqr_reference`): the LQR proved with the same candidate
V as the controller, the larger kept.

References independent of the proof: the discrete Lyapunov equation solved here by scipy on a
central-difference Jacobian of the plant's step; a Monte Carlo check that V decreases on the
kept set; and the LQR compared with itself, whose ratios must be 1 (the Riccati certificate
alone gave the mountain car's LQR 1.46x its own volume).
"""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest
import scipy.linalg
import torch

from leoc.cli import main
from leoc.control import certify_lqr, design_lqr, lqr_closed_loop
from leoc.control.trained import log_volume
from leoc.evaluation.basins import default_basin_box
from leoc.evaluation.proved_regions import (
    REFERENCE_KEY,
    lqr_reference,
    proved_region,
    refresh_lqr_reference,
)
from leoc.systems import make_system

pytestmark = pytest.mark.usefixtures("single_thread")

RESULTS = Path(__file__).resolve().parents[1] / "results"
STEP = 1e-6
"""Central-difference step of the plant's Jacobian (relative error about 1e-10)."""
MONTE_CARLO = 20_000
LQR_FIELDS = ("lqr_box_share", "box_share_ratio", "volume_ratio", "lqr_rho")


def _certified(name: str):
    system = make_system(name)
    design = design_lqr(system)
    return system, design, certify_lqr(system, design)


def _held_loop(system, design, states: np.ndarray) -> np.ndarray:
    """One control period of the plant under ``clip(W o + b)``: the system's step and
    observation, with the LQR written out here."""
    x = torch.as_tensor(states, dtype=torch.float64)
    obs = system.observe(x).numpy()
    action = np.clip(
        obs @ np.asarray(design.W).T + np.asarray(design.b),
        -system.action_limit,
        system.action_limit,
    )
    following = system.step_held(x, torch.as_tensor(action), int(design.action_repeat))
    return following.numpy()


def _jacobian(system, design) -> np.ndarray:
    a = np.asarray(system.operating_state, dtype=float)
    columns = []
    for index in range(a.size):
        shift = np.zeros_like(a)
        shift[index] = STEP
        ahead, behind = _held_loop(system, design, np.stack([a + shift, a - shift]))
        columns.append((ahead - behind) / (2 * STEP))
    return np.stack(columns, axis=1)


def test_the_mountain_car_lqr_is_referenced_with_its_own_linearisations_v():
    system, design, riccati = _certified("mountaincar")
    reference = lqr_reference(system, design, riccati)
    assert set(reference.candidates) == {"lqr", "own"}
    # the kept V proves the larger volume, here the own one (the Riccati V stops at the
    # region's edge far sooner)
    assert reference.lyapunov == "own"
    assert log_volume(reference.certificate) > log_volume(riccati) + 0.1
    # its P solves J^T P J - P = -diag(1 / region^2) for the plant's own Jacobian
    jacobian = _jacobian(system, design)
    weight = np.diag(1.0 / np.asarray(system.operating_region, dtype=float) ** 2)
    expected = scipy.linalg.solve_discrete_lyapunov(jacobian.T, weight)
    np.testing.assert_allclose(reference.certificate.P, expected, rtol=1e-5)
    # V decreases along the loop on seeded samples of the kept set (away from a)
    rng = np.random.default_rng(3)
    direction = rng.normal(size=(MONTE_CARLO, 2))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    radius = np.sqrt(rng.uniform(1e-4, 1.0, size=(MONTE_CARLO, 1)))
    lower = np.linalg.cholesky(reference.certificate.P)
    a = np.asarray(system.operating_state, dtype=float)
    deviation = np.linalg.solve(
        lower.T, (math.sqrt(reference.certificate.rho) * radius * direction).T
    ).T
    states = a + deviation
    following = _held_loop(system, design, states) - a
    P = reference.certificate.P
    before = np.einsum("bi,ij,bj->b", deviation, P, deviation)
    after = np.einsum("bi,ij,bj->b", following, P, following)
    assert np.all(after < before)


def test_the_lqr_compared_with_itself_proves_its_own_region():
    system, design, riccati = _certified("mountaincar")
    box = default_basin_box(system)
    entry = proved_region(system, lqr_closed_loop(design), design, riccati, box, samples=4000)
    assert entry[REFERENCE_KEY] == entry["lyapunov"] == "own"
    assert math.isclose(entry["volume_ratio"], 1.0, rel_tol=1e-9)
    assert math.isclose(entry["box_share_ratio"], 1.0, rel_tol=1e-12)
    assert math.isclose(entry["lqr_rho"], entry["rho"], rel_tol=1e-9)
    # refreshing an entry written with the Riccati reference alone gives the same comparison
    old = {
        key: value for key, value in entry.items() if key not in (REFERENCE_KEY, "lqr_candidates")
    }
    old.update(lqr_rho=riccati.rho, volume_ratio=1.46, budget_seconds=None, budget_boxes=None)
    refreshed = refresh_lqr_reference(system, old, design, riccati, box, samples=4000)
    for key in LQR_FIELDS:
        assert refreshed[key] == pytest.approx(entry[key], rel=1e-9), key
    assert refreshed[REFERENCE_KEY] == "own"
    assert refresh_lqr_reference(system, entry, design, riccati, box) is entry  # already new


def test_the_pendulum_lqr_keeps_its_riccati_certificate():
    # there the Riccati V proves the larger volume: the reference is its certificate as is
    system, design, riccati = _certified("pendulum")
    reference = lqr_reference(system, design, riccati)
    volumes = {name: entry["log_volume"] for name, entry in reference.candidates.items()}
    assert max(volumes, key=volumes.get) == reference.lyapunov == "lqr"
    assert reference.certificate.rho == riccati.rho
    only = lqr_reference(system, design, riccati, lyapunov="lqr")
    assert set(only.candidates) == {"lqr"}
    with pytest.raises(ValueError, match="lyapunov: expected one of"):
        lqr_reference(system, design, riccati, lyapunov="riccati")


def test_plot_refreshes_an_old_runs_reference_once(tmp_path, capsys):
    """``leoc plot --refresh-lqr-reference`` on a published mountain-car hybrid whose entry is
    put back as it was written (the Riccati reference alone): the hybrid's own V is its LQR's
    (its linearisation at a is W), so its volume is then its LQR's."""
    study = RESULTS / "certified-mountaincar-ddpg"
    folder = tmp_path / "study"
    run = Path("runs/mountaincar/ddpg_hybrid/seed0")
    (folder / run).mkdir(parents=True)
    shutil.copy(study / "meta.json", folder / "meta.json")
    record = json.loads((study / run / "evaluation.json").read_text())
    entry = record["proved_region"]
    _, _, riccati = _certified("mountaincar")
    for key in (REFERENCE_KEY, "lqr_candidates"):
        entry.pop(key, None)
    entry.update(lqr_rho=riccati.rho, volume_ratio=1.4649413254091839)
    (folder / run / "evaluation.json").write_text(json.dumps(record, indent=1))
    assert main(["plot", str(folder), "--refresh-lqr-reference"]) == 0
    assert "1 run(s) given the LQR's best-V reference" in capsys.readouterr().out
    rewritten = json.loads((folder / run / "evaluation.json").read_text())
    new = rewritten["proved_region"]
    assert new[REFERENCE_KEY] == new["lyapunov"] == "own"
    assert math.isclose(new["volume_ratio"], 1.0, rel_tol=1e-6)
    assert {k: v for k, v in rewritten.items() if k != "proved_region"} == {
        k: v for k, v in record.items() if k != "proved_region"
    }
    assert main(["plot", str(folder), "--refresh-lqr-reference"]) == 0
    assert "0 run(s)" in capsys.readouterr().out  # never rewritten twice
    assert "| own |" in (folder / "report.md").read_text()
