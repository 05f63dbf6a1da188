"""``run_metadata.json`` through its model: a fresh run's file round-trips byte for byte, every form
older versions wrote is read (and still reports, ranks and verifies), a malformed file is refused
in one line naming the file and the field, and one setting protocol serves the paper and the board."""

from __future__ import annotations

import json
import shutil
import tarfile
from pathlib import Path

import pytest
from typer.testing import CliRunner

from solarchain_eval.cli import app
from solarchain_eval.common.atomic_files import sha256_file
from solarchain_eval.config import BenchmarkConfig
from solarchain_eval.data.files import DATASET_FILES
from solarchain_eval.evaluation.fingerprint import protocol_fingerprint, protocol_id
from solarchain_eval.evaluation.run_metadata import (
    LEGACY_ENV_ID,
    ProtocolMismatch,
    RunMetadata,
    RunMetadataError,
    setting_protocol,
)
from solarchain_eval.evaluation.rundir import verify_run_dir
from solarchain_eval.evaluation.verify import VERIFIED, VerifyOptions, verify_run
from solarchain_eval.experiments import paper
from solarchain_eval.protocol import PAPER_EPISODES, PAPER_SEEDS
from solarchain_eval.records_schema import RECORDS_SCHEMA_VERSION
from solarchain_eval.report.leaderboard.inputs import LeaderboardError, open_inputs
from solarchain_eval.report.loading import ReportDataError, load_report_data

RUN_SEED, EPISODES = 5, 2
#: The keys the runner writes, in its order (a reader of the file may rely on both).
WRITTEN_KEYS = [
    "complete", "run_id", "files", "command", "started_at", "wall_s", "git_commit", "package_versions", "setting",
    "records_schema_version", "policies", "policy_specs", "policy_access", "protocol", "protocol_id", "agentic",
    "llm_agent", "concurrency", "run_seeds", "episodes", "episode_seed_protocol", "rows", "dataset", "models", "config",
]  # fmt: skip
#: What runs written before protocols, agent specs and access labels were recorded lack (and the
#: still older runs before --llm-concurrency, the llm-agent and the records schema version).
BEFORE_PROTOCOLS = ("protocol", "protocol_id", "policy_access", "policy_specs", "llm_agent")
BEFORE_CONCURRENCY = ("concurrency", "records_schema_version")


def invoke(*args):
    return CliRunner().invoke(app, [str(a) for a in args])


@pytest.fixture(scope="module")
def pristine(tiny_dataset, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("runs") / "run"
    made = invoke("evaluate", "--data", tiny_dataset, "--policies", "static,myopic", "--seeds", RUN_SEED,
                  "--episodes", EPISODES, "--out", out)  # fmt: skip
    assert made.exit_code == 0, made.output
    return out


@pytest.fixture
def run(pristine, tmp_path) -> Path:
    copy = tmp_path / "run"
    shutil.copytree(pristine, copy)
    return copy


def raw(run: Path) -> dict:
    return json.loads((run / "run_metadata.json").read_text())


def rewrite(run: Path, edit) -> dict:
    meta = raw(run)
    edit(meta)
    (run / "run_metadata.json").write_text(json.dumps(meta))
    return meta


def test_a_fresh_run_round_trips_byte_for_byte(pristine, tmp_path):
    path = pristine / "run_metadata.json"
    record = RunMetadata.read(path)
    assert list(json.loads(path.read_text())) == WRITTEN_KEYS
    record.write(tmp_path / "again.json")
    assert (tmp_path / "again.json").read_bytes() == path.read_bytes()
    assert record.protocol_recorded and record.protocol_id == protocol_id(record.fingerprint())
    assert record.policy_access == {"static": "in-process", "myopic": "in-process"}
    assert record.rows == {"metrics": 2 * EPISODES, "actions": record.rows["actions"]} and record.rows["actions"] > 0


def test_every_older_form_is_read_in_todays_form(run):
    fresh = RunMetadata.read(run / "run_metadata.json")

    def oldest(meta):
        for key in (*BEFORE_PROTOCOLS, *BEFORE_CONCURRENCY, "agentic"):
            meta.pop(key)

    rewrite(run, oldest)
    old = RunMetadata.read(run / "run_metadata.json")
    assert old.policy_specs == old.policies == ["static", "myopic"]  # what verify rebuilds them from
    assert old.policy_access == {"static": "unknown", "myopic": "unknown"}
    assert (old.concurrency, old.records_schema_version, old.agentic, old.llm_agent) == (
        1,
        RECORDS_SCHEMA_VERSION,
        None,
        None,
    )
    assert not old.protocol_recorded and old.fingerprint()["env"] == LEGACY_ENV_ID
    assert old.fingerprint()["action_modes"] == {} and old.protocol_id == fresh.protocol_id  # modes are not hashed
    assert old.fingerprint()["episode_seed_rule"] == "paper"  # from the function's name the run records
    assert "concurrency" not in old.to_dict()  # a key the file lacks is not invented when written back

    rewrite(run, lambda meta: meta.update(policy_access={"static": "public"}))  # before the isolated door
    assert RunMetadata.read(run / "run_metadata.json").policy_access == {"static": "in-process", "myopic": "unknown"}

    rewrite(run, lambda meta: [meta.pop(k) for k in ("run_id", "files")])  # before run directories vouched
    assert RunMetadata.read(run / "run_metadata.json").files is None
    assert verify_run_dir(run) == [
        f"{run / 'run_metadata.json'} records no sha256 of the files it vouches for (written by an older version?)"
    ]


def test_a_run_from_before_protocols_still_reports_ranks_and_verifies(run, pristine, tmp_path):
    rewrite(run, lambda meta: [meta.pop(k) for k in (*BEFORE_PROTOCOLS, *BEFORE_CONCURRENCY, "agentic")])
    data = load_report_data(run)
    assert data.run_metadata is not None and data.metadata["policy_access"] == {
        "static": "unknown",
        "myopic": "unknown",
    }
    reported = invoke("report", run, "--no-figures", "--format", "html", "--resamples", "100", "--out", tmp_path / "r")
    assert reported.exit_code == 0, reported.output
    with open_inputs([run]) as old, open_inputs([pristine]) as current:
        assert old[0].protocol_id == current[0].protocol_id and old[0].board_id == current[0].board_id
        assert set(old[0].access.values()) == {"unknown"}
    verified = verify_run(run, VerifyOptions(episodes=1, seed=0))
    assert [(p.policy, p.status) for p in verified.policies] == [("static", VERIFIED), ("myopic", VERIFIED)]
    assert verified.protocol_problems == (
        "run_metadata.json records no protocol fingerprint (written by an older version?)",
    )
    assert verified.protocol_id == raw(pristine)["protocol_id"]


@pytest.mark.parametrize(
    ("edit", "field", "why"),
    [
        (lambda m: m.update(run_seeds="5"), "run_seeds", "valid list"),
        (lambda m: m.pop("setting"), "setting", "Field required"),
        (lambda m: m.update(complete="yes"), "complete", "valid boolean"),
        (lambda m: m["dataset"].update(files=["a.csv"]), "dataset.files", "valid dictionary"),
        (lambda m: m["policy_access"].update(static=3), "policy_access.static", "valid string"),
    ],
)
def test_a_malformed_file_is_refused_naming_file_and_field(run, tmp_path, edit, field, why):
    path = run / "run_metadata.json"
    rewrite(run, edit)
    with pytest.raises(RunMetadataError) as refused:
        RunMetadata.read(path)
    assert str(refused.value).startswith(f"{path}: field {field}: ") and why in str(refused.value)
    tarball = tmp_path / "run.tar.gz"
    with tarfile.open(tarball, "w:gz") as archive:  # refused before anything is unpacked
        archive.add(run, arcname="run")
    for command in (("verify", run), ("report", run, "--no-figures", "--out", tmp_path / "r"),
                    ("leaderboard", run, "--out", tmp_path / "b"),
                    ("leaderboard", tarball, "--out", tmp_path / "b")):  # fmt: skip
        result = invoke(*command)
        assert result.exit_code == 2, (command, result.output)
        assert f"field {field}:" in " ".join(result.output.split()), (command, result.output)
    assert not (tmp_path / "r").exists() and not (tmp_path / "b").exists()


def test_not_json_and_not_an_object_are_named(run):
    path = run / "run_metadata.json"
    path.write_text("{")
    with pytest.raises(RunMetadataError, match=rf"^{path} is not valid JSON"):
        RunMetadata.read(path)
    path.write_text("[]")
    with pytest.raises(RunMetadataError, match=rf"^{path} does not hold a JSON object$"):
        RunMetadata.read(path)
    with pytest.raises(ReportDataError, match="does not hold a JSON object"):
        load_report_data(run, allow_unverified=True)


def test_an_unreadable_config_is_named_by_its_field(run):
    rewrite(run, lambda meta: meta["config"].update(episode_steps="many"))
    record = RunMetadata.read(run / "run_metadata.json")  # the record reads; its config does not validate
    with pytest.raises(RunMetadataError, match=r"field config\.episode_steps: "):
        record.task_config()
    verified = verify_run(run, VerifyOptions(episodes=1))
    assert verified.protocol_problems[0].startswith("the recorded config is invalid: ")
    assert "config.episode_steps" in verified.protocol_problems[0]
    with (
        pytest.raises(LeaderboardError, match=r"field config\.episode_steps: .*cannot be compared"),
        open_inputs([run]),
    ):
        pass


def _paper_unit(seed: int, files: dict[str, str], **fingerprint) -> RunMetadata:
    """An eval unit of the paper's main setting as the runner records it (one run seed)."""
    config = BenchmarkConfig()
    protocol = protocol_fingerprint(
        dataset_sha256=files, run_seeds=[seed], episodes=PAPER_EPISODES, episode_seed_rule="paper",
        setting="main", config=config, action_modes={"static": "continuous"},
    )  # fmt: skip
    protocol.update(fingerprint)
    return RunMetadata(
        complete=True, command=["solarchain-eval", "paper"], started_at="2026-11-28T00:00:00+00:00", wall_s=1.0,
        git_commit=None, package_versions={}, setting="main", policies=["static"], policy_specs=["static"],
        policy_access={"static": "in-process"}, protocol=protocol, protocol_id=protocol_id(protocol),
        run_seeds=[seed], episodes=PAPER_EPISODES, episode_seed_protocol="paper_episode_seeds",
        rows={"metrics": PAPER_EPISODES}, dataset={"data_dir": "/data", "files": files}, models={},
        config=config.model_dump(),
    )  # fmt: skip


def test_one_setting_protocol_keeps_the_paper_runs_id(shared_data, tmp_path):
    published = shared_data / "published_2026_04"
    files = {name: sha256_file(published / name) for name in DATASET_FILES}
    units = {f"static-main-{seed}": _paper_unit(seed, files) for seed in PAPER_SEEDS}
    merged = setting_protocol(units)
    assert merged["run_seeds"] == sorted(PAPER_SEEDS) and protocol_id(merged) == "89e17532f325"
    # The paper root records the same protocol from its unit directories.
    for name, unit in units.items():
        (tmp_path / name).mkdir()
        unit.write(tmp_path / name / "run_metadata.json")
    recorded = paper.setting_protocol([tmp_path / name for name in units])
    assert recorded == {"protocol": merged, "protocol_id": "89e17532f325"}
    # A unit from before protocols were recorded merges to the same id.
    legacy = units[f"static-main-{PAPER_SEEDS[0]}"].to_dict()
    legacy.pop("protocol"), legacy.pop("protocol_id")
    units[f"static-main-{PAPER_SEEDS[0]}"] = RunMetadata.from_record(legacy, "old/run_metadata.json")
    assert protocol_id(setting_protocol(units)) == "89e17532f325"
    units["other"] = _paper_unit(7, files, episodes=3)
    with pytest.raises(ProtocolMismatch, match=r"static-main-\d+ and other were evaluated under different protocols"):
        setting_protocol(units)
