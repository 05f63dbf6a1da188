"""Keep a readable module table at the top of each API reference page (docs/api/*.md).

The pages render their ``::: module`` directives with mkdocstrings only when the site is built;
read on the repository they would be bare directives. This script writes, before a page's first
directive, a table of the modules the page documents with the first paragraph of each module's
docstring (read from the source, nothing imported)::

    python docs/hooks/api_pages.py --write    # refresh the tables
    python docs/hooks/api_pages.py --check    # exit status 1 when a table is stale

``tests/test_docs.py`` fails while a table is stale.
"""

from __future__ import annotations

import argparse
import ast
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
API = ROOT / "docs" / "api"
SOURCE = ROOT / "src"
START, END = "<!-- api-modules:start -->", "<!-- api-modules:end -->"
NOTE = (
    "Modules on this page; the supported names are on the [Public API](../public_api.md) page, "
    "everything else is internal and may move between minor releases."
)
DIRECTIVE = re.compile(r"^::: ([\w.]+)", re.M)


def summary(module: str) -> str:
    """The first paragraph of a module's docstring, on one line (from its source file)."""
    base = SOURCE.joinpath(*module.split("."))
    path = base / "__init__.py" if base.is_dir() else base.with_suffix(".py")
    doc = ast.get_docstring(ast.parse(path.read_text(encoding="utf-8"))) or ""
    first = " ".join(doc.split("\n\n", 1)[0].split())
    first = re.sub(r":\w+:`~?\.?([^`]+)`", r"`\1`", first).replace("``", "`")  # Sphinx roles, as Markdown code
    return first.replace("|", "\\|")


def table(page_text: str) -> str:
    rows = [f"| `{m}` | {summary(m)} |" for m in DIRECTIVE.findall(page_text)]
    return "\n".join([START, NOTE, "", "| module | what it is |", "|---|---|", *rows, END])


def refreshed(page_text: str) -> str:
    """The page with its table inserted before the first directive, or replaced."""
    text = re.sub(rf"{re.escape(START)}.*?{re.escape(END)}\n\n", "", page_text, flags=re.S)
    first = DIRECTIVE.search(text)
    if first is None:
        return page_text
    return f"{text[: first.start()]}{table(text)}\n\n{text[first.start() :]}"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="Refresh the module tables of docs/api/*.md.")
    action = parser.add_mutually_exclusive_group()
    action.add_argument("--write", action="store_true")
    action.add_argument("--check", action="store_true")
    args = parser.parse_args(argv)
    stale = []
    for page in sorted(API.glob("*.md")):
        text = page.read_text(encoding="utf-8")
        new = refreshed(text)
        if new != text:
            stale.append(page)
            if args.write:
                page.write_text(new, encoding="utf-8")
    if args.check and stale:
        print("stale: " + ", ".join(str(p.relative_to(ROOT)) for p in stale), file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
