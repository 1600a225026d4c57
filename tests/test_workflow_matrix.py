"""The workflow matrix: every run leoc makes works with every command.

For each learner (PILCO, DDPG, TD3, SAC) x controller kind (baseline, hybrid with the paper's
relevance, hybrid with the ROA relevance, and for DDPG, TD3 and SAC hybrid with the Lyapunov
relevance, which PILCO refuses in one line) x system x variant (leoc's, the authors'), a tiny run
(``leoc train ... --profile smoke``: a few hundred steps or one PILCO iteration on a short
horizon), then, on that run folder, ``leoc simulate RUN``, ``leoc roa --controller RUN`` and a
rerun of the same ``leoc train`` command; and ``leoc reproduce`` on every controller of a system,
then ``simulate`` and ``roa`` of each of its run folders, ``leoc plot``, a rerun and a resumed
rerun. Each succeeds, or refuses in one line where a refusal is right (the authors' variant on
the acrobot, which has no authors' linearisation; a linear reference, which has no controller
file).

A gymnasium env (``leoc train gym:InvertedPendulum-v5``, MuJoCo) runs its own path: each
model-free learner and each kind once, train, rerun, simulate on the env beside its LQR, and
``roa``'s one-line refusal (no interval model of an env exists).

The slow suite (CI) runs a pairwise cover of the three paper systems (every pair of learner,
kind, system and variant appears in some case: 22 cases, about 9 minutes of one core, too much
for the fast suite's budget), the acrobot under the authors' variant and ``leoc reproduce`` on
one system and variant; the extended suite (``pytest
-m extended``, by hand: beyond CI's 45-minute budget) runs the rest of the product, each
learner's hybrid on the acrobot, and ``reproduce`` on the other five system and variant pairs.

The assertions are about values, not exit codes only: a run is simulated on the plant it
was trained on (the variant whose rules it recorded), an ROA hybrid gives exactly its LQR's
impulse response (r = 1 along it, by construction: a mismatched plant, period or LQR breaks
it), a baseline does not, nor does a Lyapunov hybrid (r = 1 at the operating point only), a
rerun trains nothing and leaves the controller as it was, and
``simulate`` of a reproduce run gives the response ``reproduce`` recorded.
"""

from __future__ import annotations

import dataclasses
import itertools
import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch

from leoc.cli import main
from leoc.experiments.controllers import load_trained_controller
from leoc.experiments.variants import VARIANTS
from leoc.names import CONTROLLERS, PAPER_SYSTEM_NAMES, RELEVANCE_NAMES, VARIANT_NAMES
from leoc.systems import StepRules

LEARNERS = ("pilco", "ddpg", "td3", "sac")
KINDS = ("baseline", "hybrid", "hybrid_roa", "hybrid_lyapunov")
#: The learners of each kind: PILCO's config refuses the Lyapunov relevance (refused in one line,
#: tested apart: test_pilco_refuses_the_lyapunov_relevance_in_one_line).
KIND_LEARNERS = {kind: LEARNERS for kind in KINDS} | {"hybrid_lyapunov": ("ddpg", "td3", "sac")}
#: The relevance design of each hybrid kind (``--relevance``).
KIND_RELEVANCE = {"hybrid": "paper", "hybrid_roa": "roa", "hybrid_lyapunov": "lyapunov"}
SYSTEMS = (*PAPER_SYSTEM_NAMES, "acrobot")
#: Basin starts and sampled-estimate samples of the matrix's ``leoc roa`` (the proof itself is
#: the same at any setting).
ROA_ARGS = ["--samples", "500", "--starts", "8", "--json"]
#: ``leoc roa --prove`` in the matrix: each run's own closed loop, on a short proof budget (the
#: path through every learner's network on intervals, not the size of the proved set).
PROVE_ARGS = ["--prove", "--proof-seconds", "2"]
#: A hybrid's equilibrium is a up to the rounding of its LQR's ``W o(a) + b`` (state units).
OFFSET_ROUNDING = 1e-12
#: A hybrid whose relevance is 1 along the impulse response equals its LQR there: the two
#: records agree to rounding (in the units of the deviation: degrees or metres).
SAME_RESPONSE_TOL = 1e-9


def _check_own_proof(entry: dict, kind: str) -> None:
    """A run's own proof ran through its network (no operation without an interval rule); a
    hybrid's equilibrium is a itself (pi(a) = G(a), up to the rounding of W o(a) + b), so
    nothing is excluded around it."""
    assert entry["limited_by"] != "unsupported", entry
    assert entry["rho"] >= 0.0 and 0.0 <= entry["box_share"] <= 1.0
    if kind != "baseline":
        offset = max(abs(value) for value in entry["offset"])
        assert entry["equilibrium_found"] and offset < OFFSET_ROUNDING, entry
        assert entry["excluded_level"] < 1e-12 and entry["rho"] > 0.0, entry


def _pairwise_cover() -> list[tuple[str, str, str, str]]:
    """One case per (learner, kind) the learner has (:data:`KIND_LEARNERS`), with the system
    and variant cycling so that every pair of the four factors over the paper's systems appears
    (i + k runs over 0..6, which fixes a distinct (system, variant) pair for each residue mod 6;
    a kind without PILCO still has three consecutive i, so every system)."""
    return [
        (learner, kind, PAPER_SYSTEM_NAMES[(i + k) % 3], VARIANT_NAMES[(i + k) % 2])
        for (i, learner), (k, kind) in itertools.product(enumerate(LEARNERS), enumerate(KINDS))
        if learner in KIND_LEARNERS[kind]
    ]


PAIRWISE_CASES = _pairwise_cover()
#: The acrobot (no paper variant of its own: the authors' has no LQR for it): in the slow suite
#: the authors' variant's baseline (trains, its roa refused) and hybrid (refused); in the
#: extended suite each learner's hybrid under leoc's variant, whose LQR certificate (the costliest
#: of the four systems: 12 and 17 minutes at the SB3 learners' and PILCO's periods, measured on 2
#: busy cores, then read from the cache) alone would take a third of CI's budget.
ACROBOT_CASES = [
    ("ddpg", "baseline", "acrobot", "authors"),
    ("ddpg", "hybrid", "acrobot", "authors"),
]
ACROBOT_LEOC_CASES = [(learner, "hybrid", "acrobot", "leoc") for learner in LEARNERS]
PRODUCT = [
    case
    for case in itertools.product(LEARNERS, KINDS, PAPER_SYSTEM_NAMES, VARIANT_NAMES)
    if case[0] in KIND_LEARNERS[case[1]]
]
#: The rest of the product, in the extended suite (about 20 minutes on 2 cores).
EXTENDED_CASES = [case for case in PRODUCT if case not in PAIRWISE_CASES]
#: Training under perturbation (``--perturb``, ``--randomise``) through the same workflow: a
#: model-free ROA hybrid (its impulse response is still exactly its LQR's: the evaluations run
#: on the nominal plant) and, in the slow suite, a PILCO hybrid under the authors' variant (its
#: cart-pole certificate costs about a minute).
PERTURBED_CASES = [
    ("td3", "hybrid_roa", "pendulum", "leoc"),
    pytest.param(("pilco", "hybrid", "cartpole", "authors"), marks=pytest.mark.slow),
]
PERTURBATION_ARGS = ["--randomise", "observation_noise=0.1", "--perturb", "actuator_gain=-0.2"]


def _case_id(case: tuple[str, str, str, str]) -> str:
    return "-".join(case)


def _run(args: list[str], capsys) -> tuple[int, str, str]:
    code = main([str(a) for a in args])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def _train_args(
    learner: str, kind: str, system: str, variant: str, out: Path, extra: tuple = ()
) -> list[str]:
    args = ["train", system, "--algo", learner, "--variant", variant, "--profile", "smoke", *extra]
    if kind != "baseline":
        args += ["--hybrid", "--relevance", KIND_RELEVANCE[kind]]
    return [*args, "--out", out, "--quiet"]


def _actions(run: Path, system: str) -> torch.Tensor:
    """The run's controller on a fixed batch of observations around the operating point."""
    from leoc.systems import make_system

    plant = make_system(system)
    generator = np.random.default_rng(0)
    starts = np.stack([plant.sample_start(generator) for _ in range(16)])
    states = 0.3 * starts + 0.7 * np.asarray(plant.operating_state)
    observations = plant.observe(torch.as_tensor(states, dtype=torch.float64))
    with torch.no_grad():
        return load_trained_controller(run, system=system)(observations)


def _check_no_flat_top(run: Path, system: str) -> None:
    """The run's relevance is the Lyapunov relevance as loaded: 1 at the operating point and
    below 1 at every observation of :func:`_actions`'s batch off it (no set where r == 1)."""
    from leoc.systems import make_system
    from leoc.systems.rollout import relevance_function

    plant = make_system(system)
    relevance = relevance_function(load_trained_controller(run, system=system))
    assert relevance is not None
    generator = np.random.default_rng(0)
    starts = np.stack([plant.sample_start(generator) for _ in range(16)])
    operating = np.asarray(plant.operating_state, dtype=float)
    states = np.concatenate([operating[None], 0.3 * starts + 0.7 * operating])
    with torch.no_grad():
        r = relevance(plant.observe(torch.as_tensor(states, dtype=torch.float64))).squeeze(-1)
    assert abs(float(r[0]) - 1.0) <= 1e-12
    assert torch.all(r[1:] < 1.0), r


def _linear_response(run: Path, learner: str, variant: str, period: int) -> np.ndarray:
    """The impulse response of the LQR inside a hybrid of ``learner`` under ``variant``, built
    from the design (not from the run's weights), on the run's plant at its period: the
    variant's LQR design, squashed as the learner squashes its linear part: PILCO's is
    u_max sin(G / u_max) under every variant (for its moment matching), DDPG's, TD3's and SAC's
    is G clipped to the action box under every variant (the authors' DDPG had no squash)."""
    from leoc.evaluation.rollout import response_test
    from leoc.experiments.controllers import trained_plant
    from leoc.experiments.variants import get_variant

    squash = "sin" if learner == "pilco" else "none"
    chosen = dataclasses.replace(get_variant(variant), linear_saturation=squash)
    plant = trained_plant(run)
    controller = chosen.linear_controller(plant, period)
    return response_test(plant, controller, steps=chosen.steps_for(plant.name)).deviation


def _check_workflow(
    case: tuple[str, str, str, str], tmp_path: Path, capsys, extra: tuple = ()
) -> None:
    learner, kind, system, variant = case
    run = tmp_path / "run"
    train = _train_args(learner, kind, system, variant, run, extra)
    code, out, err = _run(train, capsys)
    # the authors' LQR is their own linearisation, which exists for the paper's systems only: a
    # hybrid needs it (refused in one line, nothing written); a baseline trains without it
    no_authors_lqr = variant == "authors" and system not in PAPER_SYSTEM_NAMES
    if no_authors_lqr and kind != "baseline":
        assert code == 2 and len(err.strip().splitlines()) == 1
        assert "the authors' linearisation exists for" in err and not run.exists()
        return
    assert code == 0, err
    assert f"run folder: {run}" in out

    # simulate: on the plant it was trained on, and reported under the variant it ran
    code, out, err = _run(["simulate", run, "--json"], capsys)
    assert code == 0, err
    response = json.loads(out)
    assert response["system"] == system
    # the variant it ran under, or one on the same plant when the rules cannot tell them apart
    assert VARIANTS[response["variant"]].rules_for(system) == VARIANTS[variant].rules_for(system)
    assert response["variant"] == variant or no_authors_lqr
    recorded = json.loads((run / "config.json").read_text())
    assert response["step_rules"] == dataclasses.asdict(
        StepRules(**(recorded.get("step_rules") or {}))
    )
    # what it was trained under, as recorded (nothing for a nominal run)
    trained_under = recorded.get("training_perturbations")
    assert bool(trained_under) == bool(extra)
    assert response["training_perturbations"] == (trained_under or {"fixed": {}, "randomised": {}})
    deviation = np.asarray(response["deviation"])
    assert deviation.size > 1 and np.isfinite(deviation).all()

    if no_authors_lqr:  # no LQR to compare with or to certify: roa refuses in one line
        code, out, err = _run(["roa", "--controller", run, *ROA_ARGS], capsys)
        assert code == 2 and len(err.strip().splitlines()) == 1
        assert "the authors' linearisation exists for" in err
        return
    # an ROA hybrid is its LQR along the impulse (r = 1 there); a baseline is not
    reference = _linear_response(run, learner, variant, response["action_repeat"])
    same_length = deviation.shape == reference.shape  # a fall ends the record early
    difference = np.max(np.abs(deviation - reference)) if same_length else np.inf
    if kind == "hybrid_roa":
        assert difference <= SAME_RESPONSE_TOL * max(1.0, np.max(np.abs(reference)))
    elif kind in ("baseline", "hybrid_lyapunov"):
        # a Lyapunov hybrid has no flat top: r < 1 along the impulse, so H enters
        assert difference > SAME_RESPONSE_TOL
    if kind == "hybrid_lyapunov":
        _check_no_flat_top(run, system)

    # roa: the system read from the run, certified on the run's plant; its own closed loop
    # proved on intervals (every learner's network has the rules; a short budget)
    code, out, err = _run(["roa", "--controller", run, *ROA_ARGS, *PROVE_ARGS], capsys)
    assert code == 0, err
    report = json.loads(out)
    assert report["system"] == system
    assert report["trained_under"] == {str(run): response["training_perturbations"]}
    assert report["plant"]["legacy_integrator"] == (variant == "authors" and system == "pendulum")
    (held,) = [entry for label, entry in report["basins"].items() if label == run.name]
    assert 0.0 <= held["certified_set_held"] <= 1.0
    _check_own_proof(report["proofs"][run.name], kind)

    # the same train command again: nothing is trained, the controller is the same
    before = _actions(run, system)
    files = {p.name: p.stat().st_mtime_ns for p in run.iterdir() if p.is_file()}
    code, out, err = _run(train, capsys)
    assert code == 0, err
    torch.testing.assert_close(_actions(run, system), before, rtol=0.0, atol=0.0)
    if learner != "pilco":
        assert {p.name: p.stat().st_mtime_ns for p in run.iterdir() if p.is_file()} == files
    # another budget in the same folder is refused in one line, and the run left alone
    if learner != "pilco":  # PILCO extends its run given more iterations (tested apart)
        code, out, err = _run([*train, "--steps", "500"], capsys)
        assert code == 2 and len(err.strip().splitlines()) == 1 and "--overwrite" in err
        torch.testing.assert_close(_actions(run, system), before, rtol=0.0, atol=0.0)


@pytest.mark.slow
@pytest.mark.heavy
@pytest.mark.parametrize("case", PAIRWISE_CASES, ids=_case_id)
def test_workflow(case, tmp_path, capsys) -> None:
    _check_workflow(case, tmp_path, capsys)


@pytest.mark.slow
@pytest.mark.parametrize("case", PERTURBED_CASES, ids=_case_id)
def test_workflow_under_perturbation(case, tmp_path, capsys) -> None:
    _check_workflow(case, tmp_path, capsys, tuple(PERTURBATION_ARGS))


@pytest.mark.slow
@pytest.mark.parametrize("case", ACROBOT_CASES, ids=_case_id)
def test_workflow_on_the_acrobot(case, tmp_path, capsys) -> None:
    _check_workflow(case, tmp_path, capsys)


@pytest.mark.extended
@pytest.mark.parametrize("case", EXTENDED_CASES + ACROBOT_LEOC_CASES, ids=_case_id)
def test_workflow_rest_of_the_product(case, tmp_path, capsys) -> None:
    _check_workflow(case, tmp_path, capsys)


def test_the_pairwise_cover_covers_every_pair() -> None:
    """Every pair of values of two factors appears in some pairwise case (so a defect that needs
    two choices together is met by the slow suite)."""
    for a, b in itertools.combinations(range(4), 2):
        seen = {(case[a], case[b]) for case in PAIRWISE_CASES}
        assert seen == {(case[a], case[b]) for case in PRODUCT}, (a, b)
    assert set(PAIRWISE_CASES).isdisjoint(EXTENDED_CASES)
    # 4 learners x 3 kinds and the three SB3 learners' Lyapunov hybrids, x 3 systems x 2 variants
    assert len(set(PAIRWISE_CASES) | set(EXTENDED_CASES)) == 90
    # the Lyapunov hybrids split as the ROA hybrids do: one pairwise case per learner, the rest
    # extended
    for kind in ("hybrid_roa", "hybrid_lyapunov"):
        assert sorted(c[0] for c in PAIRWISE_CASES if c[1] == kind) == sorted(KIND_LEARNERS[kind])
    assert all(c[:2] != ("pilco", "hybrid_lyapunov") for c in PRODUCT)


def test_pilco_refuses_the_lyapunov_relevance_in_one_line(capsys, tmp_path) -> None:
    """PILCO x the Lyapunov relevance is not a case of the matrix: its config refuses it, in
    one line naming the relevance, before anything is written."""
    run = tmp_path / "run"
    train = _train_args("pilco", "hybrid_lyapunov", "pendulum", "leoc", run)
    code, _, err = _run(train, capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1, err
    assert "--relevance" in err and "'lyapunov'" in err and "PILCO" in err
    assert not run.exists()


def test_the_command_line_names_agree_with_the_library() -> None:
    from leoc.policies.relevance import RELEVANCE_KINDS

    assert RELEVANCE_NAMES == RELEVANCE_KINDS


def test_relevance_without_hybrid_is_refused(capsys, tmp_path) -> None:
    code, _, err = _run(
        ["train", "pendulum", "--algo", "ddpg", "--relevance", "roa", "--out", tmp_path / "r"],
        capsys,
    )
    assert code == 2 and err.count("\n") == 1 and "--relevance: only with --hybrid" in err
    assert not (tmp_path / "r").exists()


# ----------------------------------------------------------------------------- reproduce path
REPRODUCE_CONTROLLERS = CONTROLLERS  # every controller reproduce knows


def _check_reproduce(system: str, variant: str, tmp_path: Path, capsys) -> None:
    out = tmp_path / "study"
    command = [
        "reproduce", "--profile", "smoke", "--variant", variant, "--systems", system,
        "--controllers", *REPRODUCE_CONTROLLERS, "--jobs", "1", "--out", out,
    ]  # fmt: skip
    code, _, err = _run(command, capsys)
    assert code == 0, err
    assert (out / "report.md").is_file()
    for controller in REPRODUCE_CONTROLLERS:
        run = out / "runs" / system / controller / "seed0"
        recorded = json.loads((run / "evaluation.json").read_text())
        code, printed, err = _run(["simulate", run, "--json"], capsys)
        if controller.startswith("linear"):
            # designed, not trained: refused in one line that says how to simulate it
            assert code == 2 and len(err.strip().splitlines()) == 1
            assert f"leoc simulate {system} --variant {variant}" in err
            continue
        assert code == 0, err
        simulated = json.loads(printed)
        impulse = recorded["responses"]["impulse"]
        # the response simulate gives is the one reproduce recorded for this run
        assert simulated["variant"] == variant
        np.testing.assert_allclose(
            simulated["deviation"], impulse["deviation"], rtol=1e-9, atol=1e-12
        )
        code, printed, err = _run(["roa", "--controller", run, *ROA_ARGS], capsys)
        assert code == 0, err
    code, _, err = _run(["plot", out], capsys)
    assert code == 0, err
    # a rerun trains nothing; one run lost is run again, alone
    report = (out / "report.md").read_text()
    code, printed, err = _run(command, capsys)
    assert code == 0, err
    lost = out / "runs" / system / "ddpg_hybrid" / "seed0"
    kept = json.loads((lost / "evaluation.json").read_text())
    (lost / "evaluation.json").unlink()
    code, printed, err = _run(command, capsys)
    assert code == 0, err
    assert "[1/1]" in printed
    again = json.loads((lost / "evaluation.json").read_text())
    assert again["responses"] == kept["responses"]
    assert (out / "report.md").read_text().splitlines()[0] == report.splitlines()[0]


@pytest.mark.slow
def test_reproduce_workflow(tmp_path, capsys) -> None:
    _check_reproduce("mountaincar", "authors", tmp_path, capsys)


@pytest.mark.extended
@pytest.mark.parametrize(
    ("system", "variant"),
    [
        (s, v)
        for s, v in itertools.product(PAPER_SYSTEM_NAMES, VARIANT_NAMES)
        if (s, v) != ("mountaincar", "authors")
    ],
)
def test_reproduce_workflow_everywhere(system, variant, tmp_path, capsys) -> None:
    _check_reproduce(system, variant, tmp_path, capsys)


def test_a_linear_run_folder_is_refused_with_the_command_that_works(tmp_path, capsys) -> None:
    run = tmp_path / "runs" / "pendulum" / "linear_pilco" / "seed0"
    run.mkdir(parents=True)
    (run / "evaluation.json").write_text(
        json.dumps(
            {
                "spec": {"system": "pendulum", "controller": "linear_pilco", "seed": 0},
                "variant": "authors",
                "action_repeat": 2,
            }
        )
    )
    code, _, err = _run(["simulate", run], capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert "'leoc simulate pendulum --variant authors --action-repeat 2'" in err
    shutil.rmtree(run)


@pytest.mark.slow
def test_pilco_extends_a_run_given_more_iterations_and_refuses_fewer(tmp_path, capsys) -> None:
    """PILCO's budget is a count of independent iterations: the same command with more
    iterations continues the run (its config then records the new budget); fewer than it has
    done is refused in one line, the run left alone."""
    run = tmp_path / "run"
    train = ["train", "pendulum", "--algo", "pilco", "--profile", "smoke", "--out", run]
    assert _run([*train, "--iterations", "1", "--quiet"], capsys)[0] == 0
    code, _, err = _run([*train, "--iterations", "2", "--quiet"], capsys)
    assert code == 0, err
    curve = json.loads((run / "curve.json").read_text())["curve"]
    assert [row["iteration"] for row in curve] == [0, 1, 2]
    assert json.loads((run / "config.json").read_text())["iterations"] == 2
    before = _actions(run, "pendulum")
    code, _, err = _run([*train, "--iterations", "1", "--quiet"], capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert "holds a PILCO run of 2 iterations" in err and "--overwrite" in err
    torch.testing.assert_close(_actions(run, "pendulum"), before, rtol=0.0, atol=0.0)
    code, _, err = _run([*train, "--iterations", "1", "--overwrite", "--quiet"], capsys)
    assert code == 0, err
    assert [r["iteration"] for r in json.loads((run / "curve.json").read_text())["curve"]] == [0, 1]


#: The gymnasium path (``leoc train gym:ENV_ID``, :mod:`leoc.sb3.gym`): each model-free
#: learner once, each kind once (pairwise, as the fast cover), on MuJoCo's InvertedPendulum-v5.
GYM_CASES = [("ddpg", "baseline"), ("td3", "hybrid_roa"), ("sac", "hybrid_lyapunov")]
GYM_SYSTEM = "gym:InvertedPendulum-v5"
#: Training steps of a gymnasium case: the path, not the learning.
GYM_STEPS = 50


@pytest.mark.slow
@pytest.mark.usefixtures("single_thread")
@pytest.mark.parametrize(("learner", "kind"), GYM_CASES, ids=["-".join(c) for c in GYM_CASES])
def test_workflow_on_a_gymnasium_env(learner, kind, tmp_path, capsys) -> None:
    """train, a rerun (nothing trained, the controller unchanged), simulate (the trained
    controller beside its LQR on the env), roa (a one-line refusal: no interval model), and a
    hybrid's action at the operating observation is its LQR's, u_eq = 0."""
    pytest.importorskip("mujoco")
    from leoc.sb3.gym import load_gym_controller

    run = tmp_path / "run"
    train = ["train", GYM_SYSTEM, "--algo", learner, "--steps", GYM_STEPS, "--out", run]
    if kind != "baseline":
        train += ["--hybrid", "--relevance", KIND_RELEVANCE[kind]]
    code, _, err = _run([*train, "--quiet"], capsys)
    assert code == 0, err
    model = (run / "model.zip").read_bytes()
    code, out, err = _run(train, capsys)
    assert code == 0 and "nothing to train" in out, err
    assert (run / "model.zip").read_bytes() == model
    code, out, err = _run(["simulate", run, "--json"], capsys)
    assert code == 0, err
    report = json.loads(out)
    assert report["lqr"]["metrics"]["peak_deviation"] > 0.0
    assert np.isfinite(report["trained"]["metrics"]["peak_deviation"])
    code, _, err = _run(["roa", "--controller", run], capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1 and "no interval model" in err
    controller = load_gym_controller(run)
    if kind != "baseline":  # the rest state is the operating observation: G(a) = u_eq = 0
        assert abs(float(controller(np.zeros(4))[0])) < 1e-9
    if kind == "hybrid_roa":  # r == 1 near a: the action is the LQR's -K x (observation = state)
        gain = np.asarray(json.loads((run / "design.json").read_text())["K"])
        state = np.array([0.01, -0.02, 0.03, 0.01])
        np.testing.assert_allclose(controller(state), -gain @ state, rtol=1e-9, atol=1e-12)
