"""Governance reports: audit quality from counterfactual step records, its tables and figures, and
the governance leaderboard that ranks planner/auditor combinations by it (docs/governance.md).
"""
