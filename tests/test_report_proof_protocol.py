"""The report's proved regions of the trained controllers and its robustness protocol (issue 42
item 3, issue 43 item 2): their numbers against the saved entries read by hand, what a study
without the entries says, and a smoke study that writes both (evaluated, reported, replotted)."""

from __future__ import annotations

import itertools
import json
import re
from pathlib import Path

import numpy as np
import pytest

from leoc.evaluation.plots.robustness_protocol import protocol_caption
from leoc.evaluation.robustness_protocol import CategoryResult, LevelResult, ProtocolResult
from leoc.experiments.profiles import EvaluationBudget, get_profile
from leoc.experiments.report import PROVED_REGION_CHECK, Report, Study
from leoc.experiments.report import proved_regions as proved_section
from leoc.experiments.report import robustness_protocol as protocol_section
from leoc.experiments.report.base import label
from leoc.experiments.stats import improvement_verdict

RESULTS = Path(__file__).resolve().parents[1] / "results"


# ------------------------------------------------------------------------ synthetic entries
def _proof(rho, share, lqr_share, offset=(0.0, 0.0), lyapunov="lqr", cover=None, **more):
    """A ``proved_region`` entry with the fields the section reads."""
    return {
        "rho": rho,
        "box_share": share,
        "lqr_box_share": lqr_share,
        "box_share_ratio": share / lqr_share,
        "volume_ratio": more.get("volume"),
        "offset": list(offset),
        "lyapunov": lyapunov,
        "limited_by": more.get("limit", "decrease"),
        "equilibrium_found": more.get("found", True),
        "flat_top_cover": cover,
        "flat_top_rho": None if cover is None else 2.0,
        "seconds": 1.5,
        "budget_seconds": 2.0,
        "saturation": "clip",
        **({"lqr_lyapunov": more["lqr_lyapunov"]} if "lqr_lyapunov" in more else {}),
    }


def _runs(controller: str, entries: list) -> list[dict]:
    return [
        {"spec": {"system": "pendulum", "controller": controller, "seed": seed}, "proved_region": e}
        for seed, e in enumerate(entries)
    ]


def _proof_evaluations() -> dict:
    """Three seeds of a paper-relevance hybrid (one proving less than its LQR, one with the own
    V), an ROA hybrid whose proved set lies in its flat top on two seeds of three, a baseline
    with an offset equilibrium on one seed and none found on the other, and the LQR (its entry
    None)."""
    hybrid = [
        _proof(4.0, 0.60, 0.60, volume=1.0),
        _proof(2.0, 0.30, 0.60, limit="budget", volume=0.25),
        _proof(9.0, 0.66, 0.60, lyapunov="own", volume=1.46),
    ]
    roa = [
        _proof(4.0, 0.60, 0.60, cover=0.5, lqr_lyapunov="own"),
        _proof(4.0, 0.60, 0.60, cover=1.0 + 1e-12, lqr_lyapunov="own"),
        _proof(5.0, 0.65, 0.60, cover=1.3),
    ]
    baseline = [
        _proof(1.0, 0.20, 0.60, offset=(0.03, 0.0), lyapunov="own"),
        _proof(0.0, 0.0, 0.60, found=False, limit="no equilibrium"),
    ]
    linear = [{"spec": {"system": "pendulum", "controller": "linear", "seed": 0}}]
    linear[0]["proved_region"] = None
    return {
        "pendulum": {
            "linear": linear,
            "ddpg_baseline": _runs("ddpg_baseline", baseline),
            "ddpg_hybrid": _runs("ddpg_hybrid", hybrid),
            "ddpg_hybrid_roa": _runs("ddpg_hybrid_roa", roa),
        }
    }


def _table_cells(lines: list[str]) -> dict[str, dict[str, str]]:
    """The markdown tables in ``lines`` (each under its own header row) as controller label ->
    header -> cell; a label keeps the row of the first table that has it."""
    table: dict[str, dict[str, str]] = {}
    for is_table, block in itertools.groupby(lines, lambda line: line.startswith("|")):
        if not is_table:
            continue
        header, _, *rows = list(block)
        headers = [cell.strip() for cell in header.strip("|").split("|")]
        for line in rows:
            cells = line.strip("|").split("|")
            cells = dict(zip(headers, (c.strip() for c in cells), strict=True))
            table.setdefault(cells.get("controller"), cells)
    return table


def _report(evaluations: dict, tables: dict, flags: dict | None = None) -> Report:
    study = Study(Path("."), {}, evaluations)
    return Report(study, tables, flags or {}, {}, [], 0.0)


def test_the_proved_region_table_is_the_saved_entries_read_by_hand() -> None:
    evaluations = _proof_evaluations()
    rows = proved_section.proved_region_summary(evaluations)
    tables = {"proved_regions": rows}
    flags = {"proved_regions": PROVED_REGION_CHECK.flags(rows)}
    lines = proved_section.render(_report(evaluations, tables, flags))
    cells = _table_cells(lines)
    assert set(cells) == {"DDPG baseline", "DDPG hybrid", "DDPG hybrid (ROA relevance)"}
    hybrid = cells["DDPG hybrid"]
    # by hand: rho 4, 2, 9 -> median 4 [2, 9]; shares 60%, 30%, 66%; ratios 1, 0.5, 1.1
    assert hybrid["proved rho"] == "4 [2, 9]"
    assert hybrid["share of the box"] == "60% [30%, 66%]"
    assert hybrid["LQR's share"] == "60%"
    assert hybrid["LQR's V"] == "Riccati only"  # written before the reference kept its best V
    assert hybrid["ratio to the LQR's share"] == "1x [0.5x, 1.1x]"
    assert hybrid["volume / the LQR's"] == "1x [0.25x, 1.46x]"
    assert cells["DDPG baseline"]["volume / the LQR's"] == "–"  # no run recorded it
    assert hybrid["V kept"] == "lqr 2/3, own 1/3"
    assert hybrid["limited by"] == "decrease 2/3, budget 1/3"
    assert hybrid["x* - a"] == "0"
    assert hybrid["by construction"] == "evidence"  # the paper's relevance: no flat top
    roa = cells["DDPG hybrid (ROA relevance)"]
    assert roa["LQR's V"] == "own 2/3, Riccati only 1/3"
    assert roa["by construction"] == "by construction in 2/3 seeds"  # cover 0.5, 1 + 1e-12
    assert roa["proved rho"] == "4 [4, 5]"
    baseline = cells["DDPG baseline"]
    assert baseline["x* - a"] == "theta +0.03 (none found in 1/2 seeds)"
    assert baseline["by construction"] == "–"
    assert baseline["ratio to the LQR's share"] == f"{0.2 / 0.6 / 2:.3g}x [0x, {0.2 / 0.6:.3g}x]"
    assert baseline["limited by"] == "decrease 1/2, no equilibrium 1/2"
    # the check: the hybrid's seed 1 proves half its LQR's share; the ROA hybrid keeps it; the
    # baseline is no case
    checked, failures = PROVED_REGION_CHECK.failures(rows)
    assert checked == 2
    assert [(f.subject, f.size) for f in failures] == [("pendulum DDPG hybrid", 0.5)]
    assert "limited by decrease 2/3, budget 1/3" in failures[0].flag
    assert any("**pendulum DDPG hybrid** proves as little as 0.5x" in line for line in lines)
    text = "\n".join(lines)
    assert "Budget: 2 s of box search per run" in text
    assert "the proofs took 1.5 s (median per controller)" in text
    # runs that recorded a box budget (every run since the smoke profile's 2000) say it first
    for runs in evaluations["pendulum"].values():
        for run in runs:
            if run["proved_region"] is not None:
                run["proved_region"]["budget_boxes"] = 2000
    boxed = proved_section.proved_region_summary(evaluations)
    lines = proved_section.render(_report(evaluations, {"proved_regions": boxed}, flags))
    assert "Budget: 2,000 boxes per candidate V within 2 s of box search per run" in "\n".join(
        lines
    )


def _protocol(controller: str, held: list[list[bool]], seed: int = 0) -> dict:
    """A protocol record of two categories with two levels each; ``held``: per level of both
    categories (4 lists), the operating-region episodes (the swing-up ones all fail)."""
    levels = [
        LevelResult(float(i % 2), None, {"operating_region": h, "swing_up": [False] * len(h)}, {})
        for i, h in enumerate(held)
    ]
    categories = [
        CategoryResult("observation_noise", 0.5, levels[:2]),
        CategoryResult("push", 2.0, levels[2:]),
    ]
    maxima = {"observation_noise": 0.5, "push": 2.0, "constants": ["mass"]}
    starts = {"operating_region": [[0.0, 0.0]] * 2, "swing_up": [[3.1, 0.0]] * 2}
    return ProtocolResult(
        "pendulum", controller, seed, 2, 2, 1, maxima, starts, categories
    ).as_dict()


def test_the_protocol_table_is_the_held_episodes_counted_by_hand() -> None:
    both, none_, one = [True, True], [False, False], [True, False]
    evaluations = {
        "pendulum": {
            "linear": [{"robustness_protocol": _protocol("linear", [both, one, none_, none_])}],
            "ddpg_hybrid": [
                {"robustness_protocol": _protocol("ddpg_hybrid", [both, both, both, one])},
                {"robustness_protocol": _protocol("ddpg_hybrid", [both, none_, one, one])},
            ],
        }
    }
    rows = protocol_section.protocol_summary(evaluations)
    # by hand: a category's score is held / (2 levels x 2 kinds x 2 episodes = 8)
    linear, hybrid = rows
    assert linear["scores"]["observation_noise"]["median"] == 3 / 8
    assert linear["scores"]["push"]["median"] == 0.0
    assert linear["robustness"]["median"] == (3 / 8 + 0) / 2
    assert hybrid["per_seed"][0] == {
        "observation_noise": 4 / 8,
        "push": 3 / 8,
        "robustness": 7 / 16,
    }
    assert hybrid["per_seed"][1] == {
        "observation_noise": 2 / 8,
        "push": 2 / 8,
        "robustness": 4 / 16,
    }
    cells = _table_cells(protocol_section.protocol_table(rows))
    assert cells["DDPG hybrid"]["observation noise"] == "0.38 [0.25, 0.50]"
    assert cells["DDPG hybrid"]["push"] == "0.31 [0.25, 0.38]"
    assert cells["linear (LQR at dt)"]["robustness"] == "0.19"
    # the figure's pooled result: each level holds both seeds' episodes, shares their mean
    results = protocol_section.protocol_results(evaluations)["pendulum"]["ddpg_hybrid"]
    pooled = protocol_section.pooled(results)
    assert pooled.episodes == 4
    assert pooled.scores() == pytest.approx({"observation_noise": 6 / 16, "push": 5 / 16})
    # its caption counts one run's episodes and says the bars pool the seeds' runs; the seed it
    # names is the protocol's, not a training seed
    caption = protocol_caption({"DDPG hybrid": pooled}, {"DDPG hybrid": 2})
    assert "with 2 episodes per level and start kind in each run" in caption
    assert "pools the episodes of its runs" in caption
    assert f"(protocol seed {results[0].seed})" in caption
    alone = protocol_caption({"DDPG hybrid": results[0]})
    assert "with 2 episodes per level and start kind;" in alone and "pools" not in alone
    lines = protocol_section.render(_report(evaluations, {"robustness_protocol": rows}))
    assert "Sweeps up to: observation noise 0.5, push 2 (parameter errors of mass" in "\n".join(
        lines
    )
    assert "![Robustness protocol: pendulum](robustness_protocol_pendulum.png)" in lines


def test_a_study_without_the_entries_says_they_were_not_measured() -> None:
    old = {"pendulum": {"ddpg_hybrid": [{"spec": {"seed": 0}}], "linear": [{"spec": {}}]}}
    tables = {
        "proved_regions": proved_section.proved_region_summary(old),
        "robustness_protocol": protocol_section.protocol_summary(old),
    }
    report = _report(old, tables, {"proved_regions": []})
    assert proved_section.render(report)[-1] == proved_section.NOT_MEASURED
    assert protocol_section.render(report)[-1] == protocol_section.NOT_MEASURED
    # a study of LQRs only measured the protocol and has no trained controller to prove; a
    # user's system without measured maximum levels has no protocol
    linear = {"tilted": {"linear": [{"proved_region": None, "robustness_protocol": None}]}}
    report = _report(linear, {"proved_regions": [], "robustness_protocol": []})
    assert proved_section.render(report)[-1].startswith("No trained controller in these runs")
    assert protocol_section.render(report)[-1] == protocol_section.NO_MAXIMA
    from types import SimpleNamespace

    from leoc.experiments.evaluators import evaluate_proved_region, evaluate_robustness_protocol

    user = SimpleNamespace(system=SimpleNamespace(name="tilted"), controller_name="linear")
    assert evaluate_robustness_protocol(user) is None  # rather than a failed run
    assert evaluate_proved_region(user) is None  # an LQR: its region is the roa entry's
    # the committed studies predate both: their reports say so (leoc plot regenerates them)
    for study in ("paper", "paper-authors"):
        text = (RESULTS / study / "report.md").read_text()
        assert proved_section.NOT_MEASURED in text and protocol_section.NOT_MEASURED in text


def test_profiles_budget_the_proof_and_the_protocol() -> None:
    from leoc.control.proof import MAX_BOXES, MAX_SECONDS
    from leoc.names import ROBUSTNESS_EPISODES, ROBUSTNESS_LEVELS

    paper = get_profile("paper").evaluation
    expected = EvaluationBudget(MAX_SECONDS, ROBUSTNESS_LEVELS, ROBUSTNESS_EPISODES, MAX_BOXES)
    assert paper == expected
    assert get_profile("quick").evaluation == EvaluationBudget(30.0, 5, 2)
    # the smoke study's proofs stop at a box budget: the same level on every rerun
    # (and its robustness sweep and impulse sweep on fewer points: tests/test_evaluation_budget)
    smoke = EvaluationBudget(60.0, 3, 1, 2_000, (0.5, 1.0, 5.0), 2)
    assert get_profile("smoke").evaluation == smoke
    for field, value, message in (
        ("proof_seconds", 0.0, "proof_seconds: expected a positive number, found 0.0"),
        ("proof_boxes", 0, "proof_boxes: expected an integer >= 1, found 0"),
        ("protocol_levels", 1, "protocol_levels: expected an integer >= 2, found 1"),
        ("protocol_episodes", 2.5, "protocol_episodes: expected an integer >= 1, found 2.5"),
    ):
        with pytest.raises(ValueError, match=re.escape(message)):
            EvaluationBudget(**{field: value})


# ------------------------------------------------------------------------------ smoke study
def _section(text: str, heading: str) -> list[str]:
    """The lines of ``report.md``'s section ``heading`` up to the next ``## ``."""
    lines = text.splitlines()
    start = lines.index(heading)
    end = next((i for i in range(start + 1, len(lines)) if lines[i].startswith("## ")), None)
    return lines[start:end]


@pytest.mark.slow
def test_a_smoke_study_proves_and_scores_its_controllers_and_replots_them(tmp_path) -> None:
    """One system, the LQR and an ROA hybrid at the smoke budgets: both sections and the
    figure, their numbers those of the saved entries, and ``leoc plot`` the same bytes."""
    from leoc.cli import main
    from leoc.experiments.reproduce import reproduce

    reproduce(
        tmp_path,
        profile_name="smoke",
        systems=["pendulum"],
        controllers=["linear", "ddpg_hybrid_roa"],
        jobs=1,
        echo=lambda _: None,
    )
    runs = tmp_path / "runs" / "pendulum"
    hybrid = json.loads((runs / "ddpg_hybrid_roa/seed0/evaluation.json").read_text())
    linear = json.loads((runs / "linear/seed0/evaluation.json").read_text())
    assert linear["proved_region"] is None and hybrid["proved_region"]["budget_seconds"] == 60.0
    assert hybrid["proved_region"]["budget_boxes"] == 2000
    text = (tmp_path / "report.md").read_text()
    proof = _table_cells(_section(text, "## Proved regions of the trained controllers"))
    entry = hybrid["proved_region"]
    row = proof["DDPG hybrid (ROA relevance)"]
    assert row["proved rho"] == f"{entry['rho']:.3g}"
    assert row["V kept"] == entry["lyapunov"] and row["limited by"] == entry["limited_by"]
    assert row["x* - a"] == "0"  # a hybrid's equilibrium is a
    protocol = _table_cells(_section(text, "## Robustness protocol"))
    for run in (linear, hybrid):
        record = run["robustness_protocol"]
        assert record["level_count"] == 3 and record["episodes"] == 1 and record["seed"] == 0
        # by hand: the share of every level's held episodes, per category
        for category in record["categories"]:
            held = [
                h for level in category["levels"] for kind in level["held"].values() for h in kind
            ]
            cell = protocol[label(run["spec"]["controller"])]
            assert cell[category["name"].replace("_", " ")] == f"{np.mean(held):.2f}"
    # below the scores, the verdicts: one table after the protocol's, a sentence per hybrid
    lines = _section(text, "## Robustness protocol")
    assert protocol_section.VERDICT_METHOD in lines
    assert any(
        line.startswith(f"- {label('ddpg_hybrid_roa')}: at least as robust") for line in lines
    )
    assert (tmp_path / "robustness_protocol_pendulum.png").stat().st_size > 0
    before = {name: (tmp_path / name).read_bytes() for name in ("report.md", "results.json")}
    assert main(["plot", str(tmp_path)]) == 0
    for name, content in before.items():
        assert (tmp_path / name).read_bytes() == content, name


def test_the_flat_top_cover_is_the_largest_flat_top_level_on_the_proved_set() -> None:
    """Centred on a, the bound is the exact maximum of V_flat / rho_in on the proved ellipsoid
    (sampled on its boundary here); an offset only raises it; no ROA relevance: None."""
    from types import SimpleNamespace

    import torch

    from leoc.evaluation.proved_regions import flat_top_cover
    from leoc.policies.relevance import ROARelevance
    from leoc.systems import make_system

    system = make_system("pendulum")
    flat = np.array([[4.0, 1.0], [1.0, 2.0]])
    relevance = ROARelevance(system.obs_layout, system.operating_state, flat, rho_in=0.5)
    controller = torch.nn.Sequential(relevance)
    proved_p, rho = np.array([[3.0, -0.5], [-0.5, 1.0]]), 0.2
    proved = SimpleNamespace(rho=rho, certificate=SimpleNamespace(P=proved_p))
    angles = np.linspace(0.0, 2.0 * np.pi, 20001)
    circle = np.stack([np.cos(angles), np.sin(angles)])
    boundary = np.linalg.solve(np.linalg.cholesky(proved_p).T, circle) * np.sqrt(rho)
    sampled = np.max(np.einsum("in,ij,jn->n", boundary, flat, boundary)) / 0.5
    assert flat_top_cover(controller, proved, [0.0, 0.0]) == pytest.approx(sampled, rel=1e-6)
    assert flat_top_cover(controller, proved, [0.05, 0.0]) > sampled
    assert flat_top_cover(torch.nn.Linear(3, 1), proved, [0.0, 0.0]) is None
    assert flat_top_cover(controller, SimpleNamespace(rho=0.0, certificate=None), [0, 0]) is None


def test_the_verdicts_compare_each_hybrid_with_its_lqr_and_its_baseline_by_hand() -> None:
    """Per category: the hybrid's mean score minus its LQR's, P(hybrid seed > baseline seed),
    and the verdicts, against counts made by hand; the ROA hybrid that held the LQR's very
    operating-region episodes is labelled by construction; PILCO's hybrid is compared with the
    LQR at PILCO's period (``linear_pilco``), not the step's."""
    both, none_, one = [True, True], [False, False], [True, False]
    lqr = [both, one, one, none_]  # observation noise 3/8, push 1/8

    def runs(name, helds):
        return [{"robustness_protocol": _protocol(name, held)} for held in helds]

    evaluations = {
        "pendulum": {
            "linear": runs("linear", [lqr]),
            "linear_pilco": runs("linear_pilco", [[none_] * 4]),
            # observation noise 4/8 on every seed: above the LQR's 3/8; push 2/8, 1/8, 0/8
            "ddpg_hybrid": runs(
                "ddpg_hybrid",
                [[both, both, both, none_], [both, both, one, none_]] * 1
                + [[both, both, none_, none_]],
            ),
            "ddpg_hybrid_roa": runs("ddpg_hybrid_roa", [lqr, lqr, lqr]),
            "ddpg_baseline": runs("ddpg_baseline", [[none_] * 4, [one, none_, both, both]]),
            "pilco_hybrid": runs("pilco_hybrid", [[none_] * 4] * 3),
            # a paper-relevance hybrid with its LQR's very episodes: evidence, not construction
            "sac_hybrid": runs("sac_hybrid", [lqr, lqr, lqr]),
        }
    }
    rows = protocol_section.protocol_verdicts(evaluations)
    by = {(row["controller"], row["category"]): row for row in rows}
    assert {row["controller"] for row in rows} == {
        "ddpg_hybrid",
        "ddpg_hybrid_roa",
        "pilco_hybrid",
        "sac_hybrid",
    }
    noise, push = by["ddpg_hybrid", "observation_noise"], by["ddpg_hybrid", "push"]
    assert noise["lqr"] == "linear" and noise["baseline"] == "ddpg_baseline"
    # from the operating region (the swing-up episodes all fail): the LQR holds 3/4 and 1/4
    assert noise["versus_lqr"]["difference"] == pytest.approx(4 / 4 - 3 / 4)
    assert noise["versus_lqr"]["verdict"] == "above"  # every seed above: so is every resample
    assert push["versus_lqr"]["difference"] == pytest.approx((2 + 1 + 0) / 12 - 1 / 4)
    assert push["versus_lqr"]["verdict"] == "unresolved"
    low, high = push["versus_lqr"]["ci_low"], push["versus_lqr"]["ci_high"]
    assert -1 / 4 <= low < 0 < high <= 1 / 4  # between the seeds' least and largest differences
    # the baseline's two seeds score 0/8 and 1/8 on observation noise, 0/8 and 4/8 on push;
    # P(hybrid > baseline), ties counted half: noise, 4/8 beats both on every seed -> 1
    assert noise["versus_baseline"]["probability"] == pytest.approx(1.0)
    assert noise["versus_baseline"]["verdict"] == "above (n < 3)"
    # push: hybrid 2/8, 1/8, 0/8 against 0/8, 4/8 -> wins 2, ties 1 (0 vs 0) of 6
    assert push["versus_baseline"]["probability"] == pytest.approx(2.5 / 6)
    assert push["versus_baseline"]["ci_low"] is None  # 2 baseline seeds: no interval
    assert push["versus_baseline"]["verdict"] == "below (n < 3)"
    roa = by["ddpg_hybrid_roa", "robustness"]
    assert roa["versus_lqr"]["verdict"] == "equal" and roa["operating_as_lqr"]
    assert not noise["operating_as_lqr"]
    pilco = by["pilco_hybrid", "push"]
    assert pilco["lqr"] == "linear_pilco" and pilco["baseline"] is None
    assert pilco["versus_lqr"]["verdict"] == "equal"
    lines = protocol_section.verdict_sentences([r for r in rows if r["system"] == "pendulum"])
    assert lines[0].startswith(
        f"- {label('ddpg_hybrid')}: at least as robust as its LQR (linear (LQR at dt)) in 2 of 2"
    )
    assert "by construction" in lines[1] and "by construction" not in lines[0]
    assert by["sac_hybrid", "robustness"]["operating_as_lqr"]
    assert "evidence, not construction" in lines[3] and "holds by construction" not in lines[3]
    table = "\n".join(protocol_section.verdict_table(rows))
    assert "| +0.25 [+0.25, +0.25] | above |" in table

    # lost episodes (every start; the swing-up ones all fail) at levels where the LQR lost an
    # operating-region episode (noise level 1, both push levels), by hand over the 3 seeds:
    # noise 4 lost per seed, 2 of them at level 1; push 6, 7 and 8, all where the LQR loses
    # From the operating region alone: noise none; push 2, 3 and 4 (seeds' [both, none],
    # [one, none], [none, none]), all at levels where the LQR loses operating episodes too
    def counts(lost, where, near, near_where):
        return {
            "lost": lost,
            "where_lqr_loses": where,
            "operating_lost": near,
            "operating_where_lqr_loses": near_where,
        }

    assert noise["lost"] == counts(12, 6, 0, 0)
    assert push["lost"] == counts(21, 21, 9, 9)
    assert by["ddpg_hybrid", "robustness"]["lost"] == counts(33, 27, 9, 9)
    assert (
        "27 of its 33 lost episodes were at levels where its LQR lost operating-region episodes "
        "too, 9 of the 9 it lost from the operating region" in lines[0]
    )
    assert "| above (n < 3) | 6 of 12 (0 of 0) |" in table
    # PILCO's hybrid loses all 8 operating episodes per seed, the LQR at its period every one
    assert by["pilco_hybrid", "robustness"]["lost"] == counts(48, 48, 24, 24)
    # another sweep (a level moved) is not compared level by level
    moved = ProtocolResult.from_dict(evaluations["pendulum"]["linear"][0]["robustness_protocol"])
    level = moved.categories[1].levels[0]._replace(level=0.5)
    moved.categories[1].levels[0] = level
    hybrid = ProtocolResult.from_dict(
        evaluations["pendulum"]["ddpg_hybrid"][0]["robustness_protocol"]
    )
    assert protocol_section._lost(hybrid, moved, "push") is None
    # (every start: lost, where the LQR loses; then the same from the operating region)
    assert protocol_section._lost(hybrid, moved, "observation_noise") == (4, 2, 0, 0)
    lqr_sweep = ProtocolResult.from_dict(_protocol("linear", lqr))
    assert protocol_section._lost(hybrid, lqr_sweep, "push")[2:] == (2, 2)
    # the LQR's very episodes: every level counts, the first and the last included
    same = protocol_section._same_episodes
    lqr_run = ProtocolResult.from_dict(_protocol("linear", lqr))
    assert same(ProtocolResult.from_dict(_protocol("sac_hybrid", lqr)), lqr_run, "operating_region")
    for index in (0, 3):
        changed = [list(held) for held in lqr]
        changed[index] = [not episode for episode in changed[index]]
        other = ProtocolResult.from_dict(_protocol("sac_hybrid", changed))
        assert not same(other, lqr_run, "operating_region"), index
        assert same(other, lqr_run, "swing_up")  # the swing-up episodes all fail in both
    assert not same(ProtocolResult.from_dict(_protocol("sac_hybrid", lqr)), moved, "swing_up")


def test_a_verdict_without_an_interval_whose_mean_difference_is_zero_is_unresolved() -> None:
    """The protocol's verdict against a baseline
    (:func:`leoc.experiments.stats.improvement_verdict`). Two hybrid seeds (0.75, 0.25)
    against one baseline seed (0.5): one win and one loss,
    mean difference 0 but not every score equal: neither above nor below (n < 3); a mean
    above or below 0 keeps its sign."""
    tied = improvement_verdict([0.75, 0.25], [0.5])
    assert tied["probability"] == pytest.approx(0.5)
    assert tied["verdict"] == "unresolved (n < 3)"
    assert improvement_verdict([0.75, 0.5], [0.5])["verdict"] == "above (n < 3)"
    assert improvement_verdict([0.25, 0.5], [0.5])["verdict"] == "below (n < 3)"
    assert improvement_verdict([0.5, 0.5], [0.5])["verdict"] == "equal"
