"""The documentation site: references from the code resolve, and the CLI reference is complete.

``mkdocs build --strict`` (run by CI) checks the links between pages; these tests check what
mkdocs cannot see: the ``docs/<page>.md#<anchor>`` references in code comments and docstrings,
and that the generated CLI reference covers every command and option of the typer app.
"""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
REFERENCE = re.compile(r"docs/([A-Za-z0-9_/]+\.md)(#[a-z0-9_-]+)?")
FENCE = re.compile(r"^(```|~~~)")


def heading_anchors(page: Path) -> set[str]:
    """The anchors mkdocs gives the page's headings (Python-Markdown's toc slugs)."""
    toc = pytest.importorskip("markdown.extensions.toc")
    anchors, fenced = set(), False
    for line in page.read_text(encoding="utf-8").splitlines():
        if FENCE.match(line):
            fenced = not fenced
        elif not fenced and line.startswith("#"):
            anchors.add(toc.slugify(line.lstrip("#").strip(), "-"))
    return anchors


def code_references() -> list[tuple[str, str, str | None]]:
    found = []
    for path in sorted([*(ROOT / "src").rglob("*.py"), *(ROOT / "tests").rglob("*.py")]):
        for match in REFERENCE.finditer(path.read_text(encoding="utf-8")):
            found.append((str(path.relative_to(ROOT)), match.group(1), match.group(2)))
    return found


def test_code_refers_to_docs_pages_and_headings_that_exist():
    references = code_references()
    assert len(references) >= 30  # the modules that implement a documented formula cite its page
    broken = []
    for source, page, anchor in references:
        target = DOCS / page
        if not target.is_file():
            broken.append(f"{source}: docs/{page} does not exist")
        elif anchor and anchor[1:] not in heading_anchors(target):
            broken.append(f"{source}: docs/{page} has no heading {anchor}")
    assert broken == []


def test_no_reference_to_a_document_outside_the_repository():
    word = "SP" + "EC"  # spelled apart so this file does not match itself
    hits = [
        f"{path.relative_to(ROOT)}:{number}"
        for path in sorted([*(ROOT / "src").rglob("*.py"), *(ROOT / "tests").rglob("*.py")])
        for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1)
        if word in line
    ]
    assert hits == []


def test_environment_card_has_gymnasium_headings_in_page_and_docstring():
    from solarchain_eval.envs.env import SolarChainEnv

    headings = [
        "Description",
        "Action Space",
        "Observation Space",
        "Rewards",
        "Starting State",
        "Episode End",
        "Arguments",
        "Vectorized environment",
        "Info",
        "Version History",
    ]
    lines = (DOCS / "environment.md").read_text(encoding="utf-8").splitlines()
    page = {line.lstrip("#").strip() for line in lines if line.startswith("## ")}
    assert [h for h in headings if h not in page] == []
    doc = SolarChainEnv.__doc__ or ""
    assert [h for h in headings if f"\n    {h}\n    {'-' * len(h)}\n" not in doc] == []


def _cli_hook():
    spec = importlib.util.spec_from_file_location("cli_reference", DOCS / "hooks" / "cli_reference.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_cli_reference_lists_every_command_and_option():
    import typer.main

    from solarchain_eval.cli import app

    markdown = _cli_hook().cli_reference_markdown()
    missing = []

    def walk(command, path):
        ctx = command.context_class(command, info_name=path[-1])
        if f"`{' '.join(path)}`" not in markdown:
            missing.append(" ".join(path))
        for param in command.params:
            for name in [*param.opts, *param.secondary_opts]:
                if name.startswith("--") and name not in markdown:
                    missing.append(f"{' '.join(path)} {name}")
        if hasattr(command, "list_commands"):
            for name in command.list_commands(ctx):
                walk(command.get_command(ctx, name), [*path, name])

    walk(typer.main.get_command(app), ["solarchain-eval"])
    assert missing == []
    assert "`solarchain-eval data build`" in markdown and "`--nodes-per-city" in markdown
    # The hook replaces its marker on the CLI page and leaves other pages alone.
    hook = _cli_hook()
    assert hook.on_page_markdown("a\n<!-- cli-reference -->\n", page=None).count("`solarchain-eval evaluate`") == 1
    assert hook.on_page_markdown("plain page", page=None) == "plain page"
