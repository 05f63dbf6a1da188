"""A run checked against the paper: its published values and findings beside the run's estimates.

The published values and findings (:mod:`.paper_reference`, stored in ``paper_reference.json``),
the run's estimate of each (:mod:`.paper_estimates`), whether a finding holds (:mod:`.paper_findings`),
the spread over training seeds (:mod:`.seed_spread`) and the tables that put them side by side
(:mod:`.tables`, :mod:`.against_findings`).
"""
