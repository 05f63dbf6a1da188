"""One error base with user errors by type: every exception class of the package derives from
``SolarChainError`` through exactly one type, keeps its builtin base, and the CLI prints any of
them as one line with exit status 2 while a bug keeps its traceback."""

from __future__ import annotations

import ast
import builtins
import importlib
from pathlib import Path
from types import SimpleNamespace

import pytest
import typer
from typer.testing import CliRunner

from solarchain_eval.cli import app
from solarchain_eval.cli.common import EXIT_USAGE, reports_errors
from solarchain_eval.common import errors
from solarchain_eval.common.errors import OptionsError, SolarChainError
from solarchain_eval.evaluation.verify_rebuild import recorded_agentic
from solarchain_eval.governance.auditor import AUDITOR_KINDS
from solarchain_eval.governance.controls import TRIGGER_SETS, SchedulerControls
from solarchain_eval.governance.errors import GovernanceConfigError
from solarchain_eval.governance.factory import AgenticOptions
from solarchain_eval.governance.planner import PLANNER_KINDS
from solarchain_eval.llm.errors import LLMError
from solarchain_eval.report.leaderboard.tarballs import TarballRefused

PACKAGE = Path(__file__).resolve().parents[1] / "src" / "solarchain_eval"
BASE = "SolarChainError"
TYPES = {"InputDataError", "OptionsError", "UserAgentError", "RefusedError", "ServiceError"}
#: Classes that group others and are of no single type: the base, the option-naming mixin, the LLM family.
FAMILIES = {BASE, "NamesOptions", "LLMError"}
#: Internal signals kept outside the base on purpose (named in common/errors.py's docstring).
OUTSIDE_THE_BASE = {"_OutOfTokens"}

#: The builtin bases every error class had before the base existed: `except ValueError` and the
#: like must keep catching them.
BUILTIN_BASES = {
    "AgentError": "ValueError",
    "AgentFailure": "ValueError",
    "AgentSpecError": "ValueError",
    "ConfigError": "ValueError",
    "DatasetError": "ValueError",
    "FdiaError": "ValueError",
    "SupplyBuildError": "ValueError",
    "GovernanceRequestError": "ValueError",
    "GridError": "ValueError",
    "RunMetadataError": "ValueError",
    "ProtocolMismatch": "ValueError",
    "UnknownTaskError": "ValueError",
    "SuiteError": "ValueError",
    "UnknownSuiteError": "ValueError",
    "SuiteScoreError": "ValueError",
    "SettingError": "ValueError",
    "NoGovernanceViewError": "ValueError",
    "NoDatasetBuilderError": "ValueError",
    "HttpAgentError": "ValueError",
    "InvalidRequest": "ValueError",
    "IsolatedAgentError": "ValueError",
    "LLMCacheError": "RuntimeError",
    "LLMCacheMissError": "RuntimeError",
    "LLMConfigError": "RuntimeError",
    "LLMRefusalError": "RuntimeError",
    "LLMSchemaError": "RuntimeError",
    "LLMTransportError": "RuntimeError",
    "LLMTruncatedError": "RuntimeError",
    "LeaderboardError": "ValueError",
    "ModelNotFoundError": "FileNotFoundError",
    "PackagedWeatherError": "ValueError",
    "PortInUseError": "RuntimeError",
    "PublishedMismatchError": "ValueError",
    "RayUnavailableError": "RuntimeError",
    "ReportDataError": "ValueError",
    "RunDirError": "ValueError",
    "SweepError": "ValueError",
    "TarballRefused": "ValueError",
    "TrainingError": "ValueError",
    "UnsafeModel": "ValueError",
    "UnsafePickle": "UnpicklingError",
    "UnsupportedSchema": "ValueError",
    "VerifyError": "ValueError",
    "WeatherError": "ValueError",
    "WireError": "ValueError",
    # split from LLMConfigError, whose RuntimeError it keeps
    "GovernanceConfigError": "RuntimeError",
}


def _external_exception(dotted: str) -> bool:
    """Whether a base named outside the package (``ValueError``, ``pickle.UnpicklingError``) is an exception."""
    module, _, name = dotted.rpartition(".")
    try:
        value = getattr(importlib.import_module(module), name, None) if module else getattr(builtins, name, None)
    except ImportError:  # a module alias (`gym.Env`); no error class of the package derives through one
        return False
    return isinstance(value, type) and issubclass(value, BaseException)


def exception_classes(package: Path = PACKAGE) -> dict[str, tuple[str, list[str]]]:
    """Every exception class defined under ``package`` (read from the source): name -> (file, base names)."""
    classes: dict[str, list[tuple[str, list[str]]]] = {}
    for path in sorted(package.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ClassDef):
                bases = [ast.unparse(base) for base in node.bases]
                classes.setdefault(node.name, []).append((str(path.relative_to(package)), bases))
    found: dict[str, tuple[str, list[str]]] = {}
    changed = True
    while changed:  # a class is an exception when one of its bases is
        changed = False
        for name, definitions in classes.items():
            for where, bases in definitions:
                if name in found:
                    continue
                if any(b.rpartition(".")[2] in found or (b not in classes and _external_exception(b)) for b in bases):
                    found[name] = (where, bases)
                    changed = True
    duplicated = [n for n in found if len(classes[n]) > 1]
    assert not duplicated, f"exception classes defined twice: {duplicated}"  # names resolve by name below
    return found


def ancestors(name: str, found: dict[str, tuple[str, list[str]]]) -> set[str]:
    """The names of ``name``'s bases, transitively (package classes and builtins alike)."""
    seen: set[str] = set()
    stack = [b.rpartition(".")[2] for b in found[name][1]]
    while stack:
        base = stack.pop()
        if base not in seen:
            seen.add(base)
            stack.extend(b.rpartition(".")[2] for b in found.get(base, ("", []))[1])
    return seen


FOUND = exception_classes()


def test_the_scan_sees_every_error_class():
    assert {"DatasetError", "HttpAgentError", "UnsafePickle", "_OutOfTokens", "GovernanceConfigError"} <= set(FOUND)
    assert len(FOUND) >= 40


def test_every_exception_class_derives_from_the_base():
    outside = {n for n in FOUND if n != BASE and BASE not in ancestors(n, FOUND)}
    assert outside == OUTSIDE_THE_BASE, {n: FOUND[n][0] for n in outside ^ OUTSIDE_THE_BASE}
    for name in OUTSIDE_THE_BASE:  # each one is named, with why, where the errors are described
        assert name in (errors.__doc__ or "")


def test_every_error_class_is_of_exactly_one_type():
    assert {n for n in TYPES | FAMILIES if FOUND[n][0] != "common/errors.py"} == {"LLMError"}
    for name in set(FOUND) - FAMILIES - TYPES - OUTSIDE_THE_BASE:
        types = ancestors(name, FOUND) & TYPES
        assert len(types) == 1, f"{name} ({FOUND[name][0]}) is of types {sorted(types)}"


def test_every_error_class_keeps_its_builtin_base():
    for name, builtin in BUILTIN_BASES.items():
        assert builtin in ancestors(name, FOUND), f"{name} lost its base {builtin}"
    concrete = set(FOUND) - FAMILIES - TYPES - OUTSIDE_THE_BASE - {"CliError"}  # CliError: Exception only
    assert concrete == set(BUILTIN_BASES)


def test_the_scan_matches_the_classes_python_builds():
    from solarchain_eval.agents.safe_pickle import UnsafePickle
    from solarchain_eval.agents.sb3 import ModelNotFoundError
    from solarchain_eval.llm.errors import LLMCacheError, LLMConfigError
    from solarchain_eval.llm.serving.local_server import PortInUseError

    assert issubclass(UnsafePickle, errors.RefusedError) and issubclass(UnsafePickle, __import__("pickle").PickleError)
    assert issubclass(ModelNotFoundError, errors.InputDataError) and issubclass(ModelNotFoundError, FileNotFoundError)
    assert issubclass(LLMConfigError, OptionsError) and not issubclass(LLMConfigError, errors.ServiceError)
    assert issubclass(LLMCacheError, errors.InputDataError) and issubclass(PortInUseError, errors.ServiceError)


@pytest.mark.parametrize(
    ("build", "message"),
    [
        (
            lambda: AgenticOptions(planner="wizard"),
            f"unknown planner 'wizard' (choose from {', '.join(PLANNER_KINDS)})",
        ),
        (
            lambda: AgenticOptions(auditor="wizard"),
            f"unknown auditor 'wizard' (choose from {', '.join(AUDITOR_KINDS)})",
        ),
        (
            lambda: SchedulerControls(triggers="wind"),
            f"unknown trigger set 'wind' (choose from {', '.join(TRIGGER_SETS)})",
        ),
        (lambda: SchedulerControls(max_audits=0), "max audits must be at least 1, got 0"),
    ],
)
def test_governance_options_raise_the_governance_type(build, message):
    with pytest.raises(GovernanceConfigError) as caught:
        build()
    assert str(caught.value) == message  # no "LLM settings are incomplete" before it any more
    assert not isinstance(caught.value, LLMError)
    assert isinstance(caught.value, OptionsError) and isinstance(caught.value, RuntimeError)


def test_verify_reports_a_recorded_unknown_planner_instead_of_raising():
    recorded = SimpleNamespace(agentic={"planner": "wizard", "auditor": "rule"})  # a run's metadata, as far as read
    reason = recorded_agentic(recorded, llm_cache=None)
    assert (
        reason
        == f"the recorded Planner/Auditor options: unknown planner 'wizard' (choose from {', '.join(PLANNER_KINDS)})"
    )


def test_an_unknown_trigger_set_is_one_line_and_exit_2(tiny_dataset, tmp_path):
    out = tmp_path / "board"
    args = ["governance", "--data", str(tiny_dataset), "--episodes", "1", "--out", str(out), "--triggers", "wind"]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == EXIT_USAGE
    assert result.output.strip().splitlines() == [
        f"error: unknown trigger set 'wind' (choose from {', '.join(TRIGGER_SETS)})"
    ]
    assert not out.exists()


def _command(error: BaseException) -> typer.Typer:
    command = typer.Typer()

    @command.command()
    @reports_errors
    def fail() -> None:
        raise error

    return command


def test_any_package_error_is_one_line_and_exit_2():
    # TarballRefused was never registered with the CLI: the base alone makes it a user error
    result = CliRunner().invoke(_command(TarballRefused("run.tar.gz: not a readable tarball")), [])
    assert result.exit_code == EXIT_USAGE
    assert result.output.strip().splitlines() == ["error: run.tar.gz: not a readable tarball"]


def test_a_bug_keeps_its_traceback():
    result = CliRunner().invoke(_command(KeyError("columns")), [])
    assert result.exit_code == 1 and isinstance(result.exception, KeyError)
    result = CliRunner().invoke(_command(ValueError("a plain ValueError is not a package error")), [])
    assert result.exit_code == 1 and isinstance(result.exception, ValueError)
    assert not issubclass(ValueError, SolarChainError)


def test_the_public_api_page_lists_every_error_under_its_type():
    page = (PACKAGE.parents[1] / "docs" / "public_api.md").read_text(encoding="utf-8")
    listed: dict[str, str] = {}
    for row in page.split("## Errors", 1)[1].splitlines():
        cells = [cell.strip() for cell in row.strip("|").split("|")]
        if len(cells) == 3 and cells[0].strip("`") in TYPES:
            listed.update({name.strip(" `"): cells[0].strip("`") for name in cells[2].split(",")})
    expected = {n: (ancestors(n, FOUND) & TYPES).pop() for n in set(FOUND) - FAMILIES - TYPES - OUTSIDE_THE_BASE}
    assert listed == expected
