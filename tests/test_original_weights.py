"""SB3 training here equals the original release's training, weight for weight.

``original_release_traces/reference_weights.json`` (shared data, see its README) fingerprints the
policies that the original release's own ``train_model`` trained with seed 20260511, in both
settings: PPO and DQN after 4,096 steps, SAC after 2,048, on CPU with one torch thread. Our
``train`` with the same spec must give every tensor's exact bytes (sha256). This is what the
float32 clip of the action sanitiser decides: PPO's clipped Gaussian and DQN's grid points
(1, ·, ·) decode u1 = 1 all the time, and a one-ulp ℓ there changes the first update.

Bit-exact weights need the reference's library versions (numpy, torch, Stable-Baselines3,
gymnasium) on CPU: elsewhere the test skips, naming the versions that differ.
"""

from __future__ import annotations

import hashlib
import json
from importlib.metadata import version
from pathlib import Path

import numpy as np
import pytest

from solarchain_eval.training.sb3_trainer import TrainSpec, train

#: Distribution name per key of the reference's ``versions``.
LIBRARIES = {"numpy": "numpy", "torch": "torch", "stable_baselines3": "stable-baselines3", "gymnasium": "gymnasium"}
SETTINGS = {"main": False, "no_physics": True}


@pytest.fixture(scope="module")
def reference(shared_data: Path) -> dict:
    path = shared_data / "original_release_traces" / "reference_weights.json"
    if not path.is_file():
        pytest.skip(f"the original release's weight fingerprints are not at {path} (set SOLARCHAIN_SHARED_DATA)")
    data = json.loads(path.read_text())
    differ = [
        f"{dist} {version(dist)} (reference {data['versions'][key]})"
        for key, dist in LIBRARIES.items()
        if version(dist) != data["versions"][key]
    ]
    if differ:
        pytest.skip("bit-exact weights need the reference library versions; these differ: " + ", ".join(differ))
    return data


def _reference_model(reference: dict, setting: str, algo: str) -> dict:
    (model,) = [m for m in reference["models"] if m["setting"] == setting and m["algo"] == algo.upper()]
    return model


def _fingerprints(model) -> list[tuple[str, str]]:
    return [
        (name, hashlib.sha256(tensor.detach().cpu().numpy().tobytes()).hexdigest())
        for name, tensor in model.policy.state_dict().items()
    ]


@pytest.mark.slow
@pytest.mark.parametrize("setting", list(SETTINGS))
@pytest.mark.parametrize("algo", ["ppo", "dqn", "sac"])
def test_training_equals_the_original_release_tensor_for_tensor(
    reference, published_dir, tmp_path, setting, algo
) -> None:
    from solarchain_eval.agents.checkpoints import algorithm_class

    expected = _reference_model(reference, setting, algo)
    spec = TrainSpec(
        algo=algo,
        seed=expected["seed"],
        timesteps=expected["total_timesteps"],
        no_physics_penalty=SETTINGS[setting],
        data_dir=published_dir,
        checkpoint_every=0,
        torch_threads=reference["torch_num_threads"],
        device="cpu",
    )
    outcome = train(spec, tmp_path / algo)
    model = algorithm_class(algo).load(outcome.model_path, device="cpu")  # the zip this test just wrote
    got = _fingerprints(model)
    assert [name for name, _ in got] == [t["name"] for t in expected["tensors"]]
    differ = [name for (name, digest), t in zip(got, expected["tensors"], strict=True) if digest != t["sha256"]]
    assert not differ, f"{setting} {algo}: {len(differ)} of {len(got)} tensors differ from the original's: {differ}"
    if algo == "sac":
        log_ent_coef = model.log_ent_coef.detach().cpu().numpy()
        assert hashlib.sha256(log_ent_coef.tobytes()).hexdigest() == expected["log_ent_coef"]["sha256"]
    total = np.concatenate([t.detach().cpu().numpy().ravel() for t in model.policy.state_dict().values()])
    assert total.size == expected["n_parameters"]
