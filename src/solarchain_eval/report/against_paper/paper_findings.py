"""Whether a finding of the paper holds for given numbers: the paper's own, a run's, or B resamples.

:func:`finding_condition` evaluates a :class:`~solarchain_eval.report.against_paper.paper_reference.Finding` on
arrays of B values per compared quantity (B = 1 for point estimates) and returns B booleans, so
the same code decides the verdict on a run's means and the share of training-seed resamples on
which the finding still holds.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from .paper_reference import Finding, Ref, as_fraction, fraction_decimals, metric_better


def better_sign(metric: str) -> float:
    """+1 when a higher value of ``metric`` is better, -1 when lower is better (higher by default)."""
    return -1.0 if metric_better().get(metric) == "lower" else 1.0


def bounds(finding: Finding) -> tuple[float, float]:
    """The stated bounds of a ``within``/``above`` finding as fractions, each widened by half a unit
    of its last printed digit (the text rounds them); ``above`` has no upper bound."""
    widened = [(as_fraction(value_id), 0.5 * 10.0 ** -fraction_decimals(value_id)) for value_id in finding.bounds]
    if finding.kind == "above":
        return widened[0][0], float("inf")
    (low, low_slack), (high, high_slack) = widened
    return low - low_slack, high + high_slack


def compared_refs(finding: Finding) -> list[Ref]:
    """The quantities a finding compares, ``policies`` first."""
    return [finding.ref(policy) for policy in finding.compared]


def _pairs(finding: Finding, values: Mapping[Ref, np.ndarray]) -> list[np.ndarray]:
    """(policy - other) in the better direction, for each policy and each other it is compared with."""
    sign = better_sign(finding.metric)
    if finding.kind == "extreme":
        sign = 1.0 if finding.extreme == "max" else -1.0
    return [
        sign * (values[finding.ref(p)] - values[finding.ref(other)]) for p in finding.policies for other in finding.than
    ]


def finding_condition(finding: Finding, values: Mapping[Ref, np.ndarray]) -> np.ndarray:
    """B booleans: whether the finding holds for each of B sets of values.

    Parameters
    ----------
    finding
        The finding.
    values
        An array of B numbers for every quantity in :func:`compared_refs` (NaN where a resample has
        none; a NaN comparison counts as not holding).

    Notes
    -----
    ``not_better`` here is "no policy's value is above the other's in the better direction"; on
    a run the against-paper check uses the bootstrap interval of the difference instead.
    """
    with np.errstate(invalid="ignore"):
        if finding.kind in ("beats", "extreme"):
            return np.logical_and.reduce([d > 0 for d in _pairs(finding, values)])
        if finding.kind == "not_better":
            return np.logical_and.reduce([d <= 0 for d in _pairs(finding, values)])
        if finding.kind == "sign":
            signs = finding.signs or {}
            checks = [values[finding.ref(p)] * (1.0 if signs[p] == "+" else -1.0) > 0 for p in finding.policies]
            return np.logical_and.reduce(checks)
        if finding.kind == "within":
            low, high = bounds(finding)
            return np.logical_and.reduce(
                [(values[finding.ref(p)] >= low) & (values[finding.ref(p)] <= high) for p in finding.policies]
            )
        if finding.kind == "above":
            low, _ = bounds(finding)
            return np.logical_and.reduce([values[finding.ref(p)] > low for p in finding.policies])
    raise ValueError(f"finding {finding.id}: unknown kind {finding.kind!r}")


def holds(finding: Finding, values: Mapping[Ref, float]) -> bool:
    """Whether the finding holds for one value per compared quantity."""
    return bool(finding_condition(finding, {ref: np.array([v], dtype=float) for ref, v in values.items()})[0])


__all__ = ["better_sign", "bounds", "compared_refs", "finding_condition", "holds"]
