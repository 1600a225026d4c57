"""Saving and loading a trained PILCO run (nrontsis/PILCO issue 54): the GP model and the
policy load back in a fresh process and predict as the trained objects did.

One tiny run of each kind (RBF baseline, hybrid) is trained once for the module. The
references are computed in this process from what the trainer returned: the GP's predictive
moments from a posterior recomputed independently from the saved training data and the
trainer's hyperparameters (checked against the trainer's own model), the horizon prediction
from the trainer's policy and model (checked against the cost the trainer logged). A fresh
Python process then loads each run with :func:`leoc.pilco.load_pilco_run` and must reproduce
them to :data:`RTOL`.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pytest
import torch

pytestmark = pytest.mark.usefixtures("single_thread")

DTYPE = torch.float64
KINDS = {"baseline": None, "hybrid": True}
SEED = 3
#: Agreement asked of a loaded run: |loaded - reference| <= RTOL * max |reference| per array.
RTOL = 1e-10
#: Test inputs of the GP: training inputs moved by this many units (a fixed random direction).
GP_INPUT_SHIFT = 0.1
GP_TEST_POINTS = 8
#: Pendulum angles (rad) and speeds (rad/s) of the observations the policies act on: near
#: upright (the hybrid's LQR region), sideways and hanging.
TEST_ANGLES = (0.0, 0.05, 1.2, -2.0, np.pi)
TEST_SPEEDS = (0.0, -0.3, 1.0, 2.5, -1.0)
#: The one smallest value floors the spread of a target in the GP's noise floor (leoc.pilco.gp).
MIN_TARGET_STD = 1e-3

FRESH_PROCESS = """
import sys
import numpy as np
import torch
from leoc.pilco import gp_predict, load_pilco_controller, load_pilco_run

torch.set_num_threads(1)
out, given = sys.argv[1], np.load(sys.argv[2])
found = {}
for kind, run_dir in zip(sys.argv[3::2], sys.argv[4::2]):
    run = load_pilco_run(run_dir)
    x, obs = torch.as_tensor(given[kind + ".x"]), torch.as_tensor(given[kind + ".obs"])
    with torch.no_grad():
        mean, var = gp_predict(run.model, x)
        prediction = run.predict()
        values = {
            "gp_mean": mean, "gp_var": var, "means": prediction.means,
            "covs": prediction.covs, "costs": prediction.costs,
            "policy": run.policy(obs), "controller": run.controller(obs),
            "loaded_controller": load_pilco_controller(run_dir)(obs),
        }
    found.update({kind + "." + key: value.numpy() for key, value in values.items()})
    found[kind + ".repeat"] = np.array(run.controller.action_repeat)
np.savez(out, **found)
"""


class Reference(NamedTuple):
    """A trained run and what it predicts, computed in the training process."""

    run_dir: Path
    result: object  # the trainer's TrainResult
    x: np.ndarray  # GP test inputs (B, D)
    obs: np.ndarray  # observations (B, O)
    gp_mean: np.ndarray
    gp_var: np.ndarray
    means: np.ndarray
    covs: np.ndarray
    costs: np.ndarray
    actions: np.ndarray


def _observations() -> np.ndarray:
    angles, speeds = np.array(TEST_ANGLES), np.array(TEST_SPEEDS)
    return np.stack([np.cos(angles), np.sin(angles), speeds], axis=1)


def _recomputed_gp(result, run_dir: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Test inputs and the GP's moments there, from a posterior recomputed from the data the
    last model was fitted on (the checkpoint's first ``data_size`` rows of iteration 0) and the
    trainer's hyperparameters, with the documented noise floor."""
    from leoc.pilco.config import PilcoConfig
    from leoc.pilco.gp import gp_predict, posterior

    config = PilcoConfig.from_dict(result.config)
    saved = torch.load(run_dir / "checkpoint.pt", weights_only=False)
    count = result.curve[0]["data_size"]
    inputs = torch.as_tensor(saved["inputs"][:count], dtype=DTYPE)
    targets = torch.as_tensor(saved["targets"][:count], dtype=DTYPE)
    floor_var = (config.gp.noise_floor * targets.std(0).clamp(min=MIN_TARGET_STD)) ** 2
    recomputed = posterior(result.model.hyper, inputs, targets, floor_var, None)
    rng = np.random.default_rng(0)
    rows = inputs.numpy()[rng.choice(count, GP_TEST_POINTS, replace=False)]
    x = torch.as_tensor(rows + GP_INPUT_SHIFT * rng.standard_normal(rows.shape), dtype=DTYPE)
    mean, var = gp_predict(recomputed, x)
    trainer_mean, trainer_var = gp_predict(result.model, x)
    _assert_close(trainer_mean.numpy(), mean.numpy(), "trainer's GP mean")
    _assert_close(trainer_var.numpy(), var.numpy(), "trainer's GP variance")
    return x.numpy(), mean.numpy(), var.numpy()


def _reference(kind: str, run_dir: Path, settings) -> Reference:
    from leoc.pilco.config import PilcoConfig
    from leoc.pilco.objective import predict_policy
    from leoc.pilco.train import train_pilco
    from leoc.systems import make_system

    result = train_pilco(
        "pendulum", KINDS[kind], SEED, run_dir, iterations=1, progress=False, **settings
    )
    x, gp_mean, gp_var = _recomputed_gp(result, run_dir)
    config = PilcoConfig.from_dict(result.config)
    obs = _observations()
    with torch.no_grad():
        prediction = predict_policy(
            result.policy.policy, result.model, make_system("pendulum"), config
        )
        actions = result.policy(torch.as_tensor(obs, dtype=DTYPE)).numpy()
    # the horizon prediction is the one the trainer's last policy optimisation ended on
    logged = result.curve[-1]["predicted_cost"]
    assert abs(prediction.total_cost.item() - logged) <= RTOL * abs(logged)
    return Reference(
        run_dir,
        result,
        x,
        obs,
        gp_mean,
        gp_var,
        prediction.means.numpy(),
        prediction.covs.numpy(),
        prediction.costs.numpy(),
        actions,
    )


@pytest.fixture(scope="module")
def references(tmp_path_factory, tiny_pilco_settings) -> dict[str, Reference]:
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # the module-scoped fixture runs before single_thread
    try:
        root = tmp_path_factory.mktemp("pilco_runs")
        return {kind: _reference(kind, root / kind, tiny_pilco_settings) for kind in KINDS}
    finally:
        torch.set_num_threads(threads)


@pytest.fixture(scope="module")
def loaded(references, tmp_path_factory) -> dict[str, np.ndarray]:
    """What a fresh Python process loads and predicts (one process for both runs)."""
    folder = tmp_path_factory.mktemp("fresh_process")
    given, out = folder / "given.npz", folder / "loaded.npz"
    arrays = {}
    for kind, ref in references.items():
        arrays.update({kind + ".x": ref.x, kind + ".obs": ref.obs})
    np.savez(given, **arrays)
    runs = [str(part) for kind, ref in references.items() for part in (kind, ref.run_dir)]
    subprocess.run(
        [sys.executable, "-c", FRESH_PROCESS, str(out), str(given), *runs],
        capture_output=True,
        text=True,
        check=True,
        timeout=300,
    )
    with np.load(out) as found:
        return dict(found)


def _assert_close(found: np.ndarray, expected: np.ndarray, name: str) -> None:
    """``found`` equals ``expected`` to RTOL relative to the largest entry of ``expected``."""
    scale = float(np.abs(expected).max())
    assert scale > 0.0, f"{name}: a reference of zeros tells nothing"
    np.testing.assert_allclose(found, expected, rtol=RTOL, atol=RTOL * scale, err_msg=name)


@pytest.mark.parametrize("kind", KINDS)
def test_loaded_gp_predicts_as_the_trained_one(references, loaded, kind) -> None:
    ref = references[kind]
    assert ref.gp_var.min() > 0.0 and np.abs(ref.gp_mean).max() > 0.0
    _assert_close(loaded[kind + ".gp_mean"], ref.gp_mean, "GP mean")
    _assert_close(loaded[kind + ".gp_var"], ref.gp_var, "GP variance")


@pytest.mark.parametrize("kind", KINDS)
def test_loaded_run_makes_the_trainers_horizon_prediction(
    references, loaded, kind, tiny_pilco_settings
) -> None:
    ref = references[kind]
    assert ref.means.shape == (tiny_pilco_settings["horizon"] + 1, 2) and ref.costs.shape == (
        tiny_pilco_settings["horizon"],
    )
    _assert_close(loaded[kind + ".means"], ref.means, "predicted means")
    _assert_close(loaded[kind + ".covs"], ref.covs, "predicted covariances")
    _assert_close(loaded[kind + ".costs"], ref.costs, "predicted costs")


@pytest.mark.parametrize("kind", KINDS)
def test_loaded_policy_acts_as_the_saved_controller(references, loaded, kind) -> None:
    ref = references[kind]
    assert np.ptp(ref.actions) > 0.0  # the observations tell policies apart
    for name in ("policy", "controller", "loaded_controller"):
        _assert_close(loaded[f"{kind}.{name}"], ref.actions, name)
    assert int(loaded[kind + ".repeat"]) == ref.result.policy.action_repeat == 2


def test_training_moved_the_hybrids_lambda(references) -> None:
    """The reference can tell a loaded Lambda from the one every hybrid of the config starts
    from (a loader that drops it fails the tests above)."""
    from leoc.pilco.config import PilcoConfig
    from leoc.pilco.policy import build_policy
    from leoc.systems import make_system

    result = references["hybrid"].result
    config = PilcoConfig.from_dict(result.config)
    initial = build_policy(make_system("pendulum"), config, torch.Generator().manual_seed(0))
    trained = result.policy.policy.relevance_module.lambda_.detach()
    assert (trained - initial.relevance_module.lambda_.detach()).abs().max() > 1e-6


@pytest.mark.parametrize("kind", KINDS)
def test_the_curve_records_why_the_optimisation_stopped(references, kind) -> None:
    """An iteration's diagnostics (docs/user_guide/pilco.md, "Why a run fails") against
    autograd on the trainer's own policy and model: the gradient's norm at the parameters kept,
    the GP's hyperparameters, the hybrid's Lambda, a start cost no lower than the one kept."""
    import json
    import math

    from leoc.pilco.config import PilcoConfig
    from leoc.pilco.objective import predict_policy
    from leoc.systems import make_system

    ref = references[kind]
    row = json.loads((ref.run_dir / "curve.json").read_text())["curve"][-1]
    policy, model = ref.result.policy.policy, ref.result.model
    config = PilcoConfig.from_dict(ref.result.config)
    params = [p for p in policy.parameters() if p.requires_grad]
    cost = predict_policy(policy, model, make_system("pendulum"), config).total_cost
    norm = math.sqrt(sum(float(g.square().sum()) for g in torch.autograd.grad(cost, params)))
    assert norm > 0.0
    assert row["gradient_norm_best"] == pytest.approx(norm, rel=1e-6)
    assert row["predicted_cost"] == pytest.approx(float(cost), rel=1e-9)
    assert row["predicted_cost_start"] >= row["predicted_cost"]
    assert row["failed_evaluations"] == 0
    # the cost the iteration's training rollout realised: its observations at decisions 1..H
    # (rows of the data after iteration 0's), the saturating cost written out here
    saved = torch.load(ref.run_dir / "checkpoint.pt", weights_only=False)
    first = ref.result.curve[0]["data_size"]
    obs = np.asarray(saved["inputs"])[first + 1 : first + 1 + config.horizon, :3]
    system = make_system("pendulum")
    factor = np.asarray(system.cost_factor()) / config.cost_width
    scaled = (obs - np.asarray(system.operating_obs)) @ factor.T
    expected = np.sum(1.0 - np.exp(-0.5 * np.square(scaled).sum(axis=1)))
    assert len(obs) == config.horizon
    assert row["realised_cost"] == pytest.approx(expected, rel=1e-9)
    np.testing.assert_allclose(row["gp_log_noise"], model.log_noise.numpy(), rtol=1e-12)
    np.testing.assert_allclose(row["gp_log_lengthscales"], model.log_lengthscales.numpy())
    if kind == "hybrid":
        lam = policy.relevance_module.lambda_.detach().numpy()
        np.testing.assert_allclose(row["relevance_lambda"], lam, rtol=1e-12)
    else:
        assert "relevance_lambda" not in row


def test_loaded_run_carries_its_config_and_plant(references, tiny_pilco_settings) -> None:
    from leoc.pilco import PilcoRun, load_pilco_run
    from leoc.pilco.config import PilcoConfig
    from leoc.pilco.gp import GPPosterior

    ref = references["hybrid"]
    run = load_pilco_run(ref.run_dir)
    assert isinstance(run, PilcoRun) and isinstance(run.model, GPPosterior)
    assert run.config == PilcoConfig.from_dict(ref.result.config)
    assert (
        run.system.name == "pendulum"
        and run.system.episode_steps == tiny_pilco_settings["episode_steps"]
    )
    assert run.run_dir == ref.run_dir and not run.policy.training


def test_a_garbled_or_missing_file_is_named_in_one_line(tmp_path) -> None:
    from leoc.pilco import load_pilco_controller, load_pilco_run

    (tmp_path / "controller.pt").write_bytes(b"not a torch file")
    for load in (load_pilco_run, load_pilco_controller):
        with pytest.raises(ValueError, match="could not be read as a PILCO controller") as error:
            load(tmp_path)
        assert "\n" not in str(error.value) and str(tmp_path / "controller.pt") in str(error.value)
    with pytest.raises(FileNotFoundError):
        load_pilco_run(tmp_path / "absent")


def test_a_run_saved_before_its_first_iteration_has_no_model_to_load(references, tmp_path) -> None:
    from leoc.pilco import load_pilco_controller, load_pilco_run
    from leoc.pilco.checkpoint import save_controller
    from leoc.pilco.config import PilcoConfig

    ref = references["baseline"]
    config = PilcoConfig.from_dict(ref.result.config)
    save_controller(tmp_path, config, ref.result.policy.policy.state_dict(), None)
    with pytest.raises(ValueError, match="holds no GP model yet") as error:
        load_pilco_run(tmp_path)
    assert "\n" not in str(error.value)
    obs = torch.as_tensor(ref.obs, dtype=DTYPE)
    with torch.no_grad():  # the controller alone still loads
        _assert_close(load_pilco_controller(tmp_path)(obs).numpy(), ref.actions, "controller")


@pytest.mark.parametrize("kind", list(KINDS))
def test_horizon_check_replays_the_runs_last_evaluation(references, kind) -> None:
    """:func:`leoc.pilco.diagnose.horizon_check` replays the saved controller from the
    evaluation starts: its held episodes are those the trainer's last evaluation recorded, and
    its horizon is the run's ``horizon * action_repeat`` simulator steps. Its predicted cost
    over the horizon is the one the trainer logged; over the episode's decisions (more than
    the horizon's, each costing more than 0) it is larger."""
    from leoc.pilco import load_pilco_run
    from leoc.pilco.diagnose import horizon_check

    ref = references[kind]
    check = horizon_check(ref.run_dir)
    last = ref.result.curve[-1]
    assert check.held == [step is not None for step in last["hold_steps"]]
    config = load_pilco_run(ref.run_dir).config
    assert check.horizon_steps == config.horizon * config.action_repeat
    assert len(check.up) == config.eval_episodes
    assert check.predicted == pytest.approx(last["predicted_cost"], rel=1e-9)
    assert check.episode_decisions == config.episode_steps // config.action_repeat
    assert check.episode_decisions > config.horizon
    assert check.predicted_episode > check.predicted
