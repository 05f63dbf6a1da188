"""The paper report: every table and figure of the paper regenerated from one run or paper root.

:mod:`.build` loads the run and writes ``report/``: the tables (:mod:`.tables`), the figures
(:mod:`.figures`), the case study (:mod:`.casestudy`), provenance (:mod:`.provenance`) and the
self-contained page (:mod:`.html`); the against-paper tables come from
:mod:`solarchain_eval.report.against_paper`, the governance diagnostics from
:mod:`solarchain_eval.report.governance`.
"""
