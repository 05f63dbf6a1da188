"""The YAML of ``solarchain-eval sweep``: its schema, validation and expansion into points.

A sweep is a base grid (budgets, seeds, settings, policies), a base dataset (an existing
directory, or build parameters), an optional benchmark config, and ``axes``: each axis a list of
values. The points are the Cartesian product of the axes, in the order the YAML lists them;
each point is one grid (see :mod:`.sweep`). docs/stress.md#sweep-yaml documents every key.

The dataset section and the dataset axes are the build parameters of the sweep's task's dataset
builder (:mod:`~solarchain_eval.tasks.dataset`): a key the builder does not read is refused, and a
key not given takes the builder's default (the solar market's are the schema's own defaults).
"""

from __future__ import annotations

import hashlib
import itertools
import json
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError

from ..common.errors import OptionsError
from ..config import BenchmarkConfig, ConfigError, UniqueKeyLoader, config_from_mapping, load_config, read_config_text
from ..protocol import EPISODE_SEED_RULES, PAPER_SEED
from ..tasks.dataset import ScenarioDatasetBuilder, dataset_of, has_dataset_builder
from ..tasks.registry import DEFAULT_TASK, get_task
from ..training.lagrangian import DEFAULT_COST_LIMIT, DEFAULT_MULTIPLIER_LR, LagrangianSettings


class SweepError(OptionsError, ValueError):
    """A sweep YAML that is unreadable or invalid (the message names the file and key)."""


#: The builder of the dataset section's datasets: the solar market's (its defaults are the section's).
DATASET = dataset_of(get_task(DEFAULT_TASK))
_DEFAULTS = DATASET.defaults
_FALSE_DATA = DATASET.false_data

#: The names the YAML accepts, from their one definition (the builder's patterns, protocol.py).
FdiaPatternName = Literal[_FALSE_DATA.patterns]  # type: ignore[valid-type]
EpisodeSeedRuleName = Literal[tuple(EPISODE_SEED_RULES)]  # type: ignore[valid-type]


class _Section(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)


class SweepGrid(_Section):
    timesteps: int = Field(2048, ge=1, le=10**9)
    episodes: int = Field(5, ge=1, le=10**6)
    seeds: list[int] = Field(default_factory=lambda: [PAPER_SEED], min_length=1)
    settings: list[str] = Field(default_factory=lambda: ["main", "no_physics"], min_length=1)
    #: A list, or a list per setting: built-in policies and agent specs (paths relative to the YAML).
    policies: list[str] | dict[str, list[str]] | None = None
    episode_seeds: EpisodeSeedRuleName = "paper"
    checkpoint_every: int = Field(0, ge=0)
    #: Options of the user agents built from a class or factory: ``KEY: VALUE`` or ``NAME.KEY: VALUE``.
    agent_args: dict[str, Any] = Field(default_factory=dict)
    #: VecNormalize statistics of ``sb3:`` agents: a path (the only one) or ``{NAME: PATH}``.
    vecnormalize: str | dict[str, str] | None = None
    #: Run each user agent in a process of its own, as ``paper --isolate`` does.
    isolate: bool = False


class SweepDataset(_Section):
    data: str | None = None
    weather_cache: str | None = None
    seed: int = Field(_DEFAULTS.seed, ge=0, le=2**32 - 1)
    start: str = _DEFAULTS.start
    end: str = _DEFAULTS.end
    timezone: str = _DEFAULTS.timezone
    nodes_per_city: int = Field(_DEFAULTS.nodes_per_city, ge=1, le=100_000)
    cities: int | list[str] | None = None
    fdia_rate: float = Field(_FALSE_DATA.default_rate, ge=0.0, le=1.0)
    fdia_pattern: FdiaPatternName = _FALSE_DATA.default_pattern
    fdia_severity: str | None = None
    fdia_burst_hours: int = Field(_FALSE_DATA.default_burst_hours, ge=1)


class SweepLagrangian(_Section):
    cost_limit: float = Field(DEFAULT_COST_LIMIT, ge=0.0)
    multiplier_lr: float = Field(DEFAULT_MULTIPLIER_LR, ge=0.0)


class SweepFile(_Section):
    grid: SweepGrid = Field(default_factory=SweepGrid)
    dataset: SweepDataset = Field(default_factory=SweepDataset)
    config: str | None = None
    ppo_lag: SweepLagrangian = Field(default_factory=SweepLagrangian)
    axes: dict[str, list[Any]] = Field(default_factory=dict)
    bootstrap_resamples: int = Field(2000, ge=100, le=100_000)


#: Axis name -> where it acts. Reward weights also answer to the config's own key.
DATASET_AXES = ("fdia_rate", "fdia_pattern", "fdia_severity", "fdia_burst_hours", "nodes_per_city", "cities")
REWARD_AXES = {
    "lambda_p": "physics_penalty",
    "lambda_d": "drawdown_penalty",
    "lambda_j": "action_jitter_penalty",
    "lambda_u": "unmet_demand_penalty",
    "lambda_f": "fairness_penalty",
}
LAGRANGIAN_AXES = ("cost_limit", "multiplier_lr")
AXES = (*DATASET_AXES, *REWARD_AXES, *REWARD_AXES.values(), *LAGRANGIAN_AXES)


@dataclass(frozen=True)
class SweepPoint:
    """One point of the sweep: axis values, its dataset and its grid's config."""

    point_id: str
    values: dict[str, Any]
    dataset: SweepDataset
    dataset_key: str
    config: BenchmarkConfig
    lagrangian: LagrangianSettings

    @property
    def uses_existing_data(self) -> bool:
        return self.dataset.data is not None


@dataclass(frozen=True)
class Sweep:
    """A loaded sweep: its file, validated spec, points and the task its datasets are built for."""

    source: Path
    spec: SweepFile
    points: tuple[SweepPoint, ...]
    task: str = DEFAULT_TASK

    @property
    def axes(self) -> tuple[str, ...]:
        return tuple(self.spec.axes)

    def identity(self) -> dict[str, Any]:
        # grid.isolate is left out: the units record their door themselves (a change redoes them),
        # and a sweep root made before the option existed keeps its identity.
        return self.spec.model_dump(mode="json", exclude={"grid": {"isolate"}})


def _slug(value: Any) -> str:
    text = str(value)
    return re.sub(r"[^A-Za-z0-9.]+", "-", text).strip("-") or "x"


def point_id(values: dict[str, Any]) -> str:
    """A readable directory name: ``axis-value`` pairs joined by ``__`` (``base`` without axes)."""
    return "__".join(f"{k}-{_slug(v)}" for k, v in values.items()) or "base"


def dataset_cities(dataset: SweepDataset) -> tuple[Any, ...]:
    """The cities of a point's build (the builder's: none given, the paper's; a number, synthetic ones).

    Raises
    ------
    ValueError
        A city that cannot be read, or two sharing a node-id prefix.
    """
    return DATASET.cities(dataset.cities)


def fdia_scenario(dataset: SweepDataset, builder: ScenarioDatasetBuilder = DATASET) -> Any:
    """The false-data scenario of a point's build (``ValueError``: a knob out of range)."""
    return builder.scenario(dataset.fdia_rate, dataset.fdia_severity, dataset.fdia_pattern, dataset.fdia_burst_hours)


def build_parameters(dataset: SweepDataset, builder: ScenarioDatasetBuilder) -> dict[str, Any]:
    """The values of the builder's build parameters in a point's dataset section."""
    dump = dataset.model_dump(mode="json")
    return {key: dump[key] for key in builder.parameters}


def dataset_key(dataset: SweepDataset, task: str = DEFAULT_TASK, builder: ScenarioDatasetBuilder | None = None) -> str:
    """Directory name of a built dataset: a hash of its build parameters.

    The solar market's hash covers the whole section (as it always has: existing sweep roots
    resume); another task's covers its task name and its builder's parameters.
    """
    if task == DEFAULT_TASK or builder is None:
        payload = json.dumps(dataset.model_dump(mode="json"), sort_keys=True)
    else:
        payload = json.dumps({"task": task, **build_parameters(dataset, builder)}, sort_keys=True)
    return "ds-" + hashlib.sha256(payload.encode()).hexdigest()[:12]


def _task_builder(task: str) -> ScenarioDatasetBuilder | None:
    market = get_task(task)
    return dataset_of(market) if has_dataset_builder(market) else None


def _with_builder_defaults(source: Path, payload: dict[str, Any], task: str, builder: ScenarioDatasetBuilder | None):
    """``payload`` with the task builder's defaults in the dataset section; a key or axis the
    builder does not read is a :class:`SweepError`."""
    if task == DEFAULT_TASK or builder is None or not isinstance(payload.get("dataset", {}), dict):
        return payload  # the solar market's defaults are the schema's; a bad section fails validation
    section = dict(payload.get("dataset") or {})
    taken = {"data", *builder.parameters}
    for key in section:
        if key not in taken and key in SweepDataset.model_fields:
            raise SweepError(f"{source}: dataset.{key}: the {task} task's datasets take no {key}")
    for axis in payload.get("axes") or {}:
        if axis in DATASET_AXES and axis not in builder.parameters:
            raise SweepError(f"{source}: axes.{axis}: the {task} task's datasets take no {axis}")
    d, knobs = builder.defaults, builder.false_data
    defaults = {"seed": d.seed, "start": d.start, "end": d.end, "fdia_rate": knobs.default_rate}
    defaults.update(fdia_pattern=knobs.default_pattern, fdia_burst_hours=knobs.default_burst_hours)
    return {**payload, "dataset": {**defaults, **section}}


def _where(item: dict) -> str:
    return ".".join(str(part) for part in item["loc"]) or "<top level>"


def _load_yaml(path: Path) -> dict[str, Any]:
    import yaml

    try:
        text = read_config_text(path)
    except ConfigError as error:
        raise SweepError(str(error).replace("config file", "sweep file")) from None
    try:
        payload = yaml.load(text, Loader=UniqueKeyLoader)
    except yaml.YAMLError as error:
        mark = getattr(error, "problem_mark", None)
        where = f" (line {mark.line + 1}, column {mark.column + 1})" if mark is not None else ""
        raise SweepError(f"{path} is not valid YAML: {getattr(error, 'problem', None) or error}{where}") from None
    if not isinstance(payload, dict):
        raise SweepError(f"{path}: the top level must be a mapping of keys to values")
    return payload


def _point(
    source: Path,
    spec: SweepFile,
    base: BenchmarkConfig,
    values: dict[str, Any],
    where: dict[str, str],
    task: str = DEFAULT_TASK,
    builder: ScenarioDatasetBuilder | None = DATASET,
) -> SweepPoint:
    data_values = {k: v for k, v in values.items() if k in DATASET_AXES}
    try:
        dataset = SweepDataset.model_validate({**spec.dataset.model_dump(), **data_values})
    except ValidationError as error:
        item = error.errors()[0]
        raise SweepError(f"{source}: {where.get(str(item['loc'][0]), _where(item))}: {item['msg']}") from None
    if data_values and dataset.data is not None:
        key = next(iter(data_values))
        raise SweepError(f"{source}: {where[key]}: a dataset axis needs build parameters, not dataset.data")
    reward = base.reward.model_dump()
    for k, v in values.items():
        if k in REWARD_AXES or k in REWARD_AXES.values():
            reward[REWARD_AXES.get(k, k)] = v
    try:
        config = config_from_mapping({**base.model_dump(), "reward": reward}, str(source))
        if builder is not None and "cities" in builder.parameters:
            builder.cities(dataset.cities)  # type: ignore[attr-defined]  # cities unreadable or sharing a prefix
        if builder is not None:
            fdia_scenario(dataset, builder)
        lag = {**spec.ppo_lag.model_dump(), **{k: v for k, v in values.items() if k in LAGRANGIAN_AXES}}
        lagrangian = LagrangianSettings(float(lag["cost_limit"]), float(lag["multiplier_lr"]))
    except (ConfigError, ValueError, TypeError) as error:
        keys = ", ".join(where[k] for k in values) or "dataset/ppo_lag"
        raise SweepError(f"{source}: {keys}: {error}") from None
    key = dataset_key(dataset, task, builder) if dataset.data is None else "given"
    return SweepPoint(point_id(values), values, dataset, key, config, lagrangian)


def load_sweep(path: str | Path, task: str = DEFAULT_TASK) -> Sweep:
    """Read and validate a sweep YAML for ``task`` and expand its axes into points.

    The dataset section's defaults and the dataset keys and axes it accepts are those of the
    task's dataset builder (see the module docstring).

    Raises
    ------
    SweepError
        One line naming the file and the key at fault.
    """
    source = Path(path)
    builder = _task_builder(task)
    payload = _with_builder_defaults(source, _load_yaml(source), task, builder)
    try:
        spec = SweepFile.model_validate(payload)
    except ValidationError as error:
        item = error.errors()[0]
        problem = "unknown key" if item["type"] == "extra_forbidden" else item["msg"]
        raise SweepError(f"{source}: {_where(item)}: {problem}") from None
    for axis, values in spec.axes.items():
        if axis not in AXES:
            raise SweepError(f"{source}: axes.{axis}: unknown axis (choose from {', '.join(AXES)})")
        if not values:
            raise SweepError(f"{source}: axes.{axis}: give at least one value")
        if len({json.dumps(v, sort_keys=True) for v in values}) != len(values):
            raise SweepError(f"{source}: axes.{axis}: a value is listed twice")
    canonical = [REWARD_AXES.get(a, a) for a in spec.axes]
    if len(set(canonical)) != len(canonical):
        raise SweepError(f"{source}: axes: a reward weight is given twice (by its λ name and its config key)")
    base = BenchmarkConfig()
    if spec.config is not None:
        config_path = Path(spec.config) if Path(spec.config).is_absolute() else source.parent / spec.config
        try:
            base = load_config(config_path)
        except ConfigError as error:
            raise SweepError(f"{source}: config: {error}") from None
    points = []
    names = list(spec.axes)
    for combo in itertools.product(*(enumerate(spec.axes[a]) for a in names)):
        values = {a: v for a, (_, v) in zip(names, combo, strict=True)}
        where = {a: f"axes.{a}[{i}]" for a, (i, _) in zip(names, combo, strict=True)}
        points.append(_point(source, spec, base, values, where, task, builder))
    ids = [p.point_id for p in points]
    if len(set(ids)) != len(ids):
        raise SweepError(f"{source}: axes: two points share the directory name {ids[0]!r}; use distinct values")
    return Sweep(source, spec, tuple(points), task)
