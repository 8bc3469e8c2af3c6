"""Native vector environments: many envs as one numpy computation, the same episodes as one.

Run: ``python docs/tutorials/vector_envs.py``. Each section is a function, run in order by the
``__main__`` block below and shown as its own part of the tutorial page
(``docs/tutorials/vector_envs.md``, one ``literalinclude :pyobject:`` per section). Everything here
runs on the CPU; section 4 runs the same envs as torch tensors on a device (``"cuda"`` when
torch sees a GPU, else ``"cpu"``).
"""

import time

import gymnasium as gym
import numpy as np

import fdia_env  # noqa: F401 - registers the Gymnasium ids


def numpy_batch(num_envs: int = 4096, steps: int = 60) -> None:
    """1. B = 4096 sparse-attack envs, stepped together (numpy, CPU)."""
    venv = gym.make_vec(
        "fdia_env/SparseAttack-v0", num_envs=num_envs, vectorization_mode="vector_entry_point"
    )
    _, info = venv.reset(seed=0)
    rng = np.random.default_rng(0)
    start, done = time.perf_counter(), 0
    for _ in range(steps):
        legal = info["action_mask"].astype(bool)
        actions = np.argmax(rng.random(legal.shape) * legal, axis=1)  # random legal subsets
        _, _, _, _, info = venv.step(actions)
        done += venv.num_envs
    keys = sorted(k for k in info if not k.startswith("_"))
    print(f"{done / (time.perf_counter() - start):,.0f} env-steps/s; info keys: {keys}")


def members_are_single_envs() -> None:
    """2. Member i is the single env seeded seed + i."""
    single = gym.make("fdia_env/SparseAttack-v0")
    venv3 = gym.make_vec("fdia_env/SparseAttack-v0", num_envs=3)
    obs3, _ = venv3.reset(seed=7)
    obs1, _ = single.reset(seed=9)
    print("member 2 == single env seeded 9:", np.array_equal(obs3[2], obs1))


def sb3_vec_env() -> None:
    """3. stable-baselines3 sees a VecEnv."""
    from fdia_env.vector.sb3 import make_sb3_vec_env

    sb3_env = make_sb3_vec_env("fdia_env/SparseAttack-v0", num_envs=8)
    print(type(sb3_env).__name__, sb3_env.num_envs, sb3_env.observation_space.shape)


def torch_batch(num_envs: int = 4096, steps: int = 60) -> None:
    """4. The same envs as torch tensors on a device (GPU when present): one engine."""
    import torch

    torch.set_num_threads(1)  # on a small shared CPU, intra-op threads only contend
    device = "cuda" if torch.cuda.is_available() else "cpu"
    venv = gym.make_vec(
        "fdia_env/SparseAttack-v0",
        num_envs=num_envs,
        vectorization_mode="vector_entry_point",
        backend="torch",
        device=device,
    )
    obs, _ = venv.reset(seed=0)
    gen = torch.Generator(device=device).manual_seed(0)
    start, done = time.perf_counter(), 0
    for _ in range(steps):
        mask = venv.action_masks()  # (B, A) bool tensor on the device
        actions = torch.multinomial(mask.double(), 1, generator=gen).squeeze(1)
        obs, _, _, _, _ = venv.step(actions)
        done += venv.num_envs
    rate = done / (time.perf_counter() - start)
    print(f"{device}: {rate:,.0f} env-steps/s; obs {obs.dtype} {tuple(obs.shape)} on {obs.device}")
    # expected dynamics equal the numpy backend member by member (tested to 1e-10 relative)
    ref = gym.make_vec(
        "fdia_env/SparseAttack-v0", num_envs=2, vectorization_mode="vector_entry_point"
    )
    tv = gym.make_vec(
        "fdia_env/SparseAttack-v0",
        num_envs=2,
        vectorization_mode="vector_entry_point",
        backend="torch",
        device=device,
    )
    ref.reset(seed=0)
    tv.reset(seed=0)
    a = np.array([1, 2])
    r_np = ref.step(a)[1]
    r_t = tv.step(torch.as_tensor(a, device=device))[1]
    print("torch rewards == numpy rewards:", np.allclose(r_t.cpu().numpy(), r_np, rtol=1e-10))


# the tutorial's sections, in order
SECTIONS = [numpy_batch, members_are_single_envs, sb3_vec_env, torch_batch]

if __name__ == "__main__":
    for section in SECTIONS:
        section()
