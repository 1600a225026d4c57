"""``leoc train --hybrid --relevance ...`` and the relevance's parameters as flags: each flag
sets its :class:`~leoc.policies.HybridSpec` field, the run folder records the spec, and the
commands that load a run folder (``leoc simulate``, ``leoc roa``) build that hybrid."""

from __future__ import annotations

import json
import math

import pytest
import torch

from leoc.cli import build_parser, main
from leoc.cli.train import HYBRID_FLAGS, RELEVANCE_PARAMETRISATIONS, default_run_dir, hybrid_of
from leoc.names import RELEVANCE_NAMES, parse_controller
from leoc.policies import HybridPolicy
from leoc.policies.spec import RELEVANCE_DESIGNS, HybridSpec

SMOKE = ("--profile", "smoke", "--quiet")  # a few hundred steps, 32-unit networks


def _train(*argv: str) -> int:
    return main(["train", "pendulum", "--algo", "ddpg", *argv, *SMOKE])


def _error_line(capsys) -> str:
    (line,) = capsys.readouterr().err.strip().splitlines()
    return line


def test_every_flag_sets_its_hybrid_spec_field() -> None:
    """All the flags at once give the spec with each field set by its flag; every HybridSpec
    field has a flag, and the parametrisations are the library's."""
    from leoc.policies.relevance import RELEVANCE_PARAMETRISATIONS as LIBRARY

    argv = [
        "train", "pendulum", "--algo", "ddpg", "--hybrid", "--relevance", "roa",
        "--lambda-init", "2,3,4", "--freeze-lambda", "--r-min", "0.5",
        "--relevance-lr-scale", "0.1", "--rho-in-fraction", "0.25", "--width-init", "2",
        "--freeze-width",
    ]  # fmt: skip
    expected = HybridSpec(
        relevance="roa",
        lambda_init=(2.0, 3.0, 4.0),
        learn_lambda=False,
        rho_in_fraction=0.25,
        width_init=2.0,
        learn_width=False,
        r_min=0.5,
        relevance_lr_scale=0.1,
    )
    assert hybrid_of(build_parser().parse_args(argv)) == expected
    precision = [*argv[:5], "--relevance-parametrisation", "precision"]
    assert hybrid_of(build_parser().parse_args(precision)).relevance_parametrisation == "precision"
    assert set(HYBRID_FLAGS) == set(HybridSpec.field_names())
    assert RELEVANCE_PARAMETRISATIONS == LIBRARY
    # no flag: HybridSpec's defaults; no --hybrid: no hybrid
    assert hybrid_of(build_parser().parse_args(argv[:5])) == HybridSpec()
    assert hybrid_of(build_parser().parse_args(argv[:4])) is None


def test_the_flags_win_over_the_variants_hybrid_settings() -> None:
    """The authors' DDPG holds Lambda as a precision; --relevance-parametrisation log_lambda
    under --variant authors trains the log-lambda hybrid (what the learner's config gets)."""
    from leoc.cli.train import controller_of, run_settings
    from leoc.policies.spec import with_hybrid_overrides

    def trained_spec(*flags: str) -> HybridSpec:
        argv = ["train", "pendulum", "--algo", "ddpg", "--hybrid", "--variant", "authors"]
        args = build_parser().parse_args([*argv, *flags])
        return with_hybrid_overrides(controller_of(args).hybrid, run_settings(args))

    assert trained_spec().relevance_parametrisation == "precision"
    chosen = trained_spec("--relevance-parametrisation", "log_lambda", "--lambda-init", "2")
    assert (chosen.relevance_parametrisation, chosen.lambda_init) == ("log_lambda", 2.0)


def test_every_relevance_design_is_a_choice_and_names_its_run_folder(monkeypatch) -> None:
    """--relevance takes each design of RELEVANCE_DESIGNS (one added there too), and the
    default run folder is named as leoc reproduce names the controller (ddpg_hybrid_roa)."""
    from leoc.cli import _args

    base = ["train", "pendulum", "--algo", "ddpg", "--hybrid", "--relevance"]
    for name in (*RELEVANCE_NAMES, *RELEVANCE_DESIGNS):
        folder = default_run_dir(build_parser().parse_args([*base, name]))
        assert parse_controller(folder.parent.name).relevance == name
        assert folder.parent.name == f"ddpg_{'hybrid' if name == 'paper' else 'hybrid_' + name}"
    monkeypatch.setattr(_args, "registered_relevance_names", lambda: ("paper", "roa", "new"))
    assert build_parser().parse_args([*base, "new"]).relevance == "new"
    with pytest.raises(SystemExit):
        build_parser().parse_args([*base, "nonsense"])


@pytest.mark.slow
def test_an_roa_hybrid_from_the_command_line(tmp_path, monkeypatch, capsys) -> None:
    """`leoc train pendulum --algo ddpg --hybrid --relevance roa` trains an ROA hybrid into
    runs/pendulum/ddpg_hybrid_roa/seed0: config.json records the spec, the loaded controller
    holds an ROARelevance, and leoc simulate and leoc roa run on the folder."""
    from leoc.experiments.controllers import load_trained_controller
    from leoc.policies import ROARelevance

    monkeypatch.chdir(tmp_path)
    assert _train("--hybrid", "--relevance", "roa", "--rho-in-fraction", "0.5") == 0
    run = tmp_path / "runs" / "pendulum" / "ddpg_hybrid_roa" / "seed0"
    assert f"run folder: {run.relative_to(tmp_path)}" in capsys.readouterr().out
    saved = json.loads((run / "config.json").read_text())["hybrid"]
    assert saved == HybridSpec(relevance="roa", rho_in_fraction=0.5).to_dict()
    controller = load_trained_controller(run)
    assert any(isinstance(module, ROARelevance) for module in controller.modules())
    assert main(["simulate", str(run), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["controller"] == str(run)
    roa = ["roa", "--controller", str(run), "--samples", "500", "--starts", "4", "--json"]
    assert main(roa) == 0
    # labelled as simulate labels it: SYSTEM/CONTROLLER/seedN
    basin = json.loads(capsys.readouterr().out)["basins"]["pendulum/ddpg_hybrid_roa/seed0"]
    assert basin["flat_top_same_P"] is True


def test_lambda_init_and_freeze_lambda_reach_the_loaded_policy(tmp_path, capsys) -> None:
    """--lambda-init 3 --freeze-lambda with the paper's relevance as published (--r-min none
    --relevance-power 1: log_lambda on the policy): the loaded policy's Lambda is exactly 3
    after training; the same command again returns the finished run, another spec in the
    folder is refused naming the flags that differ."""
    from leoc.experiments.controllers import load_trained_controller

    run = tmp_path / "paper_lambda3"
    paper = ("--r-min", "none", "--relevance-power", "1")
    command = ("--hybrid", "--lambda-init", "3", "--freeze-lambda", *paper, "--out", str(run))
    assert _train(*command) == 0
    saved = json.loads((run / "config.json").read_text())["hybrid"]
    assert saved["lambda_init"] == 3.0 and saved["learn_lambda"] is False
    assert (saved["r_min"], saved["relevance_power"]) == (None, 1.0)
    controller = load_trained_controller(run)
    (hybrid,) = {id(m): m for m in controller.modules() if isinstance(m, HybridPolicy)}.values()
    assert torch.equal(hybrid.log_lambda, torch.full((3,), math.log(3.0), dtype=torch.float64))
    assert "log_lambda" not in dict(hybrid.named_parameters())  # a buffer: frozen
    assert _train(*command) == 0  # the same run: returned, not refused
    capsys.readouterr()
    assert _train(*command, "--r-min", "0.5") == 2  # the last --r-min wins
    line = _error_line(capsys)
    assert "--r-min (r_min): None there, 0.5 here" in line and "--overwrite" in line
    assert _train("--hybrid", "--out", str(run)) == 2  # today's default hybrid: floored at 0.5
    line = _error_line(capsys)
    assert "--lambda-init (lambda_init): 3.0 there, 1.0 here" in line
    assert "--freeze-lambda (learn_lambda): False there, True here" in line
    assert "--r-min (r_min): None there, 0.5 here" in line
    assert "--relevance-power (relevance_power): 1.0 there, 2.0 here" in line


@pytest.mark.parametrize(
    "flag",
    [
        ["--relevance", "roa"],
        ["--lambda-init", "3"],
        ["--freeze-lambda"],
        ["--relevance-parametrisation", "precision"],
        ["--r-min", "0.5"],
        ["--relevance-lr-scale", "0.1"],
        ["--relevance-power", "2"],
        ["--rho-in-fraction", "0.5"],
        ["--width-init", "2"],
        ["--freeze-width"],
    ],
)
def test_a_relevance_flag_without_hybrid_is_an_error_naming_it(tmp_path, capsys, flag) -> None:
    assert _train(*flag, "--out", str(tmp_path / "run")) == 2
    line = _error_line(capsys)
    assert line.startswith(f"leoc train: error: {flag[0]}: only with --hybrid"), line
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize(
    ("flag", "field"),
    [
        (["--r-min", "1.5"], "r_min"),
        (["--lambda-init", "1,0,1"], "lambda_init"),
        (["--lambda-init", "1,2"], "lambda_init"),  # pendulum's observation has 3 entries
        (["--relevance-lr-scale", "0"], "relevance_lr_scale"),
        (["--relevance-power", "0.5"], "relevance_power"),
        (["--relevance", "roa", "--relevance-power", "2"], "relevance_power"),
        (["--relevance", "roa", "--rho-in-fraction", "2"], "rho_in_fraction"),
        (["--relevance", "roa", "--width-init", "-1"], "width_init"),
        (["--relevance", "lyapunov", "--lambda-init", "1,2,3"], "lambda_init"),  # a scalar
    ],
)
def test_a_value_hybrid_spec_refuses_is_one_line_naming_it(tmp_path, capsys, flag, field):
    assert _train("--hybrid", *flag, "--out", str(tmp_path / "run")) == 2
    line = _error_line(capsys)
    assert f"{flag[-2]}: {field}" in line, line
    assert not (tmp_path / "run").exists()


def test_a_flag_pilco_cannot_honour_is_one_line_naming_it(tmp_path, capsys) -> None:
    run = tmp_path / "pilco"
    argv = ["train", "pendulum", "--algo", "pilco", "--hybrid", *SMOKE, "--out", str(run)]
    assert main([*argv, "--relevance-parametrisation", "precision"]) == 2
    line = _error_line(capsys)
    assert "--relevance-parametrisation: relevance_parametrisation" in line and "PILCO" in line
    assert not run.exists()


def test_a_floored_pilco_hybrid_from_the_command_line(tmp_path, capsys) -> None:
    """`leoc train pendulum --algo pilco --hybrid --r-min 0.5`: config.json records the floor
    and the default power p = 2, the loaded controller's relevance is the paper's,
    r = (1 + d^2)^-2, with Lambda floored on the proved set of the LQR at PILCO's own control
    period, so r >= 0.5 on states sampled on that set's boundary (a numpy reference from the
    certificate's P and rho, not the floor's own code), and r < 1 off the operating point;
    leoc simulate and leoc roa run on the folder."""
    import numpy as np

    from leoc.control import certify_lqr, design_lqr
    from leoc.experiments.controllers import load_trained_controller
    from leoc.pilco.config import PilcoConfig
    from leoc.policies import FlooredRelevance
    from leoc.systems import make_system

    run = tmp_path / "pilco_floor"
    argv = ["train", "pendulum", "--algo", "pilco", "--hybrid", "--r-min", "0.5", *SMOKE]
    assert main([*argv, "--out", str(run)]) == 0
    saved = json.loads((run / "config.json").read_text())["hybrid"]
    assert (saved["r_min"], saved["relevance_power"]) == (0.5, 2.0)
    controller = load_trained_controller(run)
    (relevance,) = [m for m in controller.modules() if isinstance(m, FlooredRelevance)]
    assert relevance.power == 2.0
    lam = relevance.lambda_.detach().numpy()
    system = make_system("pendulum")
    period = PilcoConfig.for_system("pendulum").controller_action_repeat
    certificate = certify_lqr(system, design_lqr(system, action_repeat=period))
    assert certificate.certified and certificate.action_repeat == period
    # states on the boundary of the proved set {z^T P z <= rho} (where r is smallest)
    rng = np.random.default_rng(0)
    P, rho = np.asarray(certificate.P), certificate.rho
    u = rng.standard_normal((4000, 2))
    u /= np.linalg.norm(u, axis=-1, keepdims=True)
    z = np.sqrt(rho) * np.linalg.solve(np.linalg.cholesky(P).T, u.T).T
    theta = z[:, 0]  # the pendulum's deviation from upright (cos theta = 1 there)
    obs = np.stack([np.cos(theta), np.sin(theta), z[:, 1]], axis=-1)
    a = np.array([1.0, 0.0, 0.0])
    r = 1.0 / (1.0 + ((obs - a) ** 2 / lam).sum(axis=-1) ** 2) ** 2
    assert r.min() >= 0.5 and r.max() < 1.0
    with torch.no_grad():
        np.testing.assert_allclose(
            relevance(torch.as_tensor(obs)).numpy()[:, 0], r, rtol=1e-12, atol=0.0
        )
    assert main(["simulate", str(run), "--json"]) == 0
    capsys.readouterr()
    roa = ["roa", "--controller", str(run), "--samples", "500", "--starts", "4", "--json"]
    assert main(roa) == 0
    assert json.loads(capsys.readouterr().out)["basins"][run.name]


@pytest.mark.slow
@pytest.mark.parametrize(
    ("algo", "flags", "module_name"),
    [
        ("ddpg", ("--relevance-power", "2", "--r-min", "none"), "PaperRelevance"),
        ("sac", ("--relevance-power", "2", "--r-min", "0.5"), "FlooredRelevance"),
        ("pilco", ("--relevance-power", "2", "--r-min", "0.5"), "FlooredRelevance"),
    ],
)
def test_relevance_power_reaches_the_loaded_controller(tmp_path, capsys, algo, flags, module_name):
    """--relevance-power 2: config.json records it, the loaded (float64, physical) controller's
    relevance is (1 + d^2)^-2 of its own learned Lambda (numpy reference) off the operating
    point, with r(a) = 1; leoc simulate and leoc roa run on the folder, and the same command
    again returns the finished run."""
    import numpy as np

    from leoc.experiments.controllers import load_trained_controller

    run = tmp_path / f"{algo}_power2"
    argv = ["train", "pendulum", "--algo", algo, "--hybrid", *flags, *SMOKE, "--out", str(run)]
    assert main(argv) == 0
    assert json.loads((run / "config.json").read_text())["hybrid"]["relevance_power"] == 2.0
    controller = load_trained_controller(run)
    (module,) = [m for m in controller.modules() if type(m).__name__ == module_name]
    assert module.power == 2.0
    lam = module.lambda_.detach().numpy()
    rng = np.random.default_rng(3)
    theta, speed = rng.uniform(-3.0, 3.0, 200), rng.uniform(-8.0, 8.0, 200)
    obs = np.stack([np.cos(theta), np.sin(theta), speed], axis=-1)
    d = ((obs - np.array([1.0, 0.0, 0.0])) ** 2 / lam).sum(axis=-1)
    with torch.no_grad():
        r = module(torch.as_tensor(obs)).numpy()[:, 0]
        assert float(module(torch.tensor([[1.0, 0.0, 0.0]], dtype=torch.float64))) == 1.0
    np.testing.assert_allclose(r, 1.0 / (1.0 + d**2) ** 2, rtol=1e-12)
    assert main(["simulate", str(run), "--json"]) == 0
    capsys.readouterr()
    roa = ["roa", "--controller", str(run), "--samples", "500", "--starts", "4", "--json"]
    assert main(roa) == 0
    assert json.loads(capsys.readouterr().out)["basins"][run.name]
    before = (run / "controller.pt").read_bytes() if (run / "controller.pt").exists() else None
    assert main(argv) == 0  # the same command again: the finished run, nothing retrained
    if before is not None:
        assert (run / "controller.pt").read_bytes() == before


@pytest.mark.slow
@pytest.mark.parametrize(
    ("flags", "r_min", "power", "module_name"),
    [
        ((), 0.5, 2.0, "FlooredRelevance"),
        (("--r-min", "none", "--relevance-power", "1"), None, 1.0, None),
    ],
    ids=["default", "paper-as-published"],
)
def test_the_default_hybrid_and_the_papers_relevance_from_the_command_line(
    tmp_path, flags, r_min, power, module_name
):
    """`--hybrid` alone (issue 40): config.json records r_min 0.5 and relevance_power 2, and the
    loaded policy's relevance is a FlooredRelevance with p = 2; `--r-min none --relevance-power
    1`: r_min None and power 1 recorded, and the paper's relevance as published (log_lambda on
    the policy, no relevance module)."""
    from leoc.experiments.controllers import load_trained_controller
    from leoc.policies import FlooredRelevance

    run = tmp_path / "run"
    assert _train("--hybrid", *flags, "--out", str(run)) == 0
    saved = json.loads((run / "config.json").read_text())["hybrid"]
    assert saved["relevance"] == "paper" and saved["relevance_parametrisation"] == "log_lambda"
    assert (saved["r_min"], saved["relevance_power"]) == (r_min, power)
    controller = load_trained_controller(run)
    (hybrid,) = {id(m): m for m in controller.modules() if isinstance(m, HybridPolicy)}.values()
    if module_name is None:
        assert hybrid.relevance_module is None and hybrid.relevance_kind == "paper"
        assert hybrid.log_lambda.shape == (3,)
    else:
        assert isinstance(hybrid.relevance_module, FlooredRelevance)
        assert hybrid.relevance_module.power == 2.0
        assert not hasattr(hybrid, "log_lambda")


def test_r_min_none_parses_to_no_floor_and_a_bad_value_is_an_argparse_error(capsys) -> None:
    """--r-min takes 'none' (any case) for no floor and a number; anything else is argparse's
    error (exit status 2) naming --r-min."""
    base = ["train", "pendulum", "--algo", "ddpg", "--hybrid", "--r-min"]

    def spec(value: str) -> HybridSpec:
        return hybrid_of(build_parser().parse_args([*base, value]))

    for word in ("none", "NONE", "None", " none "):
        assert spec(word).r_min is None, word
        assert spec(word) == HybridSpec(r_min=None)  # the power keeps its default (2)
    assert spec("none").relevance_power == 2.0
    assert spec("0.3").r_min == 0.3 and spec("0.3") == HybridSpec(r_min=0.3)
    capsys.readouterr()
    with pytest.raises(SystemExit) as exit_info:
        build_parser().parse_args([*base, "abc"])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert "--r-min" in err and "'abc'" in err, err


def test_r_min_with_the_precision_parametrisation(tmp_path, capsys) -> None:
    """--relevance-parametrisation precision has no floor: --r-min none is accepted (the run
    records r_min None and power 1) while --r-min 0.5 is a one-line error naming --r-min."""
    precision = ("--hybrid", "--relevance-parametrisation", "precision")
    argv = ["train", "pendulum", "--algo", "ddpg", *precision, "--r-min", "none"]
    assert hybrid_of(build_parser().parse_args(argv)) == HybridSpec(
        relevance_parametrisation="precision", r_min=None
    )
    run = tmp_path / "precision"
    assert _train(*precision, "--r-min", "none", "--out", str(run)) == 0
    saved = json.loads((run / "config.json").read_text())["hybrid"]
    assert saved["relevance_parametrisation"] == "precision"
    assert (saved["r_min"], saved["relevance_power"]) == (None, 1.0)
    capsys.readouterr()
    refused = tmp_path / "refused"
    assert _train(*precision, "--r-min", "0.5", "--out", str(refused)) == 2
    line = _error_line(capsys)
    assert line.startswith("leoc train: error: --r-min: r_min"), line
    assert "precision" in line
    assert not refused.exists()
