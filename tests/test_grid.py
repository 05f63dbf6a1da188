"""The paper grid: planning, episode seeds, smoke preset end to end with 2 workers, resume after
SIGKILL, failing units, and the same grid through a local Ray instance."""

from __future__ import annotations

import hashlib
import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from solarchain_eval.evaluation.settings import KNOWN_SETTINGS, Setting
from solarchain_eval.experiments.grid import (
    GridSpec,
    plan_units,
)
from solarchain_eval.experiments.paper import GridError, run_paper
from solarchain_eval.protocol import independent_episode_seeds

CLI = [sys.executable, "-c", "from solarchain_eval.cli import main; main()"]
TABLES = ("metrics.csv", "actions.csv", "city_hour_policy.csv")
POLICY_ORDER = ["static", "random", "myopic", "ppo", "sac", "dqn"]


def _paper_cmd(root: Path, data: Path, *extra: str) -> list[str]:
    return [*CLI, "paper", "--preset", "smoke", "--out", str(root), "--data", str(data), *extra]


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _done_units(root: Path) -> list[Path]:
    return sorted(p.parent for p in (root / "units").glob("*/*/DONE"))


def test_independent_episode_seeds_are_documented_prefix_stable_and_disjoint():
    seeds = {s: independent_episode_seeds(s, 30) for s in (20260511, 20260512, 20260513)}
    words = np.random.SeedSequence(entropy=20260511, spawn_key=(0x45504953,)).generate_state(30, dtype=np.uint64)
    assert seeds[20260511] == [int(w) >> 1 for w in words]
    assert independent_episode_seeds(20260511, 5) == seeds[20260511][:5]
    pooled = [e for v in seeds.values() for e in v]
    assert len(set(pooled)) == 90 and all(0 <= e < 2**63 for e in pooled)
    # the paper protocol shares 29 of 30 episode seeds between consecutive run seeds
    paper = {s: set(range(s, s + 30)) for s in seeds}
    assert len(paper[20260511] & paper[20260512]) == 29


def test_plan_of_the_paper_preset_with_its_agentic_settings(monkeypatch):
    spec = GridSpec.from_preset("paper")
    units = plan_units(spec)
    trains = [u for u in units if u.kind == "train"]
    evals = [u for u in units if u.kind == "eval"]
    # 3 algorithms × 2 training settings × 3 seeds; 6 policies × 3 seeds in main and no_physics,
    # 3 learned policies × 3 seeds in llm and llm_no_physics (which reuse those models).
    assert (len(trains), len(evals)) == (18, 54)
    assert [u.depends_on for u in evals if u.name == "eval/dqn-llm_no_physics-20260513"] == [
        ("train/dqn-no_physics-20260513",)
    ]
    assert [u.depends_on for u in evals if u.name == "eval/sac-llm-20260511"] == [("train/sac-main-20260511",)]
    assert [u.policy for u in trains[:6]] == ["sac"] * 6  # the longest units first
    ppo_eval = next(u for u in evals if u.name == "eval/ppo-no_physics-20260512")
    assert ppo_eval.depends_on == ("train/ppo-no_physics-20260512",)
    assert all(not u.depends_on for u in evals if u.policy in ("static", "random", "myopic"))
    # a registered setting that reuses the main models plans its units the same way
    monkeypatch.setitem(KNOWN_SETTINGS, "extra", Setting("extra", False, False, "main", "Extra", "extra", ("ppo",)))
    spec = GridSpec.from_preset("paper", settings=("main", "extra"))
    units = plan_units(spec)
    assert len([u for u in units if u.kind == "train"]) == 9
    extra = [u for u in units if u.setting == "extra"]
    assert len(extra) == 3 and extra[0].depends_on == ("train/ppo-main-20260511",)


@pytest.fixture(scope="module")
def smoke_root(tmp_path_factory, tiny_dataset) -> Path:
    """The smoke preset run once, uninterrupted, with 2 local workers."""
    root = tmp_path_factory.mktemp("smoke") / "root"
    started = time.monotonic()
    done = subprocess.run(_paper_cmd(root, tiny_dataset, "--workers", "2"), capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    root.joinpath("elapsed_s").write_text(f"{time.monotonic() - started:.1f}")
    root.parent.joinpath("stdout.txt").write_text(done.stdout)
    return root


def test_smoke_preset_end_to_end_with_two_workers(smoke_root):
    units = _done_units(smoke_root)
    assert len(units) == 24
    meta = json.loads((smoke_root / "paper_metadata.json").read_text())
    assert meta["complete"] and meta["status"] == "complete" and meta["execution"]["workers"] == 2
    assert all(entry["status"] == "done" and entry["wall_s"] > 0 for entry in meta["units"].values())
    # Each unit's CPU time: spent by its worker, so positive and within its wall time on every core.
    cores = os.cpu_count() or 1
    assert all(0 < entry["cpu_s"] <= entry["wall_s"] * cores + 0.1 for entry in meta["units"].values())
    cpu_total = sum(entry["cpu_s"] for entry in meta["units"].values())
    printed = (smoke_root.parent / "stdout.txt").read_text()
    assert abs(float(re.search(r"units run now: 24, ([0-9.]+) CPU s\)", printed).group(1)) - cpu_total) < 0.07
    for setting in ("main", "no_physics"):
        combined = smoke_root / "combined" / setting
        metrics = pd.read_csv(combined / "metrics.csv")
        assert list(metrics["policy"].unique()) == POLICY_ORDER and (metrics["setting"] == setting).all()
        assert list(metrics["episode_seed"][:2]) == [20260511, 20260512]  # paper protocol: s + e
        assert meta["combined"][setting] == {"metrics.csv": 12, "actions.csv": 288, "city_hour_policy.csv": 864}
        for name in TABLES:  # the combined file is the units' files concatenated in grid order
            parts = [
                pd.read_csv(smoke_root / "units" / "eval" / f"{p}-{setting}-20260511" / name) for p in POLICY_ORDER
            ]
            pd.testing.assert_frame_equal(pd.read_csv(combined / name), pd.concat(parts, ignore_index=True))
    # learned policies were evaluated with the models of their own setting (recorded by sha256)
    unit = json.loads((smoke_root / "units" / "eval" / "sac-no_physics-20260511" / "unit.json").read_text())
    model = smoke_root / "units" / "train" / "sac-no_physics-20260511" / "model.zip"
    assert unit["model_sha256"] == {"sac": _digest(model)}
    # the no-physics reward differs from main for the same static policy: the setting reached the env
    main = pd.read_csv(smoke_root / "combined" / "main" / "metrics.csv")
    no_phys = pd.read_csv(smoke_root / "combined" / "no_physics" / "metrics.csv")
    assert (no_phys["cumulative_reward"][:2] > main["cumulative_reward"][:2]).all()
    # the agentic settings: the learned policies behind the rule Planner/Auditor, with their logs
    for setting in ("llm", "llm_no_physics"):
        combined = smoke_root / "combined" / setting
        metrics = pd.read_csv(combined / "metrics.csv")
        assert list(metrics["policy"].unique()) == ["ppo", "sac", "dqn"] and (metrics["setting"] == setting).all()
        assert (metrics["planner"] == "rule").all() and (metrics["audit_rate"] > 0).all()
        logs = [json.loads(line) for line in (combined / "agentic_logs.jsonl").read_text().splitlines()]
        assert len(logs) == len(metrics) * 24 and {row["setting"] for row in logs} == {setting}
    assert meta["combined"]["llm"]["agentic_logs.jsonl"] == 144
    unit = json.loads((smoke_root / "units" / "eval" / "dqn-llm_no_physics-20260511" / "unit.json").read_text())
    assert unit["model_sha256"] == {
        "dqn": _digest(smoke_root / "units" / "train" / "dqn-no_physics-20260511" / "model.zip")
    }
    # a complete grid gets its report
    assert (smoke_root / "report" / "index.html").is_file() and (smoke_root / "report" / "tables").is_dir()


def test_rerun_skips_done_units_and_a_different_grid_is_refused(smoke_root, tiny_dataset):
    stamps = {p: p.stat().st_mtime_ns for p in smoke_root.glob("units/*/*/*") if p.is_file()}
    done = subprocess.run(
        _paper_cmd(smoke_root, tiny_dataset, "--workers", "2"), capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0 and "24 of 24 units already done: skipped" in done.stderr
    assert {p: p.stat().st_mtime_ns for p in stamps} == stamps
    with pytest.raises(GridError, match=r"holds a different grid \(episodes: 2 -> 3\)"):
        run_paper(GridSpec.from_preset("smoke", episodes=3, data_dir=tiny_dataset), smoke_root)


def _children(pid: int) -> list[int]:
    try:
        text = Path(f"/proc/{pid}/task/{pid}/children").read_text()
    except OSError:
        return []
    return [int(c) for c in text.split()]


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().split(")")[-1].split()[0]
    except OSError:
        return False
    return state != "Z"


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="uses /proc and PR_SET_PDEATHSIG (Linux)")
def test_sigkill_loses_no_finished_unit_and_rerun_gives_the_same_results(smoke_root, tiny_dataset, tmp_path):
    root = tmp_path / "root"
    proc = subprocess.Popen(
        _paper_cmd(root, tiny_dataset, "--workers", "2"),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )
    deadline = time.monotonic() + 300
    while len(_done_units(root)) < 3 and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)
    workers = [c for c in _children(proc.pid) if _alive(c)]
    proc.send_signal(signal.SIGKILL)  # only the driver: its workers must not outlive it
    proc.wait()
    assert proc.returncode == -signal.SIGKILL, "the run finished before it could be killed"
    deadline = time.monotonic() + 15
    while any(_alive(w) for w in workers) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert workers and not any(_alive(w) for w in workers), "worker processes outlived the killed driver"

    finished = _done_units(root)
    assert 3 <= len(finished) < 24
    snapshot = {}
    for unit in finished:  # every finished unit is whole: files parse and nothing is half-written
        assert not list(unit.rglob("*.partial"))
        if unit.parent.name == "train":
            assert (unit / "model.zip").stat().st_size > 0 and json.loads((unit / "train_metadata.json").read_text())[
                "complete"
            ]
        else:
            assert len(pd.read_csv(unit / "metrics.csv")) == 2 and len(pd.read_csv(unit / "actions.csv")) == 48
            assert json.loads((unit / "run_metadata.json").read_text())["complete"]
        snapshot.update({p: _digest(p) for p in unit.rglob("*") if p.is_file() and p.name != "unit.log"})
    assert not (root / "combined").exists() or not list((root / "combined").rglob("*.csv"))

    done = subprocess.run(_paper_cmd(root, tiny_dataset, "--workers", "2"), capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    assert f"{len(finished)} of 24 units already done: skipped" in done.stderr
    assert {p: _digest(p) for p in snapshot} == snapshot  # finished units were not redone
    for setting in ("main", "no_physics", "llm", "llm_no_physics"):  # equal to an uninterrupted run, byte for byte
        for name in TABLES:
            assert _digest(root / "combined" / setting / name) == _digest(smoke_root / "combined" / setting / name), (
                name
            )


def test_failing_unit_stops_the_run_or_is_recorded_with_keep_going(tiny_dataset, tmp_path):
    def plant_damage(root: Path) -> Path:
        unit = root / "units" / "train" / "sac-main-20260511"
        unit.mkdir(parents=True)
        (unit / "train_config.json").write_text("{ damaged")
        return unit

    root = tmp_path / "stop"
    unit = plant_damage(root)
    stopped = subprocess.run(_paper_cmd(root, tiny_dataset), capture_output=True, text=True, timeout=300)
    assert stopped.returncode == 1
    assert "train/sac-main-20260511" in stopped.stderr and str(unit / "unit.log") in stopped.stderr.replace("\n", "")
    assert "train_config.json is not valid JSON" in (unit / "unit.log").read_text()
    assert "stopped" in stopped.stderr and not _done_units(root)  # the first unit failed: nothing else ran
    assert json.loads((root / "paper_metadata.json").read_text())["status"] == "stopped"

    root = tmp_path / "keep"
    unit = plant_damage(root)
    kept = subprocess.run(
        _paper_cmd(root, tiny_dataset, "--workers", "2", "--keep-going"), capture_output=True, text=True, timeout=600
    )
    assert kept.returncode == 1 and "1 unit(s) failed" in kept.stderr
    meta = json.loads((root / "paper_metadata.json").read_text())
    assert meta["units"]["train/sac-main-20260511"]["status"] == "failed"
    assert meta["units"]["train/sac-main-20260511"]["log"] == str(unit / "unit.log")
    assert meta["units"]["eval/sac-main-20260511"]["status"] == "blocked"
    assert meta["units"]["eval/sac-llm-20260511"]["status"] == "blocked"  # it needs the same model
    assert sum(v["status"] == "done" for v in meta["units"].values()) == 21
    assert list(meta["combined"]) == ["no_physics", "llm_no_physics"] and not (root / "combined" / "main").exists()

    (unit / "train_config.json").unlink()  # repair, re-run: only the two missing units run
    fixed = subprocess.run(_paper_cmd(root, tiny_dataset), capture_output=True, text=True, timeout=600)
    assert fixed.returncode == 0, fixed.stderr
    assert "21 of 24 units already done" in fixed.stderr
    assert json.loads((root / "paper_metadata.json").read_text())["complete"]


def test_smoke_preset_through_a_local_ray_instance(smoke_root, tiny_dataset, tmp_path):
    ray = pytest.importorskip("ray", reason="ray is not installed (pip install -e '.[ray]')")
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        root = tmp_path / "ray"
        # ship files through Ray as on a cluster without a shared filesystem
        outcome = run_paper(
            GridSpec.from_preset("smoke", data_dir=tiny_dataset), root, ray_address="auto", ray_transfer="always"
        )
    finally:
        ray.shutdown()
    assert outcome.complete and len(outcome.report.finished) == 24
    assert not (root / ".grid-token").exists()
    for setting in ("main", "no_physics", "llm", "llm_no_physics"):
        for name in TABLES:
            assert _digest(root / "combined" / setting / name) == _digest(smoke_root / "combined" / setting / name), (
                name
            )
    for unit in ("train/ppo-main-20260511", "eval/ppo-main-20260511"):
        assert (root / "units" / unit / "DONE").is_file() and (root / "units" / unit / "unit.log").is_file()


def test_independent_episode_seeds_reach_the_evaluation(tiny_dataset, tmp_path):
    spec = GridSpec.from_preset(
        "smoke",
        episodes=3,
        seeds=(7, 8),
        settings=("main",),
        policies=("static",),
        episode_seed_protocol="independent",
        data_dir=tiny_dataset,
    )
    outcome = run_paper(spec, tmp_path / "root")
    assert outcome.complete and [u.name for u in outcome.units] == ["eval/static-main-7", "eval/static-main-8"]
    metrics = pd.read_csv(tmp_path / "root" / "combined" / "main" / "metrics.csv")
    assert list(metrics["episode_seed"]) == independent_episode_seeds(7, 3) + independent_episode_seeds(8, 3)
    meta = json.loads((tmp_path / "root" / "paper_metadata.json").read_text())
    assert meta["grid"]["episode_seed_protocol"] == "independent"
    assert "SeedSequence(entropy=s, spawn_key=(0x45504953,))" in meta["grid"]["episode_seed_derivation"]


def test_a_setting_with_no_policy_to_evaluate_is_refused_before_any_work():
    from solarchain_eval.experiments.grid import GridSpec

    spec = GridSpec.from_preset("smoke", settings=("main", "llm"), policies=("static",))
    with pytest.raises(ValueError, match="setting 'llm' would evaluate no policy: choose some of ppo, sac, dqn"):
        spec.validate()
    GridSpec.from_preset("smoke", settings=("main",), policies=("static",)).validate()
