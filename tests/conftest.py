"""Shared fixtures.

The paper's published dataset (``published_dir``) is rebuilt once per session from the weather
payload shipped with the package, into the session's own cache directory (so nothing is written
to the user's real cache), and checked against the published sha256s. Only the original
release's per-episode outputs, and the comparisons with the release's own files, are read from
``../shared/data`` beside the repository (override with the ``SOLARCHAIN_SHARED_DATA``
environment variable); tests that need them skip with the reason when it is absent.

With ``SOLARCHAIN_STRICT_SKIPS=1`` (set by CI) the session fails when a test skips for any
reason but a missing optional tool of :data:`ALLOWED_SKIP_REASONS` or the shared data.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]
PAPER_WEATHER = "open_meteo_weather_2026-04-01_2026-05-01.json"
PUBLISHED = "published_2026_04"


#: Words of the skip reasons CI accepts (case-insensitive): tools a plain machine may lack, and
#: the paper's shared data. Every other skip (a missing extra, a forgotten fixture) fails CI.
ALLOWED_SKIP_REASONS = (
    "chromium",
    "pdflatex",
    "llama",
    "jax",
    "gpu",
    "cuda",
    "SOLARCHAIN_SHARED_DATA",
    # bit-exact SB3 weights against the original release's fingerprints (test_original_weights.py)
    "reference library versions",
)
_disallowed_skips: list[str] = []


def pytest_runtest_logreport(report: pytest.TestReport) -> None:
    if report.skipped and not hasattr(report, "wasxfail") and isinstance(report.longrepr, tuple):
        reason = str(report.longrepr[2])
        if not any(word.lower() in reason.lower() for word in ALLOWED_SKIP_REASONS):
            _disallowed_skips.append(f"{report.nodeid}: {reason}")


def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    if _disallowed_skips and os.environ.get("SOLARCHAIN_STRICT_SKIPS") == "1":
        session.exitstatus = pytest.ExitCode.TESTS_FAILED


def pytest_terminal_summary(terminalreporter, exitstatus: int, config: pytest.Config) -> None:
    if _disallowed_skips and os.environ.get("SOLARCHAIN_STRICT_SKIPS") == "1":
        terminalreporter.section("skips that need no optional tool (SOLARCHAIN_STRICT_SKIPS=1 fails on them)")
        for line in _disallowed_skips:
            terminalreporter.line(line)


def shared_data_dir() -> Path:
    return Path(os.environ.get("SOLARCHAIN_SHARED_DATA", REPO_ROOT.parent / "shared" / "data"))


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """The paper's release folder (the original release's outputs, the published files); skips without it."""
    path = shared_data_dir()
    if not (path / "SHA256SUMS").is_file():
        pytest.skip(f"the paper's release files are not at {path} (set SOLARCHAIN_SHARED_DATA)")
    return path


@pytest.fixture(scope="session")
def published_dir(isolated_cache: Path) -> Path:
    """The paper's published dataset: the embedded default dataset, rebuilt from the packaged weather
    (once per session, into the session's cache) and checked against the published sha256s."""
    from solarchain_eval.data.default import default_dataset_dir

    return default_dataset_dir()


@pytest.fixture(scope="session")
def paper_weather(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The paper's Open-Meteo payload as a plain JSON file (decompressed from the package, sha256 checked)."""
    from solarchain_eval.data.published import read_paper_weather_bytes

    path = tmp_path_factory.mktemp("paper-weather") / PAPER_WEATHER
    path.write_bytes(read_paper_weather_bytes())
    return path


@pytest.fixture(scope="session", autouse=True)
def isolated_cache(tmp_path_factory: pytest.TempPathFactory) -> Path:
    cache = tmp_path_factory.mktemp("solarchain-cache")
    os.environ["SOLARCHAIN_CACHE_DIR"] = str(cache)
    # Raw Stable-Baselines3 calls in tests log here instead of a new /tmp/SB3-<time> directory.
    os.environ["SB3_LOGDIR"] = str(cache / "sb3-logs")
    return cache


@pytest.fixture(scope="session")
def tiny_dataset(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A small synthetic dataset: 3 cities × 4 nodes over 4 days (fast to build and run)."""
    from solarchain_eval.data.build import build_dataset
    from solarchain_eval.data.cities import City
    from solarchain_eval.data.synthetic import synthesize_weather

    cities = (City("Wuhan", 30.5928, 114.3055), City("Xian", 34.3416, 108.9398), City("Kunming", 25.0389, 102.7183))
    out = tmp_path_factory.mktemp("tiny-dataset")
    weather = synthesize_weather(cities, "2026-06-01", "2026-06-05", 7, "Asia/Shanghai")
    build_dataset(
        weather,
        out,
        cities=cities,
        seed=7,
        start="2026-06-01",
        end="2026-06-05",
        nodes_per_city=4,
        timezone="Asia/Shanghai",
        weather_source="synthetic",
    )
    return out
