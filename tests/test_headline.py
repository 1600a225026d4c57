"""The headline table (``leoc headline``): each cell counts the report's check on one kind of
controller, against counts made by hand on small tables; the README's and the results page's
tables are what the command writes from the committed studies; the markers are checked."""

from __future__ import annotations

import json
from pathlib import Path

from leoc.cli import main
from leoc.experiments.headline import (
    BEGIN,
    CLAIMS,
    END,
    PROVED_BEGIN,
    PROVED_END,
    ROBUSTNESS_BEGIN,
    ROBUSTNESS_END,
    VERDICTS_BEGIN,
    VERDICTS_END,
    HeadlineClaim,
    claim_cell,
    headline_lines,
    load_results,
    proved_region_lines,
    robustness_lines,
    robustness_verdict_lines,
    write_headline,
)

ROOT = Path(__file__).resolve().parents[1]
STUDIES = [ROOT / "results/paper", ROOT / "results/paper-authors"]
PAGES = [ROOT / "README.md", ROOT / "docs/results.md"]


def _response(controller: str, steady: float, peak: float = 1.0) -> dict:
    """A response row of the report's table (impulse on the pendulum), settling like an LQR."""
    return {
        "system": "pendulum",
        "test": "impulse",
        "controller": controller,
        "n_runs": 5,
        "n_settled": 5,
        "n_terminated": 0,
        "steady_state_error_mean": steady,
        "overshoot_mean": 0.1,
        "peak_deviation_mean": peak,
        "settling_time_mean": 40.0,
    }


def _robust(controller: str, scale: float, share: float, parameter: str = "mass") -> dict:
    return {
        "system": "pendulum",
        "controller": controller,
        "parameter": parameter,
        "scale": scale,
        "fraction_stabilised": share,
    }


def _tables(**tables) -> dict:
    """The tables of a study with every learned controller of ``swing_up`` named."""
    controllers = ["linear", "ddpg_baseline", "ddpg_hybrid", "ddpg_hybrid_roa", "sac_hybrid"]
    return {
        "swing_up": [{"controller": c} for c in controllers],
        "responses": [],
        "robustness": [],
        "improvements": [],
        "meta": {},
        **tables,
    }


def _claim(check: str, kind: str) -> HeadlineClaim:
    return HeadlineClaim("claim", check, kind)


def test_response_cells_count_each_relevance_apart() -> None:
    # LQR steady state 0, peak 1: a steady state off by more than 1% of 1% of the peak (the
    # report's floor of a zero reference) differs. By hand: paper relevance, DDPG's 5e-5 matches
    # and SAC's 0.05 differs; the ROA hybrid matches.
    rows = [
        _response("linear", 0.0),
        _response("ddpg_hybrid", 5e-5),
        _response("sac_hybrid", 0.05),
        _response("ddpg_hybrid_roa", 0.0),
        _response("ddpg_baseline", 0.3),
    ]
    tables = _tables(responses=rows)
    paper = claim_cell(_claim("responses", "paper"), tables)
    assert paper.startswith("**partly**: 1 of 2 hybrid response tests; biggest miss: pendulum")
    assert "SAC hybrid (impulse)" in paper
    assert claim_cell(_claim("responses", "roa"), tables) == (
        "**holds**: 1 of 1 hybrid response tests"
    )
    # claim (iii): the baseline ends 0.3 off the LQR's end point: it shows
    assert claim_cell(_claim("baseline_offsets", "baseline"), tables) == (
        "**holds**: 1 of 1 baseline response tests"
    )
    rows[-1] = _response("ddpg_baseline", -5e-5)
    assert claim_cell(_claim("baseline_offsets", "baseline"), _tables(responses=rows)).startswith(
        "**fails**: 0 of 1 baseline response tests; biggest miss: pendulum DDPG baseline"
    )


def test_robustness_cells_count_only_deficits() -> None:
    # The claim is "at least as robust as its LQR": the DDPG hybrid stabilises more than the LQR
    # at x2 (holds), the SAC hybrid 30 points less at x3 (fails); by hand 1 of 2.
    rows = [
        _robust("linear", 2.0, 0.5),
        _robust("linear", 3.0, 0.5),
        _robust("ddpg_hybrid", 2.0, 0.9),
        _robust("ddpg_hybrid", 3.0, 0.5),
        _robust("sac_hybrid", 2.0, 0.5),
        _robust("sac_hybrid", 3.0, 0.2),
    ]
    cell = claim_cell(_claim("robustness", "paper"), _tables(robustness=rows))
    assert cell == (
        "**partly**: 1 of 2 hybrid x scaled-parameter sweeps; biggest miss: pendulum SAC "
        "hybrid, mass -30 pp at x3"
    )


def test_improvement_cell_counts_resolved_pairs() -> None:
    def pair(
        hybrid: str, low: float, high: float, quantity: str = "interaction time to first hold"
    ):
        return {
            "hybrid": hybrid,
            "quantity": quantity,
            "probability": 0.5,
            "ci_low": low,
            "ci_high": high,
        }

    rows = [
        pair("ddpg_hybrid", 0.6, 1.0),  # above
        pair("ddpg_hybrid_roa", 0.2, 0.9),  # unresolved
        pair("sac_hybrid", 0.0, 0.4),  # below
        pair("sac_hybrid", 0.9, 1.0, quantity="final return"),  # another quantity
    ]
    cell = claim_cell(_claim("improvements", "hybrid"), _tables(improvements=rows))
    assert cell == ("**partly**: resolved above 0.5 in 1 of 3 hybrid-baseline pairs, below in 1")
    cell = claim_cell(_claim("improvements", "hybrid"), _tables(improvements=rows[:2]))
    assert cell.startswith("**holds**: resolved above 0.5 in 1 of 2")


def test_missing_kinds_and_unmeasured_checks_are_said() -> None:
    tables = _tables(swing_up=[{"controller": "linear"}, {"controller": "ddpg_hybrid"}])
    assert claim_cell(_claim("responses", "roa"), tables) == "*no such controller in this study*"
    assert claim_cell(_claim("responses", "paper"), tables) == "*not measured*"


def test_the_committed_tables_are_what_the_command_writes() -> None:
    """README.md and docs/results.md hold ``leoc headline``'s table of the committed studies
    (run ``leoc headline --write README.md --write docs/results.md`` after republishing)."""
    lines = headline_lines([study.relative_to(ROOT) for study in STUDIES])
    assert len(lines) <= 12 + 1  # header, separator and at most 11 claims: the README's budget
    assert len(CLAIMS) == len(lines) - 2
    for page in PAGES:
        text = page.read_text(encoding="utf-8").split("\n")
        start, stop = text.index(BEGIN), text.index(END)
        assert text[start + 1 : stop] == lines, page


def test_the_json_round_trip_keeps_the_report_s_checks() -> None:
    """The headline re-runs the report's checks on results.json's rows: on every row they give
    the counts the report stored (the JSON form changes no verdict)."""
    from leoc.experiments.headline import _checks

    stored = json.loads((STUDIES[0] / "results.json").read_text(encoding="utf-8"))["checks"]
    tables = load_results(STUDIES[0])
    for name, check in _checks().items():
        if name in ("baseline_offsets", "robustness"):
            continue  # the headline's own sides of the responses and robustness rows
        summary = check.summary(tables[check.key])
        assert summary.checked == stored[name]["checked"], name
        assert [f.subject for f in summary.failures] == [
            f["subject"] for f in stored[name]["failures"]
        ], name


def test_write_needs_both_markers_and_leaves_the_file_alone_otherwise(tmp_path, capsys) -> None:
    page = tmp_path / "page.md"
    page.write_text(f"intro\n{BEGIN}\nold\n{END}\nend\n")
    assert write_headline(page, ["| a |", "|---|"])
    assert page.read_text() == f"intro\n{BEGIN}\n| a |\n|---|\n{END}\nend\n"
    assert not write_headline(page, ["| a |", "|---|"])
    bad = tmp_path / "bad.md"
    bad.write_text(f"intro\n{END}\n")
    code = main(["headline", *map(str, STUDIES), "--write", str(bad)])
    err = capsys.readouterr().err
    assert code == 2 and "--write: expected the lines" in err and "found one of them" in err
    assert bad.read_text() == f"intro\n{END}\n"
    code = main(["headline", str(tmp_path)])
    err = capsys.readouterr().err
    assert code == 2 and "study: expected a reproduce folder with a report" in err


def _between(page: Path, begin: str, end: str) -> list[str]:
    text = page.read_text(encoding="utf-8").split("\n")
    return text[text.index(begin) + 1 : text.index(end)]


def test_the_proved_region_table_joins_the_studies_reports(monkeypatch) -> None:
    """The results page's proved-region table is ``leoc headline --proved-regions`` of every
    certified study with a report, and each of its rows is the row of that study's own
    report.md (rendered when it was published) with the study's folder in front."""
    monkeypatch.chdir(ROOT)
    studies = sorted(
        p for p in Path("results").glob("certified-*") if (p / "results.json").is_file()
    )
    assert len(studies) >= 5
    lines = proved_region_lines(studies)
    assert _between(ROOT / "docs/results.md", PROVED_BEGIN, PROVED_END) == lines
    rows = lines[2:]
    for study in studies:
        report = (study / "report.md").read_text(encoding="utf-8").split("\n")
        first = next(
            i for i, line in enumerate(report) if line == lines[0].replace("| study ", "", 1)
        )
        own = []
        for line in report[first + 2 :]:  # the report's own table, after its two header lines
            if not line.startswith("|"):
                break
            own.append(line)
        expected = [f"| {study.as_posix()} {line}" for line in own]
        assert [row for row in rows if row.startswith(f"| {study.as_posix()} |")] == expected


def test_the_readme_fits_a_screen_and_its_links_resolve() -> None:
    """Issue 45: the two set-up commands (install and run the main job, run the tests, which CI
    runs) in the README's first 30 lines, its first link list within about 60, every local
    link a file of the repository."""
    import re

    lines = (ROOT / "README.md").read_text(encoding="utf-8").split("\n")
    first = lines[:30]
    assert "pip install -e . && leoc reproduce" in first
    assert 'pip install -e ".[dev]" && pytest -n auto' in first
    ci = (ROOT / ".ci/run").read_text(encoding="utf-8").split("\n")
    assert "pytest -n auto" in ci  # the README's test command is the one CI runs
    link_list = next(i for i, line in enumerate(lines) if line.startswith("- ["))
    assert link_list <= 70, link_list
    targets = re.findall(r"\]\(([^)#]+)\)", "\n".join(lines))
    assert targets and all((ROOT / target).exists() for target in targets if "://" not in target)
    guides = {p.relative_to(ROOT).as_posix() for p in (ROOT / "docs/user_guide").glob("*.md")}
    assert guides - set(targets) == set()  # every guide page is one click from the README


def _report_tables(report: list[str], header: str) -> list[str]:
    """The body rows of every table of ``report`` whose header line is ``header``, in order."""
    rows = []
    for index, line in enumerate(report):
        if line != header:
            continue
        for row in report[index + 2 :]:
            if not row.startswith("|"):
                break
            rows.append(row)
    return rows


def test_the_robustness_table_joins_the_studies_reports(monkeypatch) -> None:
    """The results page's robustness-score table is ``leoc headline --robustness`` of every
    certified study with a report; each row is a row of that study's report.md protocol tables
    (one per system) with the study's folder and the system in front, in the report's order."""
    monkeypatch.chdir(ROOT)
    studies = sorted(
        p for p in Path("results").glob("certified-*") if (p / "results.json").is_file()
    )
    lines = robustness_lines(studies)
    assert _between(ROOT / "docs/results.md", ROBUSTNESS_BEGIN, ROBUSTNESS_END) == lines
    header = lines[0].replace("| study | system ", "", 1)
    for study in studies:
        report = (study / "report.md").read_text(encoding="utf-8").split("\n")
        own = _report_tables(report, header)
        assert own, study
        mine = [row for row in lines[2:] if row.startswith(f"| {study.as_posix()} |")]
        assert [row.split(" | ", 2)[2] for row in mine] == [row[2:] for row in own], study
        systems = {row.split(" | ")[1] for row in mine}
        assert systems == set(load_results(study)["meta"]["systems"]), study


def _verdict_row(controller: str, category: str, lqr: str | None, baseline: str | None) -> dict:
    """A row of the report's ``robustness_protocol_verdicts`` with the two verdicts only."""
    return {
        "system": "pendulum",
        "controller": controller,
        "category": category,
        "versus_lqr": None if lqr is None else {"verdict": lqr},
        "versus_baseline": None if baseline is None else {"verdict": baseline},
    }


def test_the_verdict_table_pivots_each_hybrid_s_categories_by_hand() -> None:
    from leoc.experiments.report.robustness_protocol import verdict_summary_table

    rows = [
        _verdict_row("ddpg_hybrid", "push", "equal", "below"),
        _verdict_row("ddpg_hybrid", "robustness", "unresolved", "above"),
        _verdict_row("ddpg_hybrid_roa", "action_delay", None, "above (n < 3)"),
    ]
    lines = verdict_summary_table(rows, "results/x")
    header = [cell.strip() for cell in lines[0].strip("|").split("|")]
    assert header[:3] == ["study", "system", "hybrid"] and header[-2:] == ["push", "robustness"]
    assert len(header) == 3 + 9  # every category and the score, whatever the rows hold
    first = dict(zip(header, (c.strip() for c in lines[2].strip("|").split("|")), strict=True))
    assert first["hybrid"] == "DDPG hybrid"
    assert first["push"] == "equal / below" and first["robustness"] == "unresolved / above"
    assert first["action delay"] == "–"  # not in its rows
    second = dict(zip(header, (c.strip() for c in lines[3].strip("|").split("|")), strict=True))
    assert second["hybrid"] == "DDPG hybrid (ROA relevance)"
    assert second["action delay"] == "- / above (n < 3)"  # no LQR to compare with
    assert len(lines) == 4


def test_the_verdict_table_is_each_study_s_report_verdicts(monkeypatch) -> None:
    """The results page's verdict table is ``leoc headline --robustness-verdicts`` of every
    certified study; each cell is the pair of verdicts of that study's report.md verdict table
    (hybrid, category) row, read from the report's text."""
    monkeypatch.chdir(ROOT)
    studies = sorted(
        p for p in Path("results").glob("certified-*") if (p / "results.json").is_file()
    )
    lines = robustness_verdict_lines(studies)
    assert _between(ROOT / "docs/results.md", VERDICTS_BEGIN, VERDICTS_END) == lines
    header = [cell.strip() for cell in lines[0].strip("|").split("|")]
    checked = 0
    for study in studies:
        report = (study / "report.md").read_text(encoding="utf-8").split("\n")
        pairs = {}
        for line in report:
            cells = [cell.strip() for cell in line.strip("|").split("|")]
            if len(cells) == 7 and cells[1] in {h for h in header[3:]}:
                pairs[cells[0], cells[1]] = f"{cells[3]} / {cells[5]}"
        for row in lines[2:]:
            cells = dict(zip(header, (c.strip() for c in row.strip("|").split("|")), strict=True))
            if cells["study"] != study.as_posix():
                continue
            for category in header[3:]:
                if cells[category] != "–":
                    assert cells[category] == pairs[cells["hybrid"], category], (study, category)
                    checked += 1
    assert checked >= 9 * 2 * 5  # nine cells per hybrid, two hybrids in most of the studies


def test_one_cross_study_table_at_a_time(capsys) -> None:
    assert main(["headline", "--robustness", "--robustness-verdicts"]) == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert "--robustness, --robustness-verdicts: expected one table at a time, found 2" in line


def test_the_results_page_s_reading_of_the_verdicts_holds(monkeypatch) -> None:
    """The sentences under the results page's verdict table: no DDPG, SAC or TD3 hybrid is
    below its LQR in any cell but pushes on the cart-pole (the DDPG and TD3 hybrids and the SAC
    ROA hybrid, not the SAC default-relevance hybrid; the TD3 default-relevance hybrid in the
    score too), every PILCO hybrid is (the pendulum's in four categories and the score, the
    mountain car's under pushes and in the score, the cart-pole's under pushes), and the
    overall score against the baseline is above only for the pendulum SAC ROA hybrid."""
    monkeypatch.chdir(ROOT)
    lines = _between(ROOT / "docs/results.md", VERDICTS_BEGIN, VERDICTS_END)
    header = [cell.strip() for cell in lines[0].strip("|").split("|")]
    below_lqr, above_overall = {}, []
    for row in lines[2:]:
        cells = dict(zip(header, (c.strip() for c in row.strip("|").split("|")), strict=True))
        pairs = {name: cells[name].split(" / ") for name in header[3:]}
        below_lqr[cells["system"], cells["hybrid"]] = [
            name for name, pair in pairs.items() if pair[0] == "below"
        ]
        if pairs["robustness"][1] == "above":
            above_overall.append((cells["study"], cells["hybrid"]))
    pilco = {key: names for key, names in below_lqr.items() if key[1].startswith("PILCO")}
    others = {key: names for key, names in below_lqr.items() if key not in pilco and names}
    cart_pole = {
        ("cartpole", "DDPG hybrid"),
        ("cartpole", "DDPG hybrid (ROA relevance)"),
        ("cartpole", "SAC hybrid (ROA relevance)"),
        ("cartpole", "TD3 hybrid"),
        ("cartpole", "TD3 hybrid (ROA relevance)"),
    }
    assert set(others) == cart_pole
    assert others.pop(("cartpole", "TD3 hybrid")) == ["push", "robustness"]
    assert all(names == ["push"] for names in others.values())
    assert all(pilco.values())
    for hybrid in ("PILCO hybrid", "PILCO hybrid (ROA relevance)"):
        assert len(pilco[("pendulum", hybrid)]) == 5
        assert pilco[("mountaincar", hybrid)] == ["push", "robustness"]
        assert pilco[("cartpole", hybrid)] == ["push"]
    assert above_overall == [("results/certified-pendulum-sac", "SAC hybrid (ROA relevance)")]
