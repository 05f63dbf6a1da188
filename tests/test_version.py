"""One version and one licence, stated the same way by the package, pyproject, CITATION.cff and the CLI."""

from __future__ import annotations

import tomllib
from pathlib import Path

import yaml
from typer.testing import CliRunner

import solarchain_eval
from solarchain_eval.cli import app

ROOT = Path(__file__).resolve().parents[1]


def test_version_is_the_same_everywhere():
    project = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    citation = yaml.safe_load((ROOT / "CITATION.cff").read_text(encoding="utf-8"))
    assert project["version"] == solarchain_eval.__version__ == citation["version"]
    result = CliRunner().invoke(app, ["--version"])
    assert result.exit_code == 0 and result.output == f"solarchain-eval {solarchain_eval.__version__}\n"


def test_licence_is_stated_and_the_weather_keeps_its_own():
    project = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    citation = yaml.safe_load((ROOT / "CITATION.cff").read_text(encoding="utf-8"))
    licence = (ROOT / "LICENSE").read_text(encoding="utf-8")
    assert project["license"] == citation["license"] == "MIT" and licence.startswith("MIT License")
    assert project["license-files"] == ["LICENSE"]
    # the packaged Open-Meteo payload is not MIT: the licence file says so and names its attribution
    assert "open_meteo_weather_2026-04-01_2026-05-01.json.xz" in licence and "CC BY 4.0" in licence
    packaged = ROOT / "src/solarchain_eval/data/paper/open_meteo_weather_2026-04-01_2026-05-01.json.xz"
    assert packaged.is_file()
