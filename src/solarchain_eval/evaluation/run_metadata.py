"""``run_metadata.json`` as one typed record: :class:`RunMetadata`.

The runner writes it (:meth:`RunMetadata.write`, last, atomically); verify, the report, the
leaderboard and the paper grid read it through :meth:`RunMetadata.read`, which refuses a
malformed file in one line naming the file and the field, and upgrades the forms older versions
wrote once, here, so that no reader keeps a branch of its own for them (docs/output_safety.md).

:func:`setting_protocol` is the protocol of a setting evaluated as several runs (a grid's
units, one run seed each): the paper root records it and the leaderboard ranks under it.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from pydantic import BaseModel, ConfigDict, Field, PrivateAttr, ValidationError, model_validator

from ..common.atomic_files import atomic_write_json
from ..common.errors import InputDataError
from ..protocol import EPISODE_SEED_RULES
from ..records_schema import RECORDS_SCHEMA_VERSION
from ..tasks.base import Task
from ..tasks.registry import UnknownTaskError, get_task
from .fingerprint import merge_fingerprints, protocol_fingerprint, protocol_id
from .records import METADATA_FILE

#: The environment every run that records no protocol ran (the only one before protocols were recorded).
LEGACY_ENV_ID = "SolarChainEval-v0"
#: Keys from which the protocol of a run that records none is computed.
LEGACY_PROTOCOL_KEYS = ("dataset", "run_seeds", "episodes", "episode_seed_protocol", "setting", "config")
#: Access label of a policy whose run did not record what it could see.
UNKNOWN_ACCESS = "unknown"
#: Labels of older runs, by today's name: "public" rows ran in the evaluating process.
LEGACY_ACCESS = {"public": "in-process"}


class RunMetadataError(InputDataError, ValueError):
    """A ``run_metadata.json`` that cannot be read: one line naming the file and the field."""


def rule_name(recorded: str) -> str:
    """An episode-seed rule's name from what the metadata records (the function's name, as
    ``episode_seed_protocol`` holds it)."""
    for name, rule in EPISODE_SEED_RULES.items():
        if recorded in (name, rule.__name__):
            return name
    return recorded if recorded.startswith("custom:") else f"custom:{recorded}"


class DatasetRecord(BaseModel):
    """The dataset a run used (its task's ``provenance``; a task without a dataset records ``data_dir`` None)."""

    model_config = ConfigDict(extra="allow")

    data_dir: str | None
    #: CSV name -> sha256.
    files: dict[str, str] = Field(default_factory=dict)
    #: Written only when the directory has a manifest.
    manifest_sha256: str | None = None


class RunMetadata(BaseModel):
    """Every key the runner writes, in the order it writes them.

    Keys a newer version adds are kept as they are (``extra``) and written back in place.
    """

    model_config = ConfigDict(extra="allow")

    complete: bool = Field(default=False, strict=True)
    run_id: str = ""
    #: sha256 of every file this metadata vouches for (None: written before runs recorded them).
    files: dict[str, str] | None = None
    #: The command line, redacted of credentials.
    command: list[str]
    started_at: str
    wall_s: float
    git_commit: str | None
    package_versions: dict[str, str]
    setting: str
    #: The task (market) the run evaluated (:mod:`solarchain_eval.tasks`); runs before tasks existed ran ``solar``.
    task: str = "solar"
    records_schema_version: int = RECORDS_SCHEMA_VERSION
    policies: list[str]
    policy_specs: list[str]
    #: Policy -> "isolated", "in-process", "privileged" or "unknown".
    policy_access: dict[str, str]
    #: The protocol fingerprint (:mod:`.fingerprint`) and its id.
    protocol: dict[str, Any] | None = None
    protocol_id: str | None = None
    #: The Planner/Auditor options (``AgenticOptions.describe``), None when not governed.
    agentic: dict[str, Any] | None = None
    #: The llm-agent's endpoint and cache, when it is among the policies.
    llm_agent: dict[str, Any] | None = None
    concurrency: int = 1
    run_seeds: list[int]
    episodes: int
    #: The episode-seed rule's function name (:func:`rule_name` gives its name in the protocol).
    episode_seed_protocol: str
    #: Rows written: ``{"metrics": episodes, "actions": steps}``.
    rows: dict[str, int]
    dataset: DatasetRecord
    models: dict[str, str]
    #: The task's configuration as recorded (``Task.config_record``; the solar market:
    #: ``BenchmarkConfig.model_dump()``); :meth:`task_config` validates it.
    config: dict[str, Any]

    #: Whether ``protocol`` was recorded by the run (False: computed on read, see :meth:`_upgrade`).
    _protocol_recorded: bool = PrivateAttr(default=True)
    #: Why no protocol could be computed for a run that records none ("" when there is one).
    _no_protocol: str = PrivateAttr(default="")
    _path: Path | None = PrivateAttr(default=None)

    @model_validator(mode="before")
    @classmethod
    def _upgrade_keys(cls, data: Any) -> Any:
        """The keys older versions wrote, or did not write, in today's form."""
        if not isinstance(data, dict):
            return data
        data = dict(data)
        policies = data.get("policies")
        names = [str(p) for p in policies] if isinstance(policies, list) else []
        # Runs before agent specs were recorded (before policy_access too) listed every policy given
        # as text by its spec, which is how verify rebuilds it.
        data.setdefault("policy_specs", list(names))
        access = data.get("policy_access")
        if access is None or isinstance(access, dict):
            # Runs before access labels record none (every policy "unknown"); runs before the isolated
            # door labelled in-process rows "public".
            recorded = {str(k): LEGACY_ACCESS.get(str(v), v) for k, v in (access or {}).items()}
            data["policy_access"] = {**dict.fromkeys(names, UNKNOWN_ACCESS), **recorded}
        # Runs before --llm-concurrency ran one episode at a time; runs before the record schema was
        # versioned are read with today's column names (records_schema.upgrade_columns), so they
        # take today's version (the defaults of those fields).
        return data

    @model_validator(mode="after")
    def _upgrade(self) -> RunMetadata:
        """A run written before protocols were recorded gets the protocol computed from its dataset
        checksums, run seeds, episodes, episode-seed rule, setting and config; its environment is
        :data:`LEGACY_ENV_ID` and its action modes are not known."""
        if self.protocol is not None:
            return self
        self._protocol_recorded = False
        if not self.dataset.files:
            self._no_protocol = "records no protocol and lacks dataset.files to compute one"
            return self
        try:
            config = self.task_config()
        except RunMetadataError as error:
            self._no_protocol = f"records no protocol, and {error}"
            return self
        fingerprint = protocol_fingerprint(
            dataset_sha256=self.dataset.files,
            run_seeds=self.run_seeds,
            episodes=self.episodes,
            episode_seed_rule=rule_name(self.episode_seed_protocol),
            setting=self.setting,
            config=config,
            action_modes={},
        )
        fingerprint["env"] = LEGACY_ENV_ID
        fingerprint["records_schema_version"] = self.records_schema_version
        self.protocol, self.protocol_id = fingerprint, protocol_id(fingerprint)
        return self

    @classmethod
    def read(cls, path: Path | str) -> RunMetadata:
        """The record in ``path`` (a run directory's ``run_metadata.json``), older forms upgraded.

        Raises
        ------
        RunMetadataError
            The file is missing, not JSON, not an object, or a field is missing or of the wrong
            type (the message names the file and the first such field).
        """
        path = Path(path)
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except OSError as error:
            raise RunMetadataError(f"{path} is unreadable ({error.strerror or error})") from None
        except ValueError as error:
            raise RunMetadataError(f"{path} is not valid JSON ({error})") from None
        return cls.from_record(data, path)

    @classmethod
    def from_record(cls, data: Any, path: Path | str) -> RunMetadata:
        """The record ``data`` (a parsed ``run_metadata.json`` from ``path``), validated and upgraded."""
        if not isinstance(data, dict):
            raise RunMetadataError(f"{path} does not hold a JSON object")
        try:
            metadata = cls.model_validate(data)
        except ValidationError as error:
            problem = error.errors()[0]
            field = ".".join(str(p) for p in problem["loc"]) or "<top level>"
            raise RunMetadataError(f"{path}: field {field}: {problem['msg']}") from None
        metadata._path = Path(path)
        return metadata

    def write(self, path: Path | str) -> Path:
        """Write the record to ``path`` atomically (strict JSON, two-space indent)."""
        return atomic_write_json(path, self.to_dict())

    def to_dict(self) -> dict[str, Any]:
        """The JSON object the file holds (keys absent from the record stay absent)."""
        return self.model_dump(exclude_unset=True)

    @property
    def where(self) -> str:
        """The file the record was read from (its name when it was not read)."""
        return str(self._path) if self._path is not None else METADATA_FILE

    @property
    def protocol_recorded(self) -> bool:
        """Whether the run recorded its protocol (False: computed from the older keys on read, or none)."""
        return self._protocol_recorded

    def resolve_task(self) -> Task:
        """The task the run evaluated, from the tasks installed here (never code the record names).

        Raises
        ------
        RunMetadataError
            No installed task has the recorded name (the message lists those there are).
        """
        try:
            return get_task(self.task)
        except UnknownTaskError as error:
            raise RunMetadataError(f"{self.where}: field task: {error}; install the package that provides it") from None

    def task_config(self) -> Any:
        """The recorded configuration, validated by the run's task (the solar market: a ``BenchmarkConfig``).

        Raises
        ------
        RunMetadataError
            It is not one this version reads (the message names the field), or the task is not installed.
        """
        task = self.resolve_task()
        try:
            return task.config_from_record(self.config)
        except ValidationError as error:
            problem = error.errors()[0]
            field = ".".join(str(p) for p in ("config", *problem["loc"]))
            raise RunMetadataError(f"{self.where}: field {field}: {problem['msg']}") from None
        except (TypeError, ValueError) as error:
            raise RunMetadataError(f"{self.where}: field config: {error}") from None

    def fingerprint(self) -> dict[str, Any]:
        """The run's protocol fingerprint (recorded, or computed for an older run).

        Raises
        ------
        RunMetadataError
            The run records no protocol and one cannot be computed (the message says why).
        """
        if self.protocol is None:
            raise RunMetadataError(f"{self.where} {self._no_protocol} (written by an older version)")
        return dict(self.protocol)


class ProtocolMismatch(InputDataError, ValueError):
    """Runs of one setting evaluated under different protocols (the message names both runs)."""


def setting_protocol(runs: Mapping[str, RunMetadata]) -> dict[str, Any]:
    """The protocol of one setting evaluated as several runs, by name (a grid's units, each one
    run seed): their fingerprints merged, run seeds united, action modes merged
    (:func:`~.fingerprint.merge_fingerprints`).

    Raises
    ------
    RunMetadataError
        A run records no protocol and none can be computed.
    ProtocolMismatch
        Two runs differ in another protocol field (the message names the first run and the other).
    """
    if not runs:
        raise ValueError("no runs to merge")
    (first, meta), *others = runs.items()
    merged = meta.fingerprint()
    for name, other in others:
        fingerprint = other.fingerprint()
        try:
            merged = merge_fingerprints([merged, fingerprint])
        except ValueError as error:
            raise ProtocolMismatch(f"{first} and {name} were evaluated under different protocols: {error}") from None
    return merged
