"""The keeper runs nothing a run names, and models load without running pickled code
(docs/security.md#learned-models): crafted SB3 zips and VecNormalize files whose pickles would
create a file when unpickled leave no trace, with a clear line, through every door that loads them."""

from __future__ import annotations

import base64
import contextlib
import json
import pickle
import zipfile
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from solarchain_eval.agents.sb3 import load_model, load_vecnormalize
from solarchain_eval.cli import app
from solarchain_eval.config import BenchmarkConfig
from solarchain_eval.data.table import load_table
from solarchain_eval.envs.env import SolarChainEnv

RUN_SEED = 5


class _CreatesFile:
    """Unpickling this calls ``open(path, "w")``: the file appears only if the pickle runs."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def __reduce__(self):
        return (open, (str(self.path), "w"))


def invoke(*args):
    return CliRunner().invoke(app, [str(a) for a in args], catch_exceptions=False)


@pytest.fixture(scope="module")
def honest(tiny_dataset, tmp_path_factory) -> Path:
    """An untrained PPO model of the env, saved by SB3 (nothing needs training to be loaded)."""
    from stable_baselines3 import PPO

    env = SolarChainEnv(config=BenchmarkConfig(), table=load_table(tiny_dataset))
    path = tmp_path_factory.mktemp("models") / "ppo.zip"
    PPO("MlpPolicy", env, seed=0, device="cpu", n_steps=32, batch_size=32, policy_kwargs={"net_arch": [8]}).save(path)
    return path


def craft(honest: Path, out: Path, marker: Path, *, entry: str | None = None, member: str | None = None) -> Path:
    """A copy of ``honest`` whose ``data`` entry or tensor ``member`` is a pickle creating ``marker``."""
    payload = pickle.dumps(_CreatesFile(marker))
    with zipfile.ZipFile(honest) as source, zipfile.ZipFile(out, "w") as target:
        for name in source.namelist():
            content = source.read(name)
            if name == "data" and entry is not None:
                data = json.loads(content)
                data[entry] = {":type:": "<class 'object'>", ":serialized:": base64.b64encode(payload).decode()}
                content = json.dumps(data).encode()
            if name == member:
                content = payload
            target.writestr(name, content)
    return out


@pytest.mark.parametrize(("entry", "member"), [("observation_space", None), (None, "pytorch_variables.pth")])
def test_a_crafted_model_is_refused_and_leaves_no_trace(honest, tiny_dataset, tmp_path, entry, member):
    marker = tmp_path / "pwned"
    crafted = craft(honest, tmp_path / "crafted.zip", marker, entry=entry, member=member)
    if entry is not None:  # the attack is real: SB3's own load runs it
        from stable_baselines3 import PPO

        with contextlib.suppress(Exception):  # SB3 fails on the value, after the pickle ran
            PPO.load(crafted, device="cpu")
        assert marker.exists()
        marker.unlink()
    out = tmp_path / "run"
    result = invoke("evaluate", "--data", tiny_dataset, "--policies", "ppo", "--models", f"ppo={crafted}",
                    "--seeds", RUN_SEED, "--episodes", 1, "--out", out)  # fmt: skip
    assert result.exit_code == 2, result.output
    assert not marker.exists() and not out.exists()
    assert "Traceback" not in result.output
    why = f"its pickled entry '{entry}' names " if entry else f"{member} holds more than tensors"
    assert f"cannot load {crafted} as a PPO model: {why}" in " ".join(result.output.split())
    assert "refused without running it" in " ".join(result.output.split())


def test_unneeded_pickled_entries_are_replaced_not_run(honest, tmp_path):
    marker = tmp_path / "pwned"
    crafted = craft(honest, tmp_path / "crafted.zip", marker, entry="lr_schedule")
    craft(honest, tmp_path / "crafted2.zip", marker, entry="not_an_sb3_entry")
    model = load_model("ppo", honest)
    observation = np.linspace(0.1, 0.9, int(np.prod(model.observation_space.shape)), dtype=np.float32)
    for path in (crafted, tmp_path / "crafted2.zip"):
        loaded = load_model("ppo", path)
        assert not marker.exists()
        np.testing.assert_array_equal(
            loaded.predict(observation, deterministic=True)[0], model.predict(observation, deterministic=True)[0]
        )


def test_a_crafted_vecnormalize_file_is_refused(tmp_path):
    marker = tmp_path / "pwned"
    path = tmp_path / "vecnormalize.pkl"
    path.write_bytes(pickle.dumps(_CreatesFile(marker)))
    with pytest.raises(ValueError, match=r"cannot read VecNormalize statistics from .*names .*open.*never needs"):
        load_vecnormalize(path)
    assert not marker.exists()


@pytest.fixture(scope="module")
def ppo_run(honest, tiny_dataset, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("runs") / "run"
    result = invoke("evaluate", "--data", tiny_dataset, "--policies", "static,ppo", "--models", f"ppo={honest}",
                    "--seeds", RUN_SEED, "--episodes", 2, "--out", out)  # fmt: skip
    assert result.exit_code == 0, result.output
    return out


def test_verify_loads_models_only_from_what_the_keeper_passes(ppo_run, honest, tmp_path):
    marker = tmp_path / "pwned"
    crafted = craft(honest, tmp_path / "crafted.zip", marker, entry="observation_space")
    meta_path = ppo_run / "run_metadata.json"
    original = meta_path.read_text()
    meta = json.loads(original)
    assert meta["models"] == {"ppo": str(honest)}
    meta["models"] = {"ppo": str(crafted)}  # the run names a crafted zip (the metadata is not checksummed)
    meta_path.write_text(json.dumps(meta))
    try:
        named = invoke("verify", ppo_run, "--episodes", 1)
        assert not marker.exists()
        lines = named.output.splitlines()
        assert lines[0] == "static: verified (1 episode)", named.output
        assert lines[1].startswith("ppo: cannot rebuild (policy 'ppo' needs a trained model: pass --models DIR")
        passed = invoke("verify", ppo_run, "--episodes", 1, "--models", f"ppo={crafted}")
        assert not marker.exists()
        assert f"ppo: cannot rebuild (cannot load {crafted} as a PPO model: its pickled entry 'observation_space'" in (
            passed.output
        )
        good = invoke("verify", ppo_run, "--episodes", 2, "--models", f"ppo={honest}")
        assert good.exit_code == 0 and "ppo: verified (2 episodes)" in good.output, good.output
    finally:
        meta_path.write_text(original)


def test_the_sb3_door_and_vecnormalize_refuse_crafted_files(honest, tiny_dataset, tmp_path):
    marker = tmp_path / "pwned"
    crafted = craft(honest, tmp_path / "crafted.zip", marker, entry="policy_class")
    stats = tmp_path / "vecnormalize.pkl"
    stats.write_bytes(pickle.dumps(_CreatesFile(marker)))
    for extra in ([f"mine=sb3:ppo:{crafted}"], [f"mine=sb3:ppo:{honest}", "--vecnormalize", f"mine={stats}"]):
        out = tmp_path / "run"
        result = invoke("evaluate", "--data", tiny_dataset, "--policies", *extra, "--out", out)
        assert result.exit_code == 2, result.output
        assert not marker.exists() and not out.exists()
        assert "never needs" in result.output and "Traceback" not in result.output
