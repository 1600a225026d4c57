"""Tests of the report's aggregation on synthetic run results: flags and seed statistics."""

from __future__ import annotations

import numpy as np
import pytest

from leoc.evaluation.metrics import response_metrics
from leoc.experiments.report import (
    RESPONSE_CHECK,
    ROA_CHECK,
    ROBUSTNESS_CHECK,
    SWING_UP_CHECK,
    code_line,
    code_versions,
    improvement_rows,
    improvement_table,
    response_summary,
    seed_statistics,
    swing_up_summary,
    swing_up_table,
)
from leoc.experiments.stats import iqm, percent


def _run(controller: str, seed: int, scale: float, final_return: float, held: bool) -> dict:
    e = scale * 0.9 ** np.arange(201.0)
    metrics = response_metrics(e, dt=0.05)._asdict()
    return {
        "spec": {"system": "pendulum", "controller": controller, "seed": seed},
        "action_repeat": 1,
        "responses": {
            test: {"metrics": metrics, "deviation": e.tolist()} for test in ("impulse", "step")
        },
        "swing_up": {
            "returns": [final_return] * 2,
            "hold_steps": [10, 12] if held else [None, None],
            "mean_return": final_return,
            "held_fraction": 1.0 if held else 0.0,
        },
        "curve": {
            "seconds": [0.0, 10.0, 20.0],
            "returns": [-1500.0, -800.0, final_return],
            "held_fraction": [0.0, 1.0 if held else 0.0, 1.0 if held else 0.0],
        },
    }


def _evaluations(hybrid_scale: float, seeds: int = 3) -> dict:
    return {
        "pendulum": {
            "linear": [_run("linear", 0, 1.0, -1500.0, False)],
            "ddpg_baseline": [
                _run("ddpg_baseline", s, 3.0, -300.0 - s, s > 0) for s in range(seeds)
            ],
            "ddpg_hybrid": [
                _run("ddpg_hybrid", s, hybrid_scale, -200.0 - s, True) for s in range(seeds)
            ],
        }
    }


def test_a_hybrid_is_flagged_only_beyond_one_percent_of_its_linear_reference():
    close = RESPONSE_CHECK.flags(response_summary(_evaluations(1.005)))
    assert close == []
    far = RESPONSE_CHECK.flags(response_summary(_evaluations(1.02)))
    assert len(far) == 2  # impulse and step
    assert "DDPG hybrid" in far[0] and "peak deviation" in far[0] and "linear (LQR at dt)" in far[0]


def test_controllers_that_do_not_swing_up_are_flagged_by_name():
    rows = swing_up_summary(_evaluations(1.0))
    flags = SWING_UP_CHECK.flags(rows)
    assert len(flags) == 1 and "DDPG baseline" in flags[0] and "67%" in flags[0]  # 4 of 6 held
    # 2 of 3 runs hold in every episode: Clopper-Pearson [B(0.025; 2, 2), B(0.975; 3, 1)]
    # = [0.0943, 0.975^(1/3)]
    table = swing_up_table(rows)
    baseline = next(line for line in table if "DDPG baseline" in line)
    assert "| 2/3 | [9%, 99%] |" in baseline


def test_a_flag_never_rounds_a_miss_to_100_percent():
    """A hybrid that lost 1 of 2000 certified starts was flagged as holding "only 100%"."""
    row = {"system": "pendulum", "controller": "pilco_hybrid_roa", "certified_set_held": 0.9995}
    (flag,) = ROA_CHECK.flags([row, {**row, "certified_set_held": 1.0}])
    assert "holds only 99.95% of the starts" in flag
    assert [percent(x) for x in (1.0, 0.0, 0.98, 0.0215, 4e-5, 1 - 1e-7, 1e-9)] == [
        "100%",
        "0%",
        "98%",
        "2%",
        "0.004%",
        "> 99.999%",
        "< 0.001%",
    ]


def test_robustness_flags_compare_stabilised_fractions():
    rows = [
        {
            "system": "pendulum",
            "controller": c,
            "parameter": "mass",
            "scale": 2.0,
            "fraction_stabilised": f,
        }
        for c, f in (("linear", 1.0), ("ddpg_hybrid", 0.6), ("ddpg_baseline", 0.0))
    ]
    flags = ROBUSTNESS_CHECK.flags(rows)
    assert len(flags) == 1 and "x2 (60% vs 100%)" in flags[0] and "DDPG hybrid" in flags[0]


def test_seed_statistics_with_three_seeds_have_intervals_and_with_one_do_not():
    rows = seed_statistics(_evaluations(1.0, seeds=3))
    final = next(
        r for r in rows if (r["controller"], r["quantity"]) == ("ddpg_hybrid", "final return")
    )
    assert final["iqm"] == pytest.approx(iqm(np.array([-200.0, -201.0, -202.0])))
    assert final["ci_low"] <= final["iqm"] <= final["ci_high"] and final["n"] == 3
    first_hold = next(
        r
        for r in rows
        if (r["controller"], r["quantity"])
        == ("ddpg_baseline", "interaction time to first hold [s]")
    )
    assert (first_hold["n"], first_hold["n_missing"]) == (2, 1)  # seed 0 never held
    single = seed_statistics(_evaluations(1.0, seeds=1))
    assert all(r["ci_low"] is None and r["ci_high"] is None for r in single)
    assert {r["note"] for r in single} == {"n = 1 < 3: no interval", "no values"}
    assert not any(r["controller"] == "linear" for r in rows)


def test_probability_that_the_hybrid_beats_its_baseline():
    evaluations = _evaluations(1.0, seeds=3)
    final, sooner = improvement_rows(evaluations)
    assert (final["hybrid"], final["quantity"]) == ("ddpg_hybrid", "final return")
    assert final["probability"] == 1.0  # every hybrid run is better
    # first hold: every hybrid run at 10 s; the baseline's seed 0 never holds (a win for each
    # hybrid run), seeds 1 and 2 at 10 s (ties, half each): (3 + 3) / 9
    assert sooner["quantity"] == "interaction time to first hold"
    assert sooner["probability"] == pytest.approx(6 / 9)
    # the ROA hybrid is compared with the same baseline; a hybrid that never holds loses
    evaluations["pendulum"]["ddpg_hybrid_roa"] = [
        _run("ddpg_hybrid_roa", s, 1.0, -400.0, False) for s in range(3)
    ]
    rows = improvement_rows(evaluations)
    roa = {r["quantity"]: r["probability"] for r in rows if r["hybrid"] == "ddpg_hybrid_roa"}
    # never against never (seed 0) ties: 3 * 0.5 / 9
    assert roa == {"final return": 0.0, "interaction time to first hold": pytest.approx(1.5 / 9)}
    table = improvement_table(rows)
    # the interval's ends: a baseline resample of seed 0 only (P = 1), of seeds 1 and 2 only (the
    # hybrid ties every run: P = 0.5)
    row = "| pendulum | DDPG hybrid | DDPG baseline | 1.00 | [1, 1] | 0.67 | [0.5, 1] |"
    assert table[2] == row


def test_a_run_folder_without_its_machine_says_so():
    from leoc.experiments.report import machine_line

    assert machine_line(None).startswith("Machine: not recorded")
    line = machine_line({"cpu": "AMD EPYC", "logical_cpus": 2, "platform": "Linux-6"})
    assert line == "Machine of the last invocation: AMD EPYC, 2 logical CPUs, Linux-6."
    line = machine_line(
        {
            "cpu": "AMD EPYC",
            "logical_cpus": 2,
            "platform": "Linux-6",
            "torch_cpu_capability": "AVX2",
        }
    )
    assert line == (
        "Machine of the last invocation: AMD EPYC, 2 logical CPUs, Linux-6, torch's AVX2 kernels."
    )


def test_runs_from_several_code_versions_are_said_plainly():
    evaluations = _evaluations(1.0)
    one = code_versions(evaluations)
    assert one == {
        "unknown": [
            "pendulum/linear/seed0",
            *[f"pendulum/ddpg_baseline/seed{s}" for s in range(3)],
            *[f"pendulum/ddpg_hybrid/seed{s}" for s in range(3)],
        ]
    }
    for index, run in enumerate(evaluations["pendulum"]["ddpg_hybrid"]):
        run["versions"] = {"leoc_commit": "abc" if index else "def+dirty"}
    for run in [*evaluations["pendulum"]["linear"], *evaluations["pendulum"]["ddpg_baseline"]]:
        run["versions"] = {"leoc_commit": "abc"}
    mixed = code_versions(evaluations)
    assert {c: len(r) for c, r in mixed.items()} == {"abc": 6, "def+dirty": 1}
    assert mixed["def+dirty"] == ["pendulum/ddpg_hybrid/seed0"]
    assert code_line(mixed).startswith("**Code: the runs come from 2 different leoc versions**")
    evaluations["pendulum"]["ddpg_hybrid"][0]["versions"] = {"leoc_commit": "abc"}
    assert code_line(code_versions(evaluations)) == "Code: all 7 runs from leoc commit `abc`."


def _cells(line: str) -> list[str]:
    return line.strip().strip("|").split("|")


@pytest.mark.parametrize("test", ["impulse", "step"])
def test_response_tables_have_as_many_cells_as_headers(test):
    from leoc.experiments.report import response_table

    evaluations = _evaluations(1.0)
    evaluations["pendulum"]["linear_pilco"] = [_run("linear_pilco", 0, 1.0, -1500.0, False)]
    evaluations["pendulum"]["pilco_hybrid"] = [_run("pilco_hybrid", 0, 1.0, -200.0, True)]
    lines = response_table(response_summary(evaluations), test)
    header, rule, *rows = [line for line in lines if line.startswith("|")]
    width = len(_cells(header))
    assert width == (13 if test == "impulse" else 10)  # the paper gives impulse numbers only
    assert len(_cells(rule)) == width
    assert len(rows) == 5 and all(len(_cells(row)) == width for row in rows)
    assert not any(cell.strip() == "" for row in rows for cell in _cells(row))
    if test == "impulse":
        by_controller = {_cells(row)[1].strip(): _cells(row)[-3:] for row in rows}
        # the paper's single linear row is the LQR at dt's, not repeated for PILCO's period
        assert [c.strip() for c in by_controller["linear (LQR at dt)"]] == [
            "-2.95e-13 ± 0",
            "0.45 ± 0",
            "26 ± 0",
        ]
        assert [c.strip() for c in by_controller["linear (LQR at PILCO's period)"]] == ["-"] * 3
        # the paper prints a negative std for the PILCO hybrid's steady-state error
        assert by_controller["PILCO hybrid"][0].strip() == "-3.13e-13 ± 2.33e-16*"
        assert lines[-1].startswith("* The paper prints this standard deviation with a minus")


def test_a_hybrid_that_never_settles_is_flagged_with_a_dash_not_nan():
    evaluations = _evaluations(1.0)
    hybrid = evaluations["pendulum"]["ddpg_hybrid"]
    wobble = 2.0 * np.sin(np.arange(201.0))
    for run in hybrid:
        metrics = response_metrics(wobble, dt=0.05)._asdict()
        run["responses"]["impulse"] = {"metrics": metrics, "deviation": wobble.tolist()}
    (flag,) = [f for f in RESPONSE_CHECK.flags(response_summary(evaluations)) if "(impulse)" in f]
    assert "settling time - vs " in flag and "nan" not in flag


def test_the_end_of_run_summary_is_one_line_per_check_and_sums_the_invocations(tmp_path):
    """The terminal summary printed "impulse/step responses: 12 (" and six names on wrapped
    lines; now one line per check with its count and worst failure, and the wall time of every
    invocation."""
    import json

    from leoc.experiments.summary import summary_lines

    (tmp_path / "meta.json").write_text(
        json.dumps(
            {
                "systems": ["pendulum"],
                "controllers": ["linear", "ddpg_hybrid", "ddpg_hybrid_roa", "sac_hybrid"],
                "wall_seconds_last_invocation": 0.4,
                "invocations": [{"wall_seconds": 61.2}, {"wall_seconds": 0.4}],
            }
        )
    )
    evaluations = _evaluations(1.02)
    evaluations["pendulum"]["ddpg_hybrid_roa"] = [
        _run("ddpg_hybrid_roa", s, 1.5, -250.0, True) for s in range(3)
    ]
    responses = response_summary(evaluations)
    checks = {
        "responses": RESPONSE_CHECK.summary(responses).to_json(),
        "swing_up": SWING_UP_CHECK.summary(swing_up_summary(evaluations)).to_json(),
    }
    (tmp_path / "results.json").write_text(json.dumps({"responses": responses, "checks": checks}))
    assert summary_lines(tmp_path) == [
        "Finished: 4 system/controller pairs in the report; wall time 62 s over 2 invocations "
        "(the last 0 s).",
        "Without results (failed; see their train.log): pendulum/sac_hybrid.",
        "Checks failed/checked, the worst failure of each (report.md lists all):",
        "  impulse/step responses      4/4  worst: pendulum DDPG hybrid (ROA relevance) "
        "(impulse) off by 50%",
        "  swing-up                    1/3  worst: pendulum DDPG baseline 67% held",
        f"Report: {tmp_path / 'report.md'} (figures and CSV files beside it).",
        f"Redraw after a change: leoc plot {tmp_path}",
    ]


def test_a_flagged_response_smaller_than_one_percent_of_the_peak_is_not_called_zero():
    """The cart-pole PILCO hybrid's step overshoot, 1.27 against its LQR's 1.29 (1.6% of the
    overshoot, so flagged), is 0.6% of the peak deviation 3.22: the summary said 'off by 0%'."""
    from leoc.experiments.report.responses import _size_text

    assert [_size_text(s) for s in (0.02 / 3.22, 0.0004, 0.03, 0.5, 32.4)] == [
        "0.62%",
        "0.04%",
        "3%",
        "50%",
        "32x",
    ]


# ------------------------------------------------------------------------------ the summary
def _sizes_in_order(line: str) -> list[float]:
    """The response sizes a summary line names, in its order (``off by 50%``)."""
    import re

    return [float(found) for found in re.findall(r"off by ([\d.]+)%", line)]


def test_the_summary_says_what_worked_and_what_failed_biggest_first():
    from leoc.experiments.summary import summary_markdown

    evaluations = _evaluations(1.02)  # the DDPG hybrid 2% off its LQR's peak deviation
    evaluations["pendulum"]["ddpg_hybrid_roa"] = [
        _run("ddpg_hybrid_roa", s, 1.5, -250.0, True) for s in range(3)
    ]  # 50% off
    evaluations["pendulum"]["linear_pilco"] = [_run("linear_pilco", 0, 1.0, -1500.0, False)]
    evaluations["pendulum"]["pilco_hybrid"] = [_run("pilco_hybrid", 0, 1.0, -200.0, True)]
    swing_up = swing_up_summary(evaluations)
    checks = {
        "responses": RESPONSE_CHECK.summary(response_summary(evaluations)).to_json(),
        "swing_up": SWING_UP_CHECK.summary(swing_up).to_json(),
        "robustness": ROBUSTNESS_CHECK.summary([]).to_json(),
        "roa": ROA_CHECK.summary([]).to_json(),
    }
    lines = summary_markdown(checks, ["pendulum/sac_hybrid"])
    assert len(lines) <= 15 and lines[0] == "## Summary"
    worked = lines.index("**What worked:**")
    # 2 of 6 response tests match (the PILCO hybrid's), 3 of 4 learned controllers hold
    assert lines[worked + 1] == (
        "- impulse/step responses: 2 of 6 hybrid response tests match their LQR."
    )
    assert lines[worked + 2] == (
        "- swing-up: 3 of 4 learned controllers swing up and hold in every episode."
    )
    (responses,) = [line for line in lines if line.startswith("- **impulse/step responses**")]
    assert "4 of 6 hybrid response tests; biggest: pendulum DDPG hybrid (ROA relevance)" in (
        responses
    )
    assert _sizes_in_order(responses) == [50.0, 50.0, 2.0]  # biggest first, 1 more untold
    assert responses.endswith("; 1 more in its section.")
    assert "threshold: each metric within 1% of the LQR's" in responses
    (swing,) = [line for line in lines if line.startswith("- **swing-up**")]
    assert "1 of 4 learned controllers; biggest: pendulum DDPG baseline 67% held." in swing
    assert lines[-2] == "- **runs without results** (failed or not run yet): 1."
    # the section keeps its full list in the order of its table
    flags = RESPONSE_CHECK.flags(response_summary(evaluations))
    assert [flag.split("**")[1] for flag in flags] == [
        "pendulum DDPG hybrid",
        "pendulum DDPG hybrid (ROA relevance)",
        "pendulum DDPG hybrid",
        "pendulum DDPG hybrid (ROA relevance)",
    ]


def test_a_summary_of_every_check_passing_says_so_in_few_lines():
    from leoc.experiments.summary import summary_markdown

    lines = summary_markdown({"responses": RESPONSE_CHECK.summary([]).to_json()}, [])
    assert lines == ["## Summary", "", "**What failed:** nothing; every check passed.", ""]


def test_the_summary_of_many_failures_keeps_to_its_line_limit():
    from leoc.experiments.summary import (
        FLAG_SECTIONS,
        SUMMARY_MAX_LINES,
        Failure,
        check_summary,
        summary_markdown,
    )

    def check(count: int) -> dict:
        failures = [Failure(f"case {k}", float(k), f"{k} units", "", "") for k in range(count)]
        return check_summary(
            count + 1, failures, cases="cases", threshold="0 units", worked="pass"
        ).to_json()

    checks = {key: check(30) for key in FLAG_SECTIONS}  # every check of the report
    lines = summary_markdown(checks, [f"pendulum/c{k}" for k in range(20)])
    assert len(lines) <= SUMMARY_MAX_LINES == 17
    failed = [line for line in lines if line.startswith("- **") and "threshold" in line]
    assert len(failed) == len(FLAG_SECTIONS) == 5
    assert all(
        "biggest: case 29 29 units; case 28 28 units; case 27 27 units;" in line for line in failed
    )
    assert all(line.endswith("; 27 more in its section.") for line in failed)


def _selection_run(controller: str, seed: int, selection: str | None) -> dict:
    run = _run(controller, seed, 1.0, -200.0, True)
    if selection is not None:
        run["curve"]["model_selection"] = selection
    return run


def test_the_model_selection_sentence_comes_from_what_the_runs_recorded():
    from leoc.experiments.report import model_selection_text

    evaluations = {
        "pendulum": {
            "linear": [_run("linear", 0, 1.0, -1500.0, False)],
            "ddpg_hybrid": [_selection_run("ddpg_hybrid", s, "best_held") for s in range(3)],
            "pilco_hybrid": [
                _selection_run("pilco_hybrid", 0, "final"),
                _selection_run(
                    "pilco_hybrid", 1, "best evaluation of iterations >= 6 (iteration 8)"
                ),
                _selection_run(
                    "pilco_hybrid", 2, "best evaluation of iterations >= 6 (iteration 7)"
                ),
            ],
            "sac_baseline": [_selection_run("sac_baseline", 0, None)],
        }
    }
    text = model_selection_text(evaluations)
    assert text.startswith("Model selection, as each run recorded it: DDPG (3 runs): `best_held`, ")
    assert "PILCO (1 run): `final`, the final controller" in text
    # a PILCO selection's iteration differs per run: one rule, two runs
    assert "PILCO (2 runs): best evaluation of iterations >= 6;" in text
    assert "SAC (1 run): not recorded." in text
    assert "optimistic" in text and "no selection" not in text
    final_only = {"pendulum": {"pilco_hybrid": [_selection_run("pilco_hybrid", 0, "final")]}}
    text = model_selection_text(final_only)
    assert text == (
        "Model selection, as each run recorded it: PILCO (1 run): `final`, the final "
        "controller (at the end of its training budget)."
    )


def test_markdown_tables_have_a_separator_per_column_and_refuse_ragged_rows():
    from leoc.experiments.markdown import markdown_table

    assert markdown_table(["a", "b"], [["1", ""]]) == ["| a | b |", "|---|---|", "| 1 |  |"]
    assert markdown_table(["a", "b"], [], align=["left", "right"])[1] == "|:---|---:|"
    with pytest.raises(ValueError, match="expected 2 cells in row 0, found 1"):
        markdown_table(["a", "b"], [["1"]])
    with pytest.raises(ValueError, match="align"):
        markdown_table(["a", "b"], [], align="middle")


def test_every_section_renders_and_each_check_flags_its_own_table():
    from leoc.experiments.report import SECTIONS

    keys = [section.check.key for section in SECTIONS if section.check is not None]
    assert keys == ["responses", "robustness", "swing_up", "roa", "proved_regions"]
    assert all(callable(section.render) for section in SECTIONS)


@pytest.mark.parametrize(
    ("controllers", "expected"),
    [
        (["linear", "sac_hybrid"], "SAC hybrids with *linear (LQR at dt)*"),
        (["pilco_hybrid"], "PILCO hybrids with *linear (LQR at PILCO's period)*"),
        (
            ["ddpg_hybrid", "td3_baseline", "pilco_hybrid_roa"],
            "DDPG and TD3 hybrids with *linear (LQR at dt)*, PILCO hybrids with *linear (LQR at "
            "PILCO's period)*",
        ),
        (
            ["linear"],
            "DDPG, TD3 and SAC hybrids with *linear (LQR at dt)*, PILCO hybrids with *linear "
            "(LQR at PILCO's period)*",
        ),
    ],
)
def test_report_header_names_only_the_learners_it_has(controllers, expected):
    """The header's LQR-per-period sentence lists the learners present (a SAC-only study once
    said 'DDPG and SAC hybrids'); an LQR-only report states every learner's rule."""
    from leoc.experiments.report.header import _period_comparisons

    evaluations = {"pendulum": {name: [] for name in controllers}}
    assert _period_comparisons(evaluations) == expected
