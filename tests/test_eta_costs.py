"""Tests of the ETA's expected run costs (``leoc.experiments.profiles``' tables): they equal the
published studies' measured medians (``leoc.experiments.eta.measured_run_seconds``), so they
cannot go stale silently; a profile takes the table of the variant it runs under; replayed on
those studies, the ETA is right from the first report."""

from __future__ import annotations

import json
import statistics
from pathlib import Path

import pytest

from leoc.experiments.eta import (
    COST_DECIMALS,
    Finished,
    measured_learner_seconds,
    measured_run_seconds,
    replay,
)
from leoc.experiments.profiles import (
    AUTHORS_RUN_SECONDS,
    FALLBACK_RUN_SECONDS,
    PAPER_RUN_SECONDS,
    RunSpec,
    get_profile,
    run_specs,
)

RESULTS = Path(__file__).resolve().parents[1] / "results"
ROUNDING_S = 0.5 * 10.0**-COST_DECIMALS
STUDY_TABLES = [("paper", PAPER_RUN_SECONDS), ("paper-authors", AUTHORS_RUN_SECONDS)]
REPORT_INTERVAL_S = 15.0  # the sweep's progress reports
REPORTS_PROGRESS = ("ddpg", "sac")  # learners whose log says the fraction done
# The replayed ETA's largest error (relative to the time left), at the first report and the
# median over the reports; the stale table gave +48% / 16% (results/paper) and +182% / 22%
# (results/paper-authors).
FIRST_REPORT_ERROR = 0.05
MEDIAN_ERROR = 0.05


@pytest.mark.parametrize(("study", "table"), STUDY_TABLES, ids=[s for s, _ in STUDY_TABLES])
def test_committed_cost_tables_equal_the_published_studies(study, table) -> None:
    """Regenerate with ``python benchmarks/bench_eta_costs.py`` when a study is republished."""
    measured = measured_run_seconds(RESULTS / study)
    assert set(table) == set(measured)
    for kind, seconds in measured.items():
        assert table[kind] == pytest.approx(seconds, abs=ROUNDING_S), kind


def test_fallback_costs_are_each_learners_median_in_leocs_study() -> None:
    measured = measured_learner_seconds(RESULTS / "paper")
    assert set(FALLBACK_RUN_SECONDS) == set(measured)
    for learner, seconds in measured.items():
        assert FALLBACK_RUN_SECONDS[learner] == pytest.approx(seconds, abs=ROUNDING_S), learner


def _write_run(folder: Path, system: str, controller: str, seed: int, wall: float) -> None:
    run = folder / "runs" / system / controller / f"seed{seed}"
    run.mkdir(parents=True)
    spec = {"system": system, "controller": controller, "seed": seed}
    (run / "evaluation.json").write_text(json.dumps({"spec": spec, "wall_seconds": wall}))


def test_measured_costs_are_medians_over_seeds_in_the_folders_order(tmp_path) -> None:
    meta = {"systems": ["pendulum", "cartpole"], "controllers": ["linear", "pilco_hybrid"]}
    (tmp_path / "meta.json").write_text(json.dumps(meta))
    for seed, wall in enumerate([10.0, 300.0, 11.04]):  # one slow seed: the median ignores it
        _write_run(tmp_path, "cartpole", "pilco_hybrid", seed, wall)
    _write_run(tmp_path, "pendulum", "linear", 0, 0.96)
    costs = measured_run_seconds(tmp_path)
    assert costs == {"pendulum/linear": 1.0, "cartpole/pilco_hybrid": 11.0}
    assert list(costs) == ["pendulum/linear", "cartpole/pilco_hybrid"]  # meta's order
    assert measured_learner_seconds(tmp_path) == {"linear": 1.0, "pilco": 11.0}
    with pytest.raises(ValueError, match="folder: expected finished runs"):
        measured_run_seconds(tmp_path / "empty")


def test_a_profile_is_costed_by_its_variants_study() -> None:
    paper = get_profile("paper")
    authors = paper.for_variant("authors")
    for kind, seconds in AUTHORS_RUN_SECONDS.items():
        system, controller = kind.split("/")
        assert authors.training_seconds(RunSpec(system, controller, 0)) == seconds
    # kinds the authors' study did not run keep leoc's costs
    for kind in ("cartpole/sac_hybrid", "pendulum/ddpg_hybrid_roa"):
        system, controller = kind.split("/")
        assert authors.training_seconds(RunSpec(system, controller, 0)) == PAPER_RUN_SECONDS[kind]
    assert paper.for_variant("leoc") is paper
    assert (
        get_profile("quick").for_variant("authors").run_seconds is get_profile("quick").run_seconds
    )
    assert paper.run_seconds is PAPER_RUN_SECONDS  # the profile itself is left as it was


def test_reproduce_gives_the_eta_its_variants_costs(tmp_path, monkeypatch) -> None:
    """Where ``leoc reproduce`` meets the profile and the variant: the sweep's cost model."""
    from leoc.experiments import reproduce as module

    given = {}

    class Stop(Exception):
        pass

    def fake_sweep(specs, runner, out, **options):
        given.update(options, specs=specs)
        raise Stop

    monkeypatch.setattr(module, "sweep", fake_sweep)
    with pytest.raises(Stop):
        module.reproduce(
            tmp_path,
            "paper",
            jobs=1,
            seeds=1,
            systems=("cartpole",),
            controllers=("pilco_baseline",),
            echo=lambda _line: None,
            variant="authors",
        )
    spec = RunSpec("cartpole", "pilco_baseline", 0)
    assert given["specs"] == [spec]
    proof_and_protocol = get_profile("paper").evaluation_cost(spec)
    assert proof_and_protocol > 0
    assert given["expected_seconds"](spec) == (
        AUTHORS_RUN_SECONDS["cartpole/pilco_baseline"] + proof_and_protocol
    )


def _replayed_errors(study: str) -> list[float]:
    """The relative error of each ETA report, the study's runs replayed in ``leoc reproduce``'s
    order under the profile of its variant (as benchmarks/bench_eta_costs.py)."""
    folder = RESULTS / study
    meta = json.loads((folder / "meta.json").read_text())
    profile = get_profile(meta["profile"], len(meta["seeds"])).for_variant(meta["variant"])
    walls = {}
    for path in folder.glob("runs/*/*/seed*/evaluation.json"):
        data = json.loads(path.read_text())
        walls[RunSpec(**data["spec"])] = data["wall_seconds"]
    specs = run_specs(profile, tuple(meta["systems"]), tuple(meta["controllers"]))
    # the published studies ran before the proof and the protocol: their costs without them
    runs = [Finished(profile.training_seconds(spec), walls[spec], spec.framework) for spec in specs]
    points = replay(runs, meta["jobs"], REPORT_INTERVAL_S, REPORTS_PROGRESS)
    return [(point.eta - point.remaining) / point.remaining for point in points]


@pytest.mark.parametrize("study", [s for s, _ in STUDY_TABLES])
def test_the_replayed_eta_is_right_from_the_first_report(study) -> None:
    """In sample (the tables are these runs' medians): what it measures is that each variant
    is costed by its own, current table, not how a new machine's runs will go."""
    errors = _replayed_errors(study)
    assert abs(errors[0]) < FIRST_REPORT_ERROR
    assert statistics.median(abs(error) for error in errors) < MEDIAN_ERROR
