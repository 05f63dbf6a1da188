"""Generate docs/index.md, the site's home page, from README.md.

README.md is the one source of the text both pages share (what the benchmark is, what it
reproduces, set-up, quick start, the page list). The home page is README.md with its links made
to work on the site::

    python docs/hooks/index_page.py --write    # regenerate docs/index.md
    python docs/hooks/index_page.py --check    # exit status 1 when docs/index.md is stale
    python docs/hooks/index_page.py            # print the page

A link into ``docs/`` loses that prefix; a link to another file of the repository (LICENSE,
CITATION.cff, examples/...) becomes its path in code, because the site holds only ``docs/``.
``tests/test_docs.py`` fails while the committed page differs from the generated one.
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
README = ROOT / "README.md"
PAGE = ROOT / "docs" / "index.md"
NOTICE = "<!-- Generated from README.md by `python docs/hooks/index_page.py --write`; edit README.md instead. -->\n"
_LINK = re.compile(r"\[([^\]]+)\]\(([^)\s]+)\)")


def _site_link(match: re.Match[str]) -> str:
    text, target = match.group(1), match.group(2)
    if target.startswith(("http://", "https://", "#")):
        return match.group(0)
    if target.startswith("docs/"):
        return f"[{text}]({target.removeprefix('docs/')})"
    # A file outside the site: name it instead of linking to it.
    return text if text.startswith("`") else f"`{target}`"


def index_page(readme: str | None = None) -> str:
    """The whole page docs/index.md, exactly as committed."""
    text = README.read_text(encoding="utf-8") if readme is None else readme
    title, _, body = text.partition("\n")
    return f"{title}\n\n{NOTICE}{_LINK.sub(_site_link, body)}"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="Generate the site's home page docs/index.md from README.md.")
    action = parser.add_mutually_exclusive_group()
    action.add_argument("--write", action="store_true", help=f"write {PAGE}")
    action.add_argument("--check", action="store_true", help=f"exit 1 when {PAGE} is stale")
    args = parser.parse_args(argv)
    page = index_page()
    if args.write:
        PAGE.write_text(page, encoding="utf-8")
    elif args.check:
        if not PAGE.is_file() or PAGE.read_text(encoding="utf-8") != page:
            print(f"{PAGE} is stale: run python docs/hooks/index_page.py --write", file=sys.stderr)
            return 1
    else:
        sys.stdout.write(page)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
