"""Train a sparse attacker with MaskablePPO and score it against exhaustive search (EXS).

Run: ``python docs/tutorials/sparse_attacker.py`` (``FDIA_TUTORIAL_QUICK=1`` for a short run).
"""

import os

import gymnasium as gym
import torch
from sb3_contrib import MaskablePPO

import fdia_env  # noqa: F401 - registers the Gymnasium ids
from agents.evaluate import evaluate
from baselines.sparse import exhaustive, sfs

QUICK = bool(os.environ.get("FDIA_TUTORIAL_QUICK"))
torch.set_num_threads(1)

# 1. The problem: ch4-position, budget c = 5 sensor-time pairs over N = 6 steps
kwargs = {"scenario": "ch4-position", "budget": 5, "horizon": 6}
optimum = exhaustive("ch4-position", budget=5, horizon=6)
greedy = sfs("ch4-position", budget=5, horizon=6)
print(f"EXS optimum {optimum.value:.6f} {optimum.attacks}")
print(f"SFS         {greedy.value:.6f}")

# 2. Train: the action mask is in info["action_mask"] and env.action_masks() (MaskablePPO)
env = gym.make("fdia_env/SparseAttack-v0", **kwargs)
model = MaskablePPO("MlpPolicy", env, n_steps=256, batch_size=64, seed=0, device="cpu")
model.learn(1_000 if QUICK else 50_000)

# 3. Score: one evaluation loop for the learned policy, the analytic one and random play
for name, policy in [("learned", model), ("EXS", optimum.policy()), ("random", "random")]:
    result = evaluate(policy, env, n_episodes=1 if name != "random" else 50, seed=0)
    print(f"{name:8s} {result.mean:.6f}  score {result.score:.1%} of {result.reference_name}")
