"""CITATION.cff: a valid Citation File Format 1.2.0 file whose version is the changelog's newest release.

The rule for the version: CITATION.cff's ``version`` equals the newest release heading of
CHANGELOG.md (its first ``## [X.Y.Z]`` heading, released or not), so the two are bumped together.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]
CITATION = ROOT / "CITATION.cff"
CHANGELOG = ROOT / "CHANGELOG.md"
#: A release heading: "## [0.2.0] — unreleased", "## [0.1.0] - 2026-11-24" or "## 0.1.0".
RELEASE_HEADING = re.compile(r"^## \[?(\d+\.\d+\.\d+)\]?(?:\s|$)")


def load_citation() -> dict:
    data = yaml.safe_load(CITATION.read_text(encoding="utf-8"))
    assert isinstance(data, dict), "CITATION.cff is not a YAML mapping"
    return data


def newest_release(changelog: str) -> str:
    """The version of the first release heading of a Keep-a-Changelog file."""
    for line in changelog.splitlines():
        match = RELEASE_HEADING.match(line)
        if match:
            return match.group(1)
    raise AssertionError("CHANGELOG.md has no release heading like '## [X.Y.Z] ...'")


def check_authors(authors: object, where: str) -> None:
    assert isinstance(authors, list) and authors, f"{where}: authors must be a non-empty list"
    for author in authors:
        assert isinstance(author, dict), f"{where}: an author is not a mapping: {author!r}"
        person = bool(author.get("family-names")) and bool(author.get("given-names"))
        entity = bool(author.get("name"))
        assert person or entity, f"{where}: author {author!r} needs family-names and given-names, or a name"


def test_citation_has_the_required_cff_keys():
    data = load_citation()
    assert data.get("cff-version") == "1.2.0"
    for key in ("message", "title"):
        assert isinstance(data.get(key), str) and data[key].strip(), f"'{key}' is missing or empty"
    check_authors(data.get("authors"), "authors")
    assert data.get("type", "software") in ("software", "dataset")
    cited = data.get("preferred-citation")
    assert isinstance(cited, dict), "'preferred-citation' is missing"
    for key in ("type", "title"):
        assert isinstance(cited.get(key), str) and cited[key].strip(), f"preferred-citation: '{key}' is missing"
    check_authors(cited.get("authors"), "preferred-citation")


def test_citation_cites_the_paper():
    cited = load_citation()["preferred-citation"]
    assert cited["title"].startswith("SolarChain-Eval: A Physics-Constrained Benchmark")
    assert [a.get("family-names") for a in cited["authors"]] == ["Ou", "Xu", "Zhang"]
    assert "doi" not in cited  # the paper has no DOI yet; do not invent one


def test_citation_version_is_the_changelogs_newest_release():
    version = load_citation().get("version")
    assert isinstance(version, str), "CITATION.cff: 'version' must be a quoted string such as '0.2.0'"
    assert version == newest_release(CHANGELOG.read_text(encoding="utf-8"))


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("# Changelog\n\n## [Unreleased]\n\n## [0.3.0] — unreleased\n\n## [0.2.0] - 2026-01-01\n", "0.3.0"),
        ("# Changelog\n\n## 1.0.0\n\n## 0.9.0\n", "1.0.0"),
    ],
)
def test_newest_release_reads_the_first_versioned_heading(text, expected):
    assert newest_release(text) == expected
