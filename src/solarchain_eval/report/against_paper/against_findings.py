"""The paper's findings checked on a run: ``holds`` / ``flips``, and whether the training seeds decide.

Each finding (:func:`~solarchain_eval.report.against_paper.paper_reference.paper_findings`) is evaluated on the
run's estimates of the quantities it compares. "Not clearly better" holds unless the
start-day bootstrap interval of the difference lies entirely on the better side. Findings on
agentic rows that a stand-in governed are labelled, not evaluated. In a paper root (where a
learned policy's run seed is its training seed) the share of training-seed resamples on which
the finding holds is given, and whether the seeds decide it.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from ..loading import ReportData
from ..naming import policy_label
from ..options import ReportOptions
from ..table_model import Column, ReportTable, fixed, text
from .paper_estimates import NOT_IN_RUN, Estimate, RunEstimates, difference, is_agentic, stand_in
from .paper_findings import better_sign, compared_refs, holds
from .paper_reference import Finding, Ref, paper_findings, paper_findings_values, paper_value
from .seed_spread import DECIDED_SHARE, SeedDraws, finding_seed_share, seed_decision

#: The seed column of findings the seed bootstrap does not apply to.
NOT_RESAMPLED = "training seeds not resampled (not a paper root: one model per learned policy)"


def _label(ref: Ref) -> str:
    name = "+".join(policy_label(p) for p in ref.policies)
    return f"{name} Δ" if ref.base_setting is not None else name


def _decimals(finding: Finding) -> int:
    return max(paper_value(v)["decimals"] for v in finding.cells if v not in finding.bounds)


def describe_values(finding: Finding, values: dict[Ref, float]) -> str:
    """ "SAC −22.26; PPO −22.35, ..." : the compared values, the finding's policies first."""
    digits = _decimals(finding)
    first = ", ".join(f"{_label(finding.ref(p))} {fixed(values[finding.ref(p)], digits)}" for p in finding.policies)
    rest = ", ".join(f"{_label(finding.ref(p))} {fixed(values[finding.ref(p)], digits)}" for p in finding.than)
    return f"{first}; vs {rest}" if rest else first


def _stated_bounds(finding: Finding) -> str:
    """ "; stated: 34.2 %–37.2 %" for a finding with bounds the text states ("" otherwise)."""
    if not finding.bounds:
        return ""
    printed = [paper_value(v) for v in finding.bounds]
    unit = " %" if printed[0]["unit"] == "percent" else ""
    if finding.kind == "above":
        return f"; stated: over {printed[0]['printed']}{unit}"
    return f"; stated: {printed[0]['printed']}{unit}–{printed[1]['printed']}{unit}"


def _not_better(finding: Finding, found: dict[Ref, Estimate], options: ReportOptions) -> tuple[bool, str]:
    """Holds unless a difference's interval lies entirely on the better side; the intervals as text."""
    sign, digits, holds_all, shown = better_sign(finding.metric), _decimals(finding), True, []
    for p in finding.policies:
        for other in finding.than:
            interval = difference(found[finding.ref(p)], found[finding.ref(other)]).interval(options)
            low = interval.low if sign > 0 else -interval.high  # the difference's low end, better direction
            holds_all &= not low > 0
            shown.append(
                f"{policy_label(p)} - {policy_label(other)} {fixed(interval.estimate, digits)} "
                f"[{fixed(interval.low, digits)}, {fixed(interval.high, digits)}]"
            )
    return holds_all, "; ".join(shown)


def check_finding(
    finding: Finding,
    estimates: RunEstimates,
    options: ReportOptions,
    stand: str | None,
    draws: SeedDraws | None,
) -> dict:
    """One row of the findings table (id, statement, paper, run, verdict, seed share and decision)."""
    row = {"id": finding.id, "statement": finding.statement, "source": finding.source}
    row["paper"] = describe_values(finding, paper_findings_values(finding)) + _stated_bounds(finding)
    refs = compared_refs(finding)
    found = {ref: estimates.get(ref) for ref in refs}
    if any(e is None for e in found.values()):
        return row | {"run": NOT_IN_RUN, "verdict": NOT_IN_RUN, "seed_share": np.nan, "seeds": "–"}
    present = {ref: e for ref, e in found.items() if e is not None}
    row["run"] = describe_values(finding, {ref: e.value for ref, e in present.items()})
    if stand and any(is_agentic(ref) for ref in refs):
        return row | {"verdict": f"stand-in: {stand}", "seed_share": np.nan, "seeds": "–"}
    if finding.kind == "not_better":
        ok, intervals = _not_better(finding, present, options)
        row["run"] += f" ({intervals})"
    else:
        ok = holds(finding, {ref: e.value for ref, e in present.items()})
    row["verdict"] = "holds" if ok else "flips"
    if draws is None:
        return row | {"seed_share": np.nan, "seeds": NOT_RESAMPLED}
    share = finding_seed_share(finding, estimates, draws)
    share = np.nan if share is None else share
    n_seeds = draws.n_seeds([p for ref in refs for p in ref.policies])
    return row | {"seed_share": share, "seeds": seed_decision(share, n_seeds)}


def findings_table(
    data: ReportData, options: ReportOptions, draws: SeedDraws | None, estimates: RunEstimates | None = None
) -> ReportTable:
    """Every finding of the paper checked on the run (``draws``: training-seed resamples, or None)."""
    estimates, stand = estimates or RunEstimates(data.metrics), stand_in(data)
    frame = pd.DataFrame([check_finding(f, estimates, options, stand, draws) for f in paper_findings()])

    def share(row) -> str:
        return "–" if np.isnan(row["seed_share"]) else f"{100 * row['seed_share']:.0f} %"

    columns = [
        Column("Finding", text("statement"), align="p{0.30\\textwidth}"),
        Column("Paper", text("paper"), align="p{0.20\\textwidth}"),
        Column("Run", text("run"), align="p{0.22\\textwidth}"),
        Column("Verdict", text("verdict"), align="l"),
        Column("Seed resamples holding", share),
        Column("Seeds", text("seeds"), align="l"),
    ]
    return ReportTable(
        key="against_paper_findings",
        label="tab:against-paper-findings",
        title="The paper's findings on this run",
        caption=(
            "Each finding the paper states, with the values it compares in the paper and in the run. holds / flips: "
            "whether it holds on the run's means (\"not clearly better\": unless the difference's bootstrap interval "
            "lies entirely on the better side). Seed resamples holding: the share of resamples of the learned "
            "policies' training seeds on which it holds."
        ),
        columns=columns,
        data=frame,
        basis=(
            f"{len(frame)} findings; {int((frame['verdict'] == 'holds').sum())} hold, "
            f"{int((frame['verdict'] == 'flips').sum())} flip. Seed resamples: {options.n_resamples}, seed {options.seed}."
        ),
        notes=[
            f"A share above {100 * (1 - DECIDED_SHARE):.0f} % and below {100 * DECIDED_SHARE:.0f} % means the "
            "training seeds cannot decide the finding."
        ],
    )


__all__ = ["NOT_RESAMPLED", "check_finding", "describe_values", "findings_table"]
