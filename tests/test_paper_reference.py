"""The stored paper values equal the numbers printed in the paper's LaTeX source, every one of them.

The numbers are re-read here from the paper's tabular rows (``<shared>/paper``, beside the shared
data), not copied: a value typed wrong in ``paper_reference.json`` fails these tests.
"""

from __future__ import annotations

import re
from collections import defaultdict
from pathlib import Path

import pytest

from conftest import shared_data_dir
from solarchain_eval.report.against_paper.paper_findings import holds
from solarchain_eval.report.against_paper.paper_reference import (
    paper_findings,
    paper_findings_values,
    paper_tables,
    paper_value,
    paper_values,
    printed_row,
    ref_of,
)

PAPER_TEX = "solarchain_eval_paper.tex"
NUMBER = r"-?\d+(?:\.\d+)?"
#: A cell's numbers and the part each one is: "a $\pm$ b", "a (b--c)", "a--b", "a".
CELL_FORMS = (
    (rf"({NUMBER}) \$\\pm\$ ({NUMBER})", ("mean", "std")),
    (rf"({NUMBER}) \(({NUMBER})--({NUMBER})\)", ("mean", "p05", "p95")),
    (rf"({NUMBER})--({NUMBER})", ("min", "max")),
    (rf"({NUMBER})", ("value",)),
)


@pytest.fixture(scope="module")
def tex() -> str:
    path = shared_data_dir().parent / "paper" / PAPER_TEX
    if not path.is_file():
        pytest.skip(f"the paper's LaTeX source is not at {path} (set SOLARCHAIN_SHARED_DATA)")
    return path.read_text(encoding="utf-8")


def tabular(tex: str, label: str) -> tuple[list[str], list[list[str]]]:
    """Header cells and data rows (cells) of the tabular after ``\\label{label}``."""
    at = tex.index(f"\\label{{{label}}}")
    body = tex[tex.index("\\begin{tabular}", at) : tex.index("\\end{tabular}", at)]
    head, rest = body.split("\\toprule", 1)[1].split("\\midrule", 1)
    rows = rest.split("\\bottomrule", 1)[0]

    def cells(line: str) -> list[str]:
        return [c.strip() for c in line.strip().removesuffix("\\\\").split("&")]

    return cells(head), [cells(line) for line in rows.strip().splitlines() if line.strip()]


def numbers(cell: str) -> dict[str, str] | None:
    """The numbers of a cell by part, None when the cell is not numeric."""
    for pattern, parts in CELL_FORMS:
        match = re.fullmatch(pattern, cell)
        if match:
            return dict(zip(parts, match.groups(), strict=True))
    return None


def printed_numbers(tex: str, label: str, label_columns: int) -> dict[tuple, str]:
    """(row labels, column header, part) -> the number as printed."""
    header, rows = tabular(tex, label)
    out = {}
    for row in rows:
        for column, cell in zip(header[label_columns:], row[label_columns:], strict=True):
            parsed = numbers(cell)
            assert parsed is not None, f"{label}: cell {cell!r} is not a number"
            for part, text in parsed.items():
                out[(tuple(row[:label_columns]), column, part)] = text
    return out


def section_text(tex: str, label: str) -> str:
    """The text of the (sub)section with ``\\label{label}``, up to the next (sub)section."""
    start = tex.index(f"\\label{{{label}}}")
    end = min(i for i in (tex.find("\\subsection", start), tex.find("\\section", start)) if i > 0)
    return tex[start:end]


def test_every_stored_table_value_equals_the_printed_number(tex):
    stored = paper_values()
    for table in paper_tables():
        header, _ = tabular(tex, table.label)
        assert tuple(header) == table.label_columns + table.columns, table.label
        printed = printed_numbers(tex, table.label, len(table.label_columns))
        mine = stored[stored["table"] == table.label]
        ours = {(r["row"], r["column"], r["part"]): r["printed"] for r in mine.to_dict("records")}
        wrong = {k: (v, printed.get(k)) for k, v in ours.items() if printed.get(k) != v}
        assert not wrong, f"{table.label}: stored vs printed {wrong}"
        assert set(ours) == set(printed), f"{table.label}: numbers not stored: {sorted(set(printed) - set(ours))}"


def test_printed_rows_reassemble_the_papers_rows(tex):
    for table in paper_tables():
        _, rows = tabular(tex, table.label)
        width = len(table.label_columns)
        for row in rows:
            assert printed_row(table.label, tuple(row[:width])) == row[width:], (table.label, row[:width])


def test_every_result_table_of_the_paper_is_stored(tex):
    """Every tabular whose data cells are numbers (with decimals) is one of the stored tables."""
    numeric = set()
    for label in re.findall(r"\\label\{(tab:[^}]+)\}", tex):
        if "\\begin{tabular}" not in tex[tex.index(f"\\label{{{label}}}") :]:
            continue
        try:
            _, rows = tabular(tex, label)
        except ValueError:
            continue
        decimal_cells = [c for row in rows for c in row[1:] if numbers(c) and "." in c]
        if len(decimal_cells) >= len(rows):
            numeric.add(label)
    assert numeric == {t.label for t in paper_tables()}


def test_stored_numbers_agree_with_their_printed_strings():
    for row in paper_values().to_dict("records"):
        printed = row["printed"]
        assert row["value"] == float(printed), row["id"]
        assert row["decimals"] == (len(printed.split(".")[1]) if "." in printed else 0), row["id"]


def test_numbers_stated_in_the_text_are_in_their_section(tex):
    text_values = paper_values().query("source == 'text'")
    assert len(text_values) >= 8
    for row in text_values.to_dict("records"):
        section = section_text(tex, row["table"])
        assert row["context"] in section, row["id"]
        assert row["printed"] in row["context"], row["id"]


def test_a_quantity_printed_in_several_tables_agrees_to_the_shorter_precision():
    groups = defaultdict(list)
    for row in paper_values().query("source == 'table' and part != 'std'").to_dict("records"):
        groups[(row["setting"], row["base_setting"], row["policy"], row["metric"], row["statistic"])].append(row)
    repeated = [rows for rows in groups.values() if len(rows) > 1]
    assert len(repeated) >= 30  # main table vs appendix detail and four-setting table, body vs appendix deltas
    for rows in repeated:
        digits = min(r["decimals"] for r in rows)
        assert len({f"{r['value']:.{digits}f}" for r in rows}) == 1, [r["id"] for r in rows]


def test_values_map_to_the_report_tables_columns():
    """Each table names the report table that regenerates it; spot checks of the mapping."""
    assert {t.label: t.report_key for t in paper_tables()}["tab:auditability"] == "agentic_effects"
    static = paper_value("main-performance:static:cumulative_reward:mean")
    assert (static["printed"], static["setting"], static["policy"], static["report_column"]) == (
        "-23.38",
        "main",
        "static",
        "cumulative_reward_mean",
    )
    delta = ref_of("physics-ablation-deltas:rl+llm/dqn:delta_artificial_liquidity:mean")
    assert (delta.setting, delta.base_setting, delta.policy, delta.metric) == (
        "llm_no_physics",
        "llm",
        "dqn",
        "artificial_liquidity_MWh",
    )
    assert ref_of("app-four-setting-aggregate:rl:reward").policies == ("ppo", "sac", "dqn")


def test_every_finding_holds_on_the_papers_own_numbers():
    findings = paper_findings()
    assert {f.kind for f in findings} == {"beats", "extreme", "not_better", "sign", "within", "above"}
    for finding in findings:
        values = paper_findings_values(finding)
        assert set(values) == {finding.ref(p) for p in finding.compared}, finding.id
        assert holds(finding, values), finding.id


def test_a_finding_flips_when_its_cells_are_swapped():
    finding = next(f for f in paper_findings() if f.id == "sac_highest_reward")
    values = paper_findings_values(finding)
    sac, ppo = finding.ref("sac"), finding.ref("ppo")
    values[sac], values[ppo] = values[ppo], values[sac]
    assert not holds(finding, values)


def test_the_json_is_package_data():
    pyproject = (Path(__file__).resolve().parents[1] / "pyproject.toml").read_text(encoding="utf-8")
    assert "paper_reference.json" in pyproject
