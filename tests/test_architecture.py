"""The layout is the architecture: wings import only downwards, no import circle, a small top level.

The layers (docs/architecture.md), lowest first. A module may import its own wing and any wing of
a lower rank; wings of one rank do not import each other.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "src" / "solarchain_eval"

RANKS = {
    "common": 0,
    "protocol": 0,
    "records_schema": 0,
    "config": 0,
    "data": 1,
    "tasks": 1,  # the task interface and registry: what generic wings use to reach a market
    "market": 2,
    "envs": 3,
    "agents": 3,
    "llm": 3,
    "governance": 4,
    "solar": 4,  # the solar market's task object (its internals: data, market, envs)
    "supply": 4,  # the supply-chain market: its dataset, dynamics, environments and task object
    "evaluation": 5,
    "training": 6,
    "experiments": 7,
    "report": 8,
    "perf": 8,
    "jax": 9,
    "": 9,  # the package's face: solarchain_eval/__init__.py
    "cli": 10,
}
#: Within the bottom layer, config.py may read its defaults from protocol.py and base its error on
#: common/errors.py's types.
BOTTOM_EXCEPTIONS = {("config", "protocol"), ("config", "common")}
#: The package's top level: its face and three contracts every layer reads.
TOP_LEVEL = {"__init__.py", "config.py", "protocol.py", "records_schema.py", "py.typed"}


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(PACKAGE).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _imports(path: Path, *, top_level_only: bool) -> set[str]:
    """First-party modules ``path`` imports (relative to the package), at module level or anywhere."""
    package = _package_of(_module_name(path), path)
    tree = ast.parse(path.read_text(encoding="utf-8"))
    nodes = tree.body if top_level_only else list(ast.walk(tree))
    if top_level_only:  # statements of the module body, including inside if/try blocks
        stack, nodes = list(tree.body), []
        while stack:
            node = stack.pop()
            nodes.append(node)
            if isinstance(node, ast.If | ast.Try):
                stack.extend([*node.body, *node.orelse, *getattr(node, "finalbody", [])])
                for handler in getattr(node, "handlers", []):
                    stack.extend(handler.body)
    found: set[str] = set()
    for node in nodes:
        if isinstance(node, ast.ImportFrom):
            target = _from_target(node, package)
            if target is None:
                continue
            for alias in node.names:  # `from . import x` may name a submodule
                sub = f"{target}.{alias.name}" if target else alias.name
                found.add(sub if _exists(sub) else target)
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.startswith("solarchain_eval"):
                    found.add(alias.name.removeprefix("solarchain_eval").lstrip("."))
    return found


def _package_of(module: str, path: Path) -> list[str]:
    """The package a module's relative imports start from (the module itself for an ``__init__``)."""
    return [p for p in (module.split(".") if path.name == "__init__.py" else module.split(".")[:-1]) if p]


def _from_target(node: ast.ImportFrom, package: list[str]) -> str | None:
    """The first-party module a ``from ... import`` names (relative to the package), or None."""
    if node.level:
        base = package[: len(package) - (node.level - 1)] if node.level > 1 else package
        return ".".join([*base, *([node.module] if node.module else [])])
    if node.module and node.module.startswith("solarchain_eval"):
        return node.module.removeprefix("solarchain_eval").lstrip(".")
    return None


def _exists(module: str) -> bool:
    path = PACKAGE.joinpath(*module.split("."))
    return path.with_suffix(".py").is_file() or (path / "__init__.py").is_file()


def _wing(module: str) -> str:
    return module.split(".")[0]


MODULES = {_module_name(p): p for p in sorted(PACKAGE.rglob("*.py"))}


def test_every_wing_has_a_rank():
    assert {_wing(m) for m in MODULES} <= set(RANKS), "a new wing needs a rank here and a line in docs/architecture.md"


@pytest.mark.parametrize("module", sorted(MODULES))
def test_imports_only_go_down(module):
    wing = _wing(module)
    wrong = sorted(
        target
        for target in _imports(MODULES[module], top_level_only=False)
        if _wing(target) != wing
        and RANKS[_wing(target)] >= RANKS[wing]
        and (wing, _wing(target)) not in BOTTOM_EXCEPTIONS
    )
    assert not wrong, f"{module} (layer {wing}) imports {', '.join(wrong)} from its own or a higher layer"


def test_no_import_circle():
    # Imports inside functions count: a lazy import hides a circle, it does not remove it.
    graph = {m: {t for t in _imports(p, top_level_only=False) if t in MODULES and t != m} for m, p in MODULES.items()}
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    circles: list[list[str]] = []

    def visit(node: str) -> None:  # Tarjan's strongly connected components
        index[node] = low[node] = len(index)
        stack.append(node)
        for nxt in graph[node]:
            if nxt not in index:
                visit(nxt)
                low[node] = min(low[node], low[nxt])
            elif nxt in stack:
                low[node] = min(low[node], index[nxt])
        if low[node] == index[node]:
            component = []
            while True:
                top = stack.pop()
                component.append(top)
                if top == node:
                    break
            if len(component) > 1:
                circles.append(sorted(component))

    for node in graph:
        if node not in index:
            visit(node)
    assert not circles, f"import circles: {circles}"


def test_the_top_level_is_only_the_face():
    names = {p.name for p in PACKAGE.iterdir() if not p.name.startswith("__pycache__")}
    assert {n for n in names if not (PACKAGE / n).is_dir()} == TOP_LEVEL


#: The solar market's interface to the layers that are not specific to it (docs/architecture.md,
#: "The market domain interface"): what evaluation, governance and the report may name from
#: data/ and market/. A second market domain provides the same names; widening this set is a
#: design decision, not a drive-by import.
DOMAIN_INTERFACE = {
    "evaluation": {
        "data.default.resolve_data_dir",
        "data.provenance.dataset_provenance",
        "data.table.HourlyTable",
        "data.table.load_table",
        "market.baselines.BASELINES",
    },
    # The governance layer names nothing: it reads a market through its governance view (tasks/governance_view.py).
    "governance": set(),
    "report": {"market.baselines.BASELINES"},
}


@pytest.mark.parametrize("wing", sorted(DOMAIN_INTERFACE))
def test_generic_layers_reach_the_market_only_through_its_interface(wing):
    named: set[str] = set()
    for module, path in MODULES.items():
        if _wing(module) != wing:
            continue
        package = _package_of(module, path)
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom):
                target = _from_target(node, package)
                if target is not None and _wing(target) in ("data", "market"):
                    named |= {f"{target}.{alias.name}" for alias in node.names}
    assert named <= DOMAIN_INTERFACE[wing], (
        f"{wing} names {sorted(named - DOMAIN_INTERFACE[wing])} outside the interface"
    )


#: A task's internals: the solar market's dataset pipeline, dynamics, environments and task object, and the
#: supply-chain market's wing.
TASK_INTERNALS = ("data", "market", "envs", "solar", "supply")
#: Wings that are generic over tasks: they reach a market only through ``tasks`` (the interface and registry).
GENERIC_WINGS = (
    "agents",
    "llm",
    "governance",
    "evaluation",
    "training",
    "experiments",
    "report",
    "perf",
    "cli",
    "",  # the package's face: solarchain_eval/__init__.py
)
#: Public faces of one task kept at the package's top for users (``from solarchain_eval.jax import
#: SolarChainJaxEnv``): they re-export that task's internals and hold no code of their own.
TASK_FACES = {"jax": "solar"}


def _task_internal_imports(module: str) -> list[str]:
    return sorted(t for t in _imports(MODULES[module], top_level_only=False) if _wing(t) in TASK_INTERNALS)


def test_generic_wings_reach_a_market_only_through_the_task_interface():
    offenders = sorted(m for m in MODULES if _wing(m) in GENERIC_WINGS and _task_internal_imports(m))
    assert not offenders, "generic modules import a task's internals (use solarchain_eval.tasks instead): " + "; ".join(
        f"{m} imports {', '.join(_task_internal_imports(m))}" for m in offenders
    )


@pytest.mark.parametrize("face", sorted(TASK_FACES))
def test_a_task_face_only_re_exports(face):
    """A task's face holds imports, ``__all__`` and its docstring only: no function, class or logic."""
    tree = ast.parse(MODULES[face].read_text(encoding="utf-8"))
    for node in tree.body:
        if isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant):
            continue  # the docstring
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            continue
        if isinstance(node, ast.Try):  # the optional extra's import guard
            continue
        if isinstance(node, ast.Assign) and [getattr(t, "id", None) for t in node.targets] == ["__all__"]:
            continue
        raise AssertionError(f"{face} holds {type(node).__name__} at line {node.lineno}: a task face only re-exports")
    internals = {t for t in _imports(MODULES[face], top_level_only=False) if _wing(t) in TASK_INTERNALS}
    assert {m for m in MODULES if _wing(m) == _wing(face)} == {face}, f"the {face} wing is one face module"
    assert internals, f"{face} re-exports nothing of task {TASK_FACES[face]!r}: drop it from TASK_FACES"
