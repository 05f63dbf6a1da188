"""Train a Stable-Baselines3 PPO agent on SolarChainEval-v0, then put it through the benchmark.

    python examples/train_sb3_then_evaluate.py                           # 20,000 steps, the paper's protocol
    python examples/train_sb3_then_evaluate.py --timesteps 300000 --out runs/my-ppo

The model is trained on the default dataset (the paper's) with the paper preset's learning rate,
batch size and discount, evaluated with solarchain_eval.evaluate under the name "my_ppo", and
printed beside the Static and Myopic baselines evaluated with the same protocol (equal protocol
ids: the rows are comparable).
"""

from __future__ import annotations

import argparse

import gymnasium as gym
import pandas as pd
from stable_baselines3 import PPO

import solarchain_eval  # registers SolarChainEval-v0


def main(argv: list[str] | None = None) -> pd.DataFrame:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--timesteps", type=int, default=20_000, help="training steps (the paper preset: 300,000)")
    parser.add_argument("--seed", type=int, default=20260511, help="training seed")
    parser.add_argument("--seeds", default="20260511,20260512,20260513", help="evaluation run seeds")
    parser.add_argument("--episodes", type=int, default=30, help="evaluation episodes per run seed")
    parser.add_argument("--data", default=None, help="dataset directory (default: the embedded default dataset)")
    parser.add_argument("--out", default=None, help="keep the model's run directory here")
    args = parser.parse_args(argv)

    env = gym.make("SolarChainEval-v0", data_dir=args.data)
    # A rollout no longer than the budget, so a short run still trains on what it collected.
    n_steps = max(64, min(2048, args.timesteps))
    model = PPO(
        "MlpPolicy", env, learning_rate=3e-4, batch_size=64, gamma=0.98, n_steps=n_steps, seed=args.seed, verbose=0
    )
    model.learn(total_timesteps=args.timesteps)

    protocol = {"data": args.data, "seeds": [int(s) for s in args.seeds.split(",")], "episodes": args.episodes}
    mine = solarchain_eval.evaluate(model, name="my_ppo", out=args.out, **protocol)
    baselines = solarchain_eval.evaluate(["static", "myopic"], **protocol)
    assert mine.protocol_id == baselines.protocol_id  # same task, so the rows compare
    table = pd.concat([mine.summary, baselines.summary], ignore_index=True)
    columns = ["policy", "cumulative_reward_mean", "physics_violation_rate_mean", "artificial_liquidity_MWh_mean"]
    print(table[columns].to_string(index=False))
    print("protocol id:", mine.protocol_id)
    return table


if __name__ == "__main__":
    main()
