"""The Lyapunov-relevance hybrids as ``leoc reproduce`` controllers: named, not default, labelled,
drawn, and in every part of the report that compares hybrids, without the ROA's flat top."""

from __future__ import annotations

import json

import pytest

from leoc.cli import build_parser
from leoc.evaluation.plots.common import CONTROLLER_COLOURS, CONTROLLER_MARKERS, CONTROLLER_STYLES
from leoc.experiments.profiles import CONTROLLER_LABELS, get_profile, run_specs
from leoc.learners import ControllerSpec
from leoc.names import (
    CONTROLLERS,
    DEFAULT_CONTROLLERS,
    FRAMEWORKS,
    RELEVANCE_NAMES,
    ControllerName,
    parse_controller,
)

#: Slow suite: the module's smoke study takes minutes.
pytestmark = pytest.mark.slow

LYAPUNOV_HYBRIDS = ("ddpg_hybrid_lyapunov", "sac_hybrid_lyapunov")


def _controllers_action():
    (reproduce,) = (
        parser
        for action in build_parser()._subparsers._group_actions
        for name, parser in action.choices.items()
        if name == "reproduce"
    )
    (controllers,) = (a for a in reproduce._actions if a.dest == "controllers")
    return controllers


def test_reproduce_offers_the_lyapunov_hybrids_but_not_pilcos():
    action = _controllers_action()
    assert set(LYAPUNOV_HYBRIDS) <= set(action.choices)
    assert "pilco_hybrid_lyapunov" not in action.choices
    assert tuple(action.choices) == CONTROLLERS
    # each framework's hybrids in report order: paper, ROA, then Lyapunov
    assert CONTROLLERS.index("ddpg_hybrid_roa") + 1 == CONTROLLERS.index("ddpg_hybrid_lyapunov")
    assert CONTROLLERS.index("sac_hybrid_roa") + 1 == CONTROLLERS.index("sac_hybrid_lyapunov")
    specs = run_specs(get_profile("smoke"), ("pendulum",), LYAPUNOV_HYBRIDS)
    assert {spec.controller for spec in specs} == set(LYAPUNOV_HYBRIDS)
    assert all(
        spec.hybrid and spec.controller_spec.hybrid.relevance == "lyapunov" for spec in specs
    )
    with pytest.raises(ValueError, match=r"controllers: unknown 'pilco_hybrid_lyapunov'"):
        run_specs(get_profile("smoke"), ("pendulum",), ("pilco_hybrid_lyapunov",))


def test_pilco_lyapunov_is_refused_on_the_command_line(capsys):
    with pytest.raises(SystemExit) as exit_:
        build_parser().parse_args(["reproduce", "--controllers", "pilco_hybrid_lyapunov"])
    assert exit_.value.code == 2
    assert "invalid choice: 'pilco_hybrid_lyapunov'" in capsys.readouterr().err


def test_the_default_reproduce_set_is_unchanged():
    default = ("linear", "linear_pilco", "ddpg_baseline", "ddpg_hybrid")
    default += ("pilco_baseline", "pilco_hybrid")
    assert DEFAULT_CONTROLLERS == default
    assert build_parser().parse_args(["reproduce"]).controllers == list(default)


def test_every_learner_has_a_hybrid_per_relevance_its_config_accepts():
    """A reproduce controller per (framework, relevance design) the framework trains, and none
    it refuses: PILCO's config refuses the Lyapunov relevance, so there is no
    ``pilco_hybrid_lyapunov``."""
    from leoc.pilco.config import PilcoConfig
    from leoc.sb3.config import DDPGConfig

    for framework in FRAMEWORKS:
        for relevance in RELEVANCE_NAMES:
            name = ControllerName(framework, relevance).name
            hybrid = ControllerSpec.from_name(name).hybrid
            try:
                if framework == "pilco":
                    PilcoConfig.for_system("pendulum", hybrid=hybrid)
                else:
                    DDPGConfig.for_system("pendulum", algo=framework, hybrid=hybrid)
            except ValueError as error:
                assert name not in CONTROLLERS, (name, error)
                assert (framework, relevance) == ("pilco", "lyapunov")
                assert "relevance" in str(error) and "'lyapunov'" in str(error)
            else:
                assert name in CONTROLLERS, name


def test_every_controller_has_a_label_a_colour_a_marker_and_hybrids_a_style():
    for name in CONTROLLERS:
        assert name in CONTROLLER_LABELS and name in CONTROLLER_COLOURS
        assert name in CONTROLLER_MARKERS
    hybrids = [name for name in CONTROLLERS if parse_controller(name).hybrid]
    assert all(name in CONTROLLER_STYLES for name in hybrids)
    for name in CONTROLLERS:
        others = [other for other in CONTROLLERS if other != name]
        assert CONTROLLER_LABELS[name] not in {CONTROLLER_LABELS[o] for o in others}
        assert CONTROLLER_COLOURS[name] not in {CONTROLLER_COLOURS[o] for o in others}
        assert CONTROLLER_MARKERS[name] not in {CONTROLLER_MARKERS[o] for o in others}
    assert CONTROLLER_LABELS["ddpg_hybrid_lyapunov"] == "DDPG hybrid (Lyapunov relevance)"
    assert CONTROLLER_LABELS["sac_hybrid_lyapunov"] == "SAC hybrid (Lyapunov relevance)"


def test_each_hybrid_of_a_framework_is_compared_with_its_baseline_in_report_order():
    from leoc.experiments.report.seeds import framework_hybrids

    assert framework_hybrids("ddpg") == ("ddpg_hybrid", "ddpg_hybrid_roa", "ddpg_hybrid_lyapunov")
    assert framework_hybrids("sac") == ("sac_hybrid", "sac_hybrid_roa", "sac_hybrid_lyapunov")
    assert framework_hybrids("pilco") == ("pilco_hybrid", "pilco_hybrid_roa")


def test_only_a_report_with_a_lyapunov_hybrid_says_what_its_relevance_is():
    """The published reports (paper and ROA hybrids) read as before; with a Lyapunov hybrid the
    header says what each relevance of the labels is, and that this one has no flat top."""
    from leoc.experiments.report.header import relevance_note

    assert relevance_note({"pendulum": {"ddpg_hybrid": [], "ddpg_hybrid_roa": []}}) == ""
    note = relevance_note({"pendulum": {"ddpg_hybrid_roa": [], "sac_hybrid_lyapunov": []}})
    assert "the ROA relevance is exactly 1 on a flat top" in note
    assert "the Lyapunov relevance is r = (1 + V~/(lambda rho))^-2" in note
    assert "(no flat top)" in note


def test_the_claims_section_says_the_lyapunov_relevance_has_no_flat_top(monkeypatch):
    """In the opening's sentence on the paper's relevance, or, should that sentence change, in a
    paragraph of its own after the heading; a study without the Lyapunov hybrid reads as
    before."""
    from leoc.experiments.report import claims
    from leoc.experiments.report.base import Report, Study

    def report(controllers):
        evaluations = {"pendulum": {name: [] for name in controllers}}
        return Report(Study(None, {}, evaluations), {}, {}, {}, [], 0.0)

    opening = ["", "## Hybrids", "", f"The ROA hybrids ...; {claims.PAPER_SENTENCE}", "", "| t |"]
    monkeypatch.setattr(claims, "hybrid_claims_section", lambda evaluations: list(opening))
    assert claims.render(report(["ddpg_hybrid", "ddpg_hybrid_roa"])) == opening
    said = claims.render(report(["ddpg_hybrid", "ddpg_hybrid_lyapunov"]))
    assert said[3] == f"The ROA hybrids ...; {claims.WITH_LYAPUNOV}" and said[4:] == opening[4:]
    other = ["", "## Hybrids", "", "Another opening.", ""]
    monkeypatch.setattr(claims, "hybrid_claims_section", lambda evaluations: list(other))
    noted = claims.render(report(["sac_hybrid_lyapunov"]))
    assert noted == ["", "## Hybrids", "", claims.LYAPUNOV_NOTE, *other[2:]]


# --------------------------------------------------------------- a report from a smoke study


@pytest.fixture(scope="module")
def smoke_study(tmp_path_factory):
    """A smoke reproduce of the pendulum's LQR, DDPG baseline and DDPG Lyapunov hybrid (about
    20 s on one worker)."""
    from leoc.experiments.reproduce import reproduce

    out = tmp_path_factory.mktemp("lyapunov_study")
    controllers = ["linear", "ddpg_baseline", "ddpg_hybrid_lyapunov"]
    path = reproduce(
        out, profile_name="smoke", systems=["pendulum"], controllers=controllers, jobs=1,
        echo=lambda _: None,
    )  # fmt: skip
    return out, path.read_text(), json.loads((out / "results.json").read_text())


@pytest.mark.heavy
def test_a_smoke_study_reports_the_lyapunov_hybrid_with_its_label(smoke_study):
    out, report, results = smoke_study
    label = "DDPG hybrid (Lyapunov relevance)"
    rows = [line for line in report.splitlines() if line.startswith(f"| pendulum | {label} |")]
    # impulse, step, robustness (mass, gravity), swing-up, ROA, the trained controllers'
    # proved regions, five seed statistics and the probability of improvement: a row in each
    # table (the robustness protocol's tables are per system, their rows without it)
    assert len(rows) == 2 + 2 + 1 + 1 + 1 + 5 + 1
    assert sum(row.split("|")[4].strip() in ("lqr", "own") for row in rows) == 1  # V kept
    # compared with its LQR (the responses check) and its baseline (probability of improvement)
    tests = {r["test"] for r in results["responses"] if r["controller"] == "ddpg_hybrid_lyapunov"}
    assert tests == {"impulse", "step"}
    assert f"| pendulum | {label} | DDPG baseline |" in report
    improvements = results["probability_of_improvement"]
    assert {r["hybrid"] for r in improvements} == {"ddpg_hybrid_lyapunov"}
    # no flat top: the header and the hybrid-claims section say so, and no comparison of the
    # Lyapunov hybrid is by construction (r = 1 at the operating point only)
    assert "the Lyapunov relevance is r = (1 + V~/(lambda rho))^-2" in report
    assert "the paper's relevance and the Lyapunov relevance" in report
    assert (
        "| pendulum | ddpg_hybrid_lyapunov | none (r < 1 off a) | evidence | evidence |" in report
    )
    run = out / "runs" / "pendulum" / "ddpg_hybrid_lyapunov" / "seed0" / "evaluation.json"
    claims = json.loads(run.read_text())["hybrid_claims"]
    assert claims["flat_top"] is None
    for name in ("responses.png", "learning_curves.png", "robustness.png", "relevance.png"):
        assert (out / name).stat().st_size > 0


def test_a_smoke_study_draws_the_lyapunov_hybrid_where_it_draws_the_roa_hybrid(smoke_study):
    """Responses, robustness, relevance and basins show the Lyapunov hybrid under its label;
    its learning curve is in results.json (the figure draws baselines and the paper's hybrids
    only, as for the ROA hybrids)."""
    from leoc.evaluation.plots.basins import draw_basins
    from leoc.evaluation.plots.robustness import draw_robustness
    from leoc.evaluation.robustness import SCALED_PARAMETERS
    from leoc.experiments.report.figures import relevance_traces

    out, _, results = smoke_study
    label = CONTROLLER_LABELS["ddpg_hybrid_lyapunov"]
    assert results["learning_curves"]["pendulum"]["ddpg_hybrid_lyapunov"]["seconds"]
    assert ("pendulum", "ddpg_hybrid_lyapunov") in relevance_traces(_evaluations(out))
    robustness = draw_robustness(
        results["robustness"], CONTROLLERS, SCALED_PARAMETERS, CONTROLLER_LABELS
    )
    legend = {text.get_text() for item in robustness.legends for text in item.get_texts()}
    assert label in legend
    basins = draw_basins(results["region_of_attraction"], CONTROLLER_LABELS)
    assert label in {tick.get_text() for tick in basins.axes[0].get_xticklabels()}


def _evaluations(out):
    from leoc.experiments.report.build import load_study

    return load_study(out).evaluations
