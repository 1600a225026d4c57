"""leoc.load and leoc export: values against independent references.

- ``leoc.load(RUN).act`` equals :func:`load_trained_controller` (the controller ``leoc
  simulate`` runs) on observations of the operating and swing-up regions, for every learner and
  relevance; ``leoc.load(SYSTEM).act`` equals ``clip(W o + b)`` computed in numpy from the
  design.
- The export check passes at 1e-6 for ONNX and TorchScript, and fails (writing nothing) when
  the exported model is wrong.
- The done-when: a fresh Python process in which torch and leoc cannot be imported (an import
  blocker on ``sys.meta_path``; the test also checks that neither got into ``sys.modules``)
  loads the ONNX model with onnxruntime and runs the paper's impulse test in closed loop on the
  pendulum, stepped by a numpy transcription of its equations of motion (semi-implicit Euler,
  the speed clipped, the action held for the exported control period), and its response equals
  ``leoc simulate RUN --json``'s.
- Bad input: one line, exit status 2.

The runs are tiny (``leoc train pendulum ... --profile smoke``): what is tested does not depend
on training.
"""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
import torch

import leoc
from leoc.cli import main
from leoc.deploy import export as export_module
from leoc.deploy import export_controller, load
from leoc.experiments.controllers import load_trained_controller

#: Slow suite: the module's fixture trains a run of every learner and kind.
pytestmark = pytest.mark.slow

#: Smoke runs of the pendulum: every learner, every relevance design, the floor r_min.
RUNS = {
    "pilco_hybrid": ["--algo", "pilco", "--hybrid"],
    "ddpg_baseline": ["--algo", "ddpg"],
    "ddpg_hybrid_floor": ["--algo", "ddpg", "--hybrid", "--r-min", "0.5"],
    "td3_hybrid_roa": ["--algo", "td3", "--hybrid", "--relevance", "roa"],
    "sac_hybrid_lyapunov": ["--algo", "sac", "--hybrid", "--relevance", "lyapunov"],
}
#: The rest of the learner x kind product on the pendulum (slow suite: SAC's smoke baseline
#: alone takes about a minute).
SLOW_RUNS = {
    "pilco_baseline": ["--algo", "pilco"],
    "ddpg_hybrid": ["--algo", "ddpg", "--hybrid"],
    "td3_baseline": ["--algo", "td3"],
    "sac_baseline": ["--algo", "sac"],
}
ALL_RUNS = [*RUNS, *(pytest.param(name, marks=pytest.mark.slow) for name in SLOW_RUNS)]
#: leoc.load and load_trained_controller run the same float64 module.
SAME_ACTION_TOL = 1e-12
#: The exported closed loop against leoc simulate's (degrees; float64 both, same operations
#: up to the order of floating-point sums).
SAME_RESPONSE_TOL = 1e-9
#: leoc simulate's impulse (leoc.evaluation.rollout.IMPULSE_MAGNITUDE), and the peak it must
#: at least reach (degrees) for the comparison to say something.
IMPULSE, MOVED = -1.0, 0.1
#: A swing-up episode (state theta, theta_dot): far from the operating point, r < 1.
SWING_START, SWING_STEPS = [2.5, 0.5], 100


@pytest.fixture(scope="session")
def runs(tmp_path_factory):
    """name -> run folder, each trained once per session on first use."""
    folder = tmp_path_factory.mktemp("deploy-runs")
    trained: dict[str, Path] = {}

    def get(name: str) -> Path:
        if name not in trained:
            out = folder / name
            arguments = {**RUNS, **SLOW_RUNS}[name]
            status = main(
                ["train", "pendulum", *arguments, "--profile", "smoke"]
                + ["--out", str(out), "--quiet"]
            )
            assert status == 0
            trained[name] = out
        return trained[name]

    return get


def _observations(system, count: int = 64) -> np.ndarray:
    """Observations of swing-up starts and of the operating region (not the export check's)."""
    rng = np.random.default_rng(1)
    swing = np.stack([system.sample_start(rng) for _ in range(count // 2)])
    near = system.sample_operating_region(rng, count - count // 2)
    states = torch.as_tensor(np.concatenate([swing, near]), dtype=torch.float64)
    return system.observe(states).numpy()


@pytest.mark.parametrize("name", ALL_RUNS)
def test_load_acts_as_the_trained_controller(runs, name):
    run = runs(name)
    controller = leoc.load(run)
    obs = _observations(controller.system)
    with torch.no_grad():
        expected = load_trained_controller(run)(torch.as_tensor(obs)).numpy()
    np.testing.assert_allclose(controller.act(obs), expected, rtol=0, atol=SAME_ACTION_TOL)
    # one observation, and torch in -> torch out
    np.testing.assert_allclose(controller.act(obs[0]), expected[0], rtol=0, atol=SAME_ACTION_TOL)
    as_tensor = controller.act(torch.as_tensor(obs))
    assert isinstance(as_tensor, torch.Tensor)
    np.testing.assert_allclose(as_tensor.numpy(), expected, rtol=0, atol=SAME_ACTION_TOL)


@pytest.mark.parametrize("name", ALL_RUNS)
def test_load_reports_period_design_spec_and_certificate(runs, name):
    run = runs(name)
    controller = leoc.load(run)
    config = json.loads((run / "config.json").read_text())
    steps = config["action_repeat"] if name.startswith("pilco") else 1
    assert controller.period_steps == steps
    assert controller.period == pytest.approx(steps * 0.05, abs=1e-15)
    assert controller.system.name == "pendulum"
    assert controller.design.action_repeat == steps
    hybrid = next(
        (m for m in controller.module.modules() if isinstance(m, leoc.policies.HybridPolicy)),
        None,
    )
    assert (hybrid is None) == (controller.hybrid_spec is None) == ("baseline" in name)
    if hybrid is not None:
        # the linear part of the hybrid is the design the controller reports
        np.testing.assert_allclose(hybrid.linear.W.numpy(), controller.design.W, rtol=1e-9)
        assert controller.hybrid_spec.to_dict() == config["hybrid"]
    # every hybrid's relevance rests on the LQR's certificate: the ROA and Lyapunov ones, and
    # the paper's, floored (r_min 0.5) by default since issue 40
    certified = "baseline" not in name
    assert (controller.certificate is not None) == certified
    if certified:
        _check_certificate(controller, hybrid, config, steps, name)


def _check_certificate(controller, hybrid, config, steps: int, name: str) -> None:
    """The certificate is leoc.control.certify_lqr's for the LQR designed here at the run's
    period, of the loop it runs in (PILCO: u_max sin(G / u_max), written out here; else G
    clipped by the actuator); a paper hybrid (floored) has r >= 0.5 in the proved set."""
    from leoc.control import certify_lqr, design_lqr

    system = controller.system
    design = design_lqr(system, action_repeat=steps)
    np.testing.assert_allclose(controller.design.W, design.W, rtol=1e-12)
    if name.startswith("pilco"):
        gain = torch.as_tensor(np.asarray(design.W), dtype=torch.float64)
        bias = torch.as_tensor(np.asarray(design.b), dtype=torch.float64)
        limit = float(system.action_limit)
        expected = certify_lqr(
            system, design, lambda obs: limit * torch.sin((obs @ gain.T + bias) / limit)
        )
    else:
        expected = certify_lqr(system, design)
    certificate = controller.certificate
    assert expected.certified and certificate.rho > 0
    assert certificate.rho == expected.rho and certificate.action_repeat == steps
    np.testing.assert_array_equal(certificate.P, expected.P)
    if config["hybrid"]["relevance"] != "paper":
        return
    assert config["hybrid"]["r_min"] == 0.5
    # states in {z^T P z <= rho}: on its boundary (where r is smallest) and inside
    rng = np.random.default_rng(2)
    P, rho = np.asarray(expected.P), expected.rho
    u = rng.standard_normal((4000, P.shape[0]))
    u /= np.linalg.norm(u, axis=-1, keepdims=True)
    u[2000:] *= rng.uniform(0.0, 1.0, (2000, 1))
    z = np.sqrt(rho) * np.linalg.solve(np.linalg.cholesky(P).T, u.T).T
    assert np.all(np.einsum("ni,ij,nj->n", z, P, z) <= rho * (1 + 1e-12))
    states = torch.as_tensor(np.asarray(system.operating_state) + z, dtype=torch.float64)
    with torch.no_grad():
        r = hybrid.relevance(system.observe(states)).numpy()[:, 0]
    assert r.min() >= 0.5 and r.max() <= 1.0


def test_lqr_alone_is_the_saturated_design_in_numpy():
    controller = leoc.load("pendulum", action_repeat=2)
    design = controller.design
    obs = _observations(controller.system, 200)
    limit = controller.system.params.max_torque
    expected = np.clip(obs @ np.asarray(design.W).T + np.asarray(design.b), -limit, limit)
    assert np.any(np.abs(expected) == limit) and np.any(np.abs(expected) < limit)
    np.testing.assert_allclose(controller.act(obs), expected, rtol=0, atol=1e-12)
    assert controller.period_steps == 2 and design.action_repeat == 2
    assert controller.hybrid_spec is None and controller.certificate is None


@pytest.mark.parametrize("fmt", ["onnx", "torchscript"])
@pytest.mark.parametrize("name", [*RUNS, "lqr"])
def test_export_check_passes_at_1e_6(runs, tmp_path, name, fmt):
    controller = leoc.load("pendulum" if name == "lqr" else runs(name))
    result = export_controller(controller, tmp_path / f"model.{fmt}", fmt)
    assert result.check.passed and result.check.count == 100_000
    assert result.check.max_error <= 1e-6
    metadata = json.loads(result.metadata.read_text())
    assert metadata["control_period"]["steps"] == controller.period_steps
    assert metadata["action"][0]["high"] == 2.0 and metadata["action"][0]["low"] == -2.0
    assert [entry["name"] for entry in metadata["observation"]] == [
        "cos(theta)",
        "sin(theta)",
        "theta_dot",
    ]
    assert (metadata["certificate"] is not None) == (controller.certificate is not None)
    if controller.certificate is not None:
        assert metadata["certificate"]["rho"] == controller.certificate.rho


@pytest.mark.parametrize("variant", ["leoc", "authors"])
@pytest.mark.parametrize("system", ["pendulum", "cartpole", "mountaincar", "acrobot"])
def test_lqr_export_of_every_system_passes_its_check(tmp_path, system, variant):
    """Every observation layout (angles through cos and sin, plain states, two angles) and the
    authors' sin-squashed LQR."""
    if system == "acrobot" and variant == "authors":
        pytest.skip("the authors' variant has no LQR of the acrobot")
    controller = leoc.load(system, variant=variant)
    assert controller.saturation == ("sin" if variant == "authors" else "clip")
    result = export_controller(controller, tmp_path / "model.onnx", "onnx", count=20_000)
    assert result.check.passed and result.check.max_error <= 1e-6


def test_export_of_a_cartpole_roa_hybrid_passes_its_check(tmp_path):
    """The ROA relevance on the cart-pole's layout (a plain position, an angle through cos and
    sin), whose certificate takes minutes to prove."""
    out = tmp_path / "run"
    train = ["train", "cartpole", "--algo", "ddpg", "--hybrid", "--relevance", "roa"]
    assert main([*train, "--profile", "smoke", "--out", str(out), "--quiet"]) == 0
    controller = leoc.load(out)
    for fmt in ("onnx", "torchscript"):
        result = export_controller(controller, tmp_path / f"model.{fmt}", fmt)
        assert result.check.passed and result.check.max_error <= 1e-6
    assert json.loads(result.metadata.read_text())["certificate"]["flat_top_rho"] > 0


def test_a_wrong_export_fails_its_check_and_writes_nothing(runs, tmp_path, monkeypatch):
    """The check compares the exported bytes with torch: a model exported without the
    relevance (r = 0: the learned part alone) is caught, and nothing is written."""
    controller = leoc.load(runs("td3_hybrid_roa"))
    hybrid = next(
        m for m in controller.module.modules() if isinstance(m, leoc.policies.HybridPolicy)
    )
    original = export_module.model_bytes

    def without_relevance(deployed, fmt):
        hybrid.relevance = lambda x: torch.zeros_like(x[..., :1])
        try:
            return original(deployed, fmt)
        finally:
            del hybrid.relevance

    monkeypatch.setattr(export_module, "model_bytes", without_relevance)
    with pytest.raises(ValueError, match="FAILED; nothing written"):
        export_controller(controller, tmp_path / "model.onnx", "onnx", count=1000)
    assert not any(tmp_path.iterdir())


#: The child process: onnxruntime and numpy only (torch and leoc blocked), the pendulum's
#: equations of motion in numpy (leoc.systems.pendulum: semi-implicit Euler, the torque and the
#: speed clipped), the impulse test (-1 added to the action of the first simulator step) with the
#: action held for the exported control period; prints the wrapped angle in degrees per step.
FRESH_PROCESS = textwrap.dedent(
    """
    import importlib.abc, json, math, sys

    class Blocked(importlib.abc.MetaPathFinder):
        def find_spec(self, name, path=None, target=None):
            if name.split(".")[0] in ("torch", "leoc"):
                raise ImportError(f"{name} is blocked in this process")
            return None

    sys.meta_path.insert(0, Blocked())
    import numpy as np
    import onnxruntime

    model, metadata_file, params, steps, start, impulse = sys.argv[1:7]
    metadata = json.load(open(metadata_file))
    p = json.loads(params)
    session = onnxruntime.InferenceSession(model, providers=["CPUExecutionProvider"])
    hold = metadata["control_period"]["steps"]
    limit = metadata["action"][0]["high"]
    theta, theta_dot = json.loads(start)
    record = [math.degrees((theta + math.pi) % (2.0 * math.pi) - math.pi)]
    for index in range(int(steps)):
        if index % hold == 0:
            obs = np.array([[math.cos(theta), math.sin(theta), theta_dot]])
            action = session.run(["action"], {"observation": obs})[0][0, 0]
        torque = min(max(action + (float(impulse) if index == 0 else 0.0), -limit), limit)
        theta_ddot = 3.0 * p["gravity"] / (2.0 * p["length"]) * math.sin(theta) + 3.0 / (
            p["mass"] * p["length"] ** 2
        ) * torque
        theta_dot = min(max(theta_dot + theta_ddot * p["dt"], -p["max_speed"]), p["max_speed"])
        theta = theta + theta_dot * p["dt"]
        record.append(math.degrees((theta + math.pi) % (2.0 * math.pi) - math.pi))
    assert not {"torch", "leoc"} & set(sys.modules), sorted(sys.modules)
    print(json.dumps(record))
    """
)


def _fresh_process(folder: Path, system, steps: int, start: list, impulse: float) -> list:
    """The closed loop of ``folder/m.onnx`` run by :data:`FRESH_PROCESS`: the main coordinate
    (degrees) at each of ``steps + 1`` samples."""
    child = subprocess.run(
        [
            sys.executable,
            "-I",
            "-c",
            FRESH_PROCESS,
            str(folder / "m.onnx"),
            str(folder / "m.onnx.json"),
            json.dumps(dataclasses.asdict(system.params)),
            str(steps),
            json.dumps(start),
            str(impulse),
        ],
        capture_output=True,
        text=True,
        check=False,
        cwd=folder,
    )
    assert child.returncode == 0, child.stderr
    return json.loads(child.stdout)


@pytest.mark.parametrize("name", [*RUNS, "lqr"])
def test_onnx_in_a_fresh_process_gives_leoc_simulates_responses(runs, tmp_path, capsys, name):
    """The impulse response of ``leoc simulate``; and, since an impulse that stays where
    r = 1 tests the LQR alone, a swing-up episode, where the learned part and the relevance
    decide (leoc's rollout from the same start)."""
    from leoc.systems.rollout import rollout

    target = "pendulum" if name == "lqr" else str(runs(name))
    out = str(tmp_path / "m.onnx")
    assert main(["export", target, "--out", out, "--check-count", "1000"]) == 0
    capsys.readouterr()
    assert main(["simulate", target, "--json"]) == 0
    expected = json.loads(capsys.readouterr().out)["deviation"]
    system = leoc.load(target).system
    response = _fresh_process(tmp_path, system, len(expected) - 1, [0.0, 0.0], IMPULSE)
    # a response that does not move would compare equal to a controller that does nothing
    assert max(abs(value) for value in expected) > MOVED
    np.testing.assert_allclose(response, expected, rtol=0, atol=SAME_RESPONSE_TOL)
    controller = load_trained_controller(target) if name != "lqr" else leoc.load(target).module
    swing = rollout(system, controller, SWING_START, SWING_STEPS)
    expected = system.main_coordinate(swing.states)
    response = _fresh_process(tmp_path, system, SWING_STEPS, SWING_START, 0.0)
    np.testing.assert_allclose(response[: len(expected)], expected, rtol=0, atol=1e-6)


def test_import_leoc_does_not_import_torch():
    code = "import sys, leoc; leoc.load; assert 'torch' not in sys.modules, 'torch imported'"
    subprocess.run([sys.executable, "-c", code], check=True)


def _one_line_error(capsys, argv: list[str], *fragments: str) -> None:
    try:
        status = main(argv)
    except SystemExit as exit:  # argparse's own refusals
        status = exit.code
    assert status == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    for fragment in fragments:
        assert fragment in err, err


def test_bad_input_is_refused_in_one_line(runs, tmp_path, capsys):
    run = str(runs("ddpg_baseline"))
    out = str(tmp_path / "m.onnx")
    assert main(["export", run, "--out", out, "--check-count", "100"]) == 0
    before = (tmp_path / "m.onnx").read_bytes()
    capsys.readouterr()
    _one_line_error(capsys, ["export", run, "--out", out], "--out", "--overwrite", out)
    assert (tmp_path / "m.onnx").read_bytes() == before
    _one_line_error(capsys, ["export", run, "--format", "tflite"], "--format", "tflite")
    _one_line_error(capsys, ["export", str(tmp_path / "none")], "RUN_DIR|SYSTEM", "none")
    _one_line_error(capsys, ["export", run, "--method", "continuous"], "--method", run)
    _one_line_error(capsys, ["export", run, "--variant", "authors"], "--variant", run)
    _one_line_error(capsys, ["export", str(tmp_path)], "run folder", str(tmp_path))
    _one_line_error(capsys, ["export", run, "--out", str(tmp_path)], "--out", "folder")
    assert main(["export", run, "--out", out, "--overwrite", "--check-count", "100"]) == 0


def test_act_refuses_a_bad_observation_in_one_line():
    controller = leoc.load("pendulum")
    with pytest.raises(
        ValueError, match=r"observation: expected shape \(3,\) or \(B, 3\), found \(2,\)"
    ):
        controller.act([1.0, 0.0])
    with pytest.raises(ValueError, match="observation: expected finite numbers, found nan"):
        controller.act([np.nan, 0.0, 0.0])
    with pytest.raises(ValueError, match="method, action_repeat, variant: expected them only"):
        load("/nonexistent-run", action_repeat=2)


def test_missing_onnxruntime_names_the_extra(tmp_path, monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "onnxruntime", None)
    with pytest.raises(ImportError, match=r"pip install 'leoc\[deploy\]'"):
        export_controller(leoc.load("pendulum"), tmp_path / "m.onnx", "onnx", count=10)
    assert main(["export", "pendulum", "--out", str(tmp_path / "m.onnx")]) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "leoc[deploy]" in err
    assert not any(tmp_path.iterdir())
