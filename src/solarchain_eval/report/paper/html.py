"""The self-contained ``index.html``: tables, figures (embedded PNG data URIs), provenance and
run metadata. No scripts and no external resources, so it opens offline and from any folder."""

from __future__ import annotations

import base64
import html
import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from ...evaluation.records import METADATA_FILE
from ...experiments.layout import PAPER_METADATA_FILE
from ..figure_style import FigureFile
from ..loading import ReportData
from ..naming import paper_order, policy_label, setting_label
from ..table_model import ReportTable, Skipped, to_html
from .provenance import dataset_records, run_records

CSS = """
body{font-family:system-ui,-apple-system,"Segoe UI",Roboto,sans-serif;margin:0 auto;max-width:1440px;padding:1.5rem;color:#1d1d1f;line-height:1.45}
h1{margin-bottom:.2rem}h2{border-bottom:2px solid #e5e5e5;padding-bottom:.2rem;margin-top:2.2rem}
.meta{color:#555}.warning{background:#fff6d6;border-left:4px solid #e6a700;padding:.6rem .9rem;margin:1rem 0}
table{border-collapse:collapse;margin:.4rem 0;font-size:.88rem}
th,td{padding:.28rem .6rem;text-align:center;border-bottom:1px solid #e2e2e2;white-space:nowrap}
th{border-top:2px solid #333;border-bottom:1px solid #333;background:#fafafa}
tbody tr:last-child td{border-bottom:2px solid #333}
td:first-child,th:first-child{text-align:left}
figure{margin:1.2rem 0}figcaption{font-size:.9rem;margin-bottom:.3rem}
figure.table{overflow-x:auto}
.basis{font-size:.82rem;color:#444;font-style:italic;margin:.2rem 0}.meta-list dt{font-weight:600;margin-top:.3rem}.meta-list dd{margin-left:1.2rem}
.caveat{font-size:.85rem;font-weight:600;color:#8a4b00;background:#fff4e0;border-left:4px solid #e6a700;padding:.3rem .6rem;margin:.3rem 0}
.notes{font-size:.82rem;color:#444}
.figures{display:grid;grid-template-columns:repeat(auto-fill,minmax(520px,1fr));gap:1rem}
.figures figure{border:1px solid #eee;padding:.5rem;border-radius:6px}
.figures img{max-width:100%;height:auto;display:block}
.figures figure.wide{grid-column:1/-1}
code,pre{font-family:ui-monospace,SFMono-Regular,Menlo,monospace;font-size:.82rem}
pre{background:#f6f6f6;padding:.7rem;overflow-x:auto}
.skipped li{color:#666}
.scroll{overflow-x:auto}
td.wrap{white-space:normal;text-align:left}
#case_study td{white-space:normal;text-align:left}
"""

WIDE_FIGURES = {"city_hour_liquidity", "city_hour_reward"}


def _escape(value: Any) -> str:
    return html.escape(str(value))


def figure_html(figure: FigureFile) -> str:
    """A written figure as an HTML ``<figure>``: its PNG as a data URI, its title and caption."""
    data = base64.b64encode(Path(figure.png).read_bytes()).decode("ascii")
    css = ' class="wide"' if figure.key in WIDE_FIGURES else ""
    return (
        f'<figure{css} id="fig-{_escape(figure.key)}"><img src="data:image/png;base64,{data}" alt="{_escape(figure.title)}">'
        f"<figcaption><strong>{_escape(figure.title)}.</strong> {_escape(figure.caption)} "
        f'<span class="meta">(figures/{_escape(figure.key)}.png, .svg)</span></figcaption></figure>\n'
    )


def _skipped(items: Sequence[Skipped], what: str) -> str:
    if not items:
        return ""
    rows = "".join(
        f"<li><strong>{_escape(s.title)}</strong> ({_escape(s.key)}): {_escape(s.reason)}</li>" for s in items
    )
    return f'<p>{what} this run cannot support:</p><ul class="skipped">{rows}</ul>\n'


def _overview(data: ReportData) -> str:
    rows = []
    for setting in data.settings:
        rollouts = data.rollouts(setting)
        for policy in paper_order(rollouts["policy"]):
            group = rollouts[rollouts["policy"] == policy]
            rows.append(
                f"<tr><td>{_escape(setting_label(setting))}</td><td>{_escape(policy_label(policy))}</td>"
                f"<td>{len(group)}</td><td>{group['run_seed'].nunique()}</td>"
                f"<td>{group['episode_seed'].nunique()}</td><td>{group['start_hour'].nunique()}</td></tr>"
            )
    head = "<tr><th>Setting</th><th>Policy</th><th>Rollouts</th><th>Run seeds</th><th>Distinct episode seeds</th><th>Distinct start days</th></tr>"
    return f"<table><thead>{head}</thead><tbody>{''.join(rows)}</tbody></table>\n"


def _provenance(data: ReportData) -> str:
    parts = []
    records = dataset_records(data)
    if not records:
        parts.append("<p>The run's metadata records no dataset.</p>")
    for record in records:
        files = "".join(
            f"<tr><td>{_escape(f['name'])}</td><td><code>{_escape(f['sha256'])}</code></td><td>{_escape(f['status'])}</td></tr>"
            for f in record["files"]
        )
        manifest = record["manifest"]
        manifest_html = (
            f"<details><summary>manifest.json</summary><pre>{_escape(json.dumps(manifest, indent=2, sort_keys=True))}</pre></details>"
            if manifest is not None
            else '<p class="meta">No manifest.json in the dataset directory (the published CSVs ship without one).</p>'
        )
        parts.append(
            f"<h3>Dataset <code>{_escape(record['data_dir'])}</code></h3>"
            f'<p class="meta">Used by: {_escape(", ".join(record["used_by"]))}. Manifest sha256: '
            f"<code>{_escape(record['manifest_sha256'] or 'not recorded')}</code>. Status compares the recorded "
            "sha256 with the file on disk now.</p>"
            f"<table><thead><tr><th>File</th><th>sha256 (recorded)</th><th>Status now</th></tr></thead><tbody>{files}</tbody></table>"
            + manifest_html
        )
    return "\n".join(parts) + "\n"


def _metadata_value(value: Any) -> str:
    """A metadata value as plain text: lists joined, mappings as ``key=value`` pairs, never JSON."""
    if isinstance(value, dict):
        return ", ".join(f"{k}={_metadata_value(v)}" for k, v in value.items())
    if isinstance(value, (list, tuple)):
        return (
            " ".join(str(v) for v in value)
            if all(isinstance(v, str) for v in value)
            else ", ".join(_metadata_value(v) for v in value)
        )
    return str(value)


def _run_metadata(data: ReportData) -> str:
    """Fields every unit shares, once; then a table of the fields that differ between units.

    A paper root's units share the command and the commit: printing them once per row buried the
    fields that do differ. Values are plain text; the full record stays in the metadata file.
    """
    records = run_records(data)
    name = PAPER_METADATA_FILE if data.kind == "paper" else METADATA_FILE
    if not records:
        return "<p>No per-run metadata found.</p>\n"
    keys = [k for k in dict.fromkeys(k for r in records for k in r) if k != "unit"]
    shared = [k for k in keys if all(k in r for r in records) and len({repr(r[k]) for r in records}) == 1]
    varying = [k for k in keys if k not in shared]
    items = "".join(
        f"<dt>{_escape(k)}</dt><dd><code>{_escape(_metadata_value(records[0][k]))}</code></dd>"
        if k == "command"
        else f"<dt>{_escape(k)}</dt><dd>{_escape(_metadata_value(records[0][k]))}</dd>"
        for k in shared
    )
    label = "Every unit" if len(records) > 1 else f"Run {_escape(str(records[0]['unit']))}"
    parts = [f'<p>{label} ({len(records)} unit(s)):</p><dl class="meta-list">{items}</dl>']
    if len(records) > 1 and varying:
        head = "".join(f"<th>{_escape(k)}</th>" for k in ["unit", *varying])
        body = "".join(
            "<tr>"
            + "".join(f'<td class="wrap">{_escape(_metadata_value(r.get(k, "")))}</td>' for k in ["unit", *varying])
            + "</tr>"
            for r in records
        )
        parts.append(f'<div class="scroll"><table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table></div>')
    parts.append(f'<p class="meta">The full record is {_escape(name)} in the run directory.</p>')
    return "\n".join(parts) + "\n"


def _against(tables: Sequence[ReportTable | Skipped]) -> str:
    """The against-paper section: the published values beside the run's, with verdicts."""
    if not tables:
        return ""
    return (
        '<h2 id="against-paper">Checking the run against the paper</h2>\n'
        "<p>Each published value of the paper beside the run's estimate, with a verdict; the paper's findings "
        "checked on the run; and how much the learned rows depend on the training seeds.</p>\n"
        + "".join(to_html(t) for t in tables if isinstance(t, ReportTable))
        + _skipped([t for t in tables if isinstance(t, Skipped)], "Checks")
    )


def render_html(
    data: ReportData,
    tables: Sequence[ReportTable | Skipped],
    figures: Sequence[FigureFile | Skipped],
    warnings: Sequence[str],
    against: Sequence[ReportTable | Skipped] = (),
) -> str:
    """The whole page as one string (deterministic for the same inputs); ``against``: the
    against-paper tables, shown in their own section when given."""
    made_tables = [t for t in tables if isinstance(t, ReportTable)]
    made_figures = [f for f in figures if isinstance(f, FigureFile)]
    toc = "".join(f'<li><a href="#{_escape(t.key)}">{_escape(t.title)}</a></li>' for t in made_tables)
    kind = "paper root" if data.kind == "paper" else "evaluation run directory"
    body = [
        "<h1>SolarChain-Eval report</h1>",
        f'<p class="meta">Source: <code>{_escape(data.root)}</code> ({kind}); {len(data.metrics)} rollouts, '
        f"{len(data.actions)} step rows, {len(data.city_hour)} city-hour rows, {len(data.logs)} agentic log steps.</p>",
        *[f'<div class="warning"><strong>Warning.</strong> {_escape(w)}</div>' for w in warnings],
        "<h2>Contents</h2>",
        f'<ul><li><a href="#overview">Overview</a></li>{toc}'
        + ('<li><a href="#against-paper">Checking the run against the paper</a></li>' if against else "")
        + '<li><a href="#figures">Figures</a></li>'
        '<li><a href="#provenance">Dataset provenance</a></li><li><a href="#metadata">Run metadata</a></li></ul>',
        '<h2 id="overview">Overview</h2>',
        _overview(data),
        "<h2>Tables</h2>",
        *[to_html(t) for t in made_tables],
        _skipped([t for t in tables if isinstance(t, Skipped)], "Tables"),
        _against(against),
        '<h2 id="figures">Figures</h2>',
        '<div class="figures">' + "".join(figure_html(f) for f in made_figures) + "</div>",
        _skipped([f for f in figures if isinstance(f, Skipped)], "Figures"),
        '<h2 id="provenance">Dataset provenance</h2>',
        _provenance(data),
        '<h2 id="metadata">Run metadata</h2>',
        _run_metadata(data),
    ]
    return (
        '<!DOCTYPE html>\n<html lang="en">\n<head>\n<meta charset="utf-8">\n'
        '<meta name="viewport" content="width=device-width, initial-scale=1">\n'
        '<link rel="icon" href="data:,">\n'
        f"<title>SolarChain-Eval report: {_escape(data.root.name)}</title>\n<style>{CSS}</style>\n</head>\n<body>\n"
        + "\n".join(body)
        + "\n</body>\n</html>\n"
    )
