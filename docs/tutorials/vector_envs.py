"""Native vector environments: many envs as one numpy computation, the same episodes as one.

Run: ``python docs/tutorials/vector_envs.py``. A GPU (torch) backend is not part of fdia_env yet:
everything here runs in numpy on the CPU.
"""

import time

import gymnasium as gym
import numpy as np

import fdia_env  # noqa: F401 - registers the Gymnasium ids

# 1. B = 4096 sparse-attack envs, stepped together
venv = gym.make_vec(
    "fdia_env/SparseAttack-v0", num_envs=4096, vectorization_mode="vector_entry_point"
)
obs, info = venv.reset(seed=0)
rng = np.random.default_rng(0)
start, steps = time.perf_counter(), 0
for _ in range(60):
    legal = info["action_mask"].astype(bool)
    actions = np.argmax(rng.random(legal.shape) * legal, axis=1)  # random legal subsets
    obs, rewards, terminated, truncated, info = venv.step(actions)
    steps += venv.num_envs
keys = sorted(k for k in info if not k.startswith("_"))
print(f"{steps / (time.perf_counter() - start):,.0f} env-steps/s; info keys: {keys}")

# 2. Member i is the single env seeded seed + i
single = gym.make("fdia_env/SparseAttack-v0")
venv3 = gym.make_vec("fdia_env/SparseAttack-v0", num_envs=3)
obs3, _ = venv3.reset(seed=7)
obs1, _ = single.reset(seed=9)
print("member 2 == single env seeded 9:", np.array_equal(obs3[2], obs1))

# 3. stable-baselines3 sees a VecEnv
from fdia_env.vector.sb3 import make_sb3_vec_env  # noqa: E402

sb3_env = make_sb3_vec_env("fdia_env/SparseAttack-v0", num_envs=8)
print(type(sb3_env).__name__, sb3_env.num_envs, sb3_env.observation_space.shape)
