"""MaskablePPO training throughput: the sequential format against the ``Discrete(2**M)`` bitmask.

The bitmask format exists up to 16 sensors only, so the comparison runs on the 14-RTU IEEE 14
grid (``grid_system("ieee14", sensors="bus")``: 16,384 masked actions per window step), budget
c = 6, window N = 6, log det, where both formats play the identical instance; the sequential
format (``Discrete(M + 1)`` time-major and ``Discrete(N·M + 1)`` plan-first) is also timed on
the ``grid-ieee14`` preset (34 meters, c = 6, N = 6, log det), which has no bitmask format.

Every setting trains a fresh MaskablePPO with ``train.py``'s hyperparameters for the sparse
attacker on the grid presets (read from :mod:`agents.config`), one torch thread, for the same
number of decisions, in two ways:

- ``8 envs``: as ``train.py`` trains by default there: the native vector env of each format
  (``gymnasium.make_vec(..., vectorization_mode="vector_entry_point")`` through
  :mod:`fdia_env.vector.sb3`), 8 members of 128 decisions each per rollout, minibatches of 256,
  10 epochs, without ``train.py``'s reward rescaling; the plan-first order as ``train.py`` picks
  it (``order="increasing"``: a plan's picks in increasing order);
- ``1 env``: as ``train.py --num-envs 1`` would, one Gymnasium env in a ``DummyVecEnv`` with the
  one-env settings (rollout 512, minibatch 128, 10 epochs).

A last row of the ``1 env`` way, ``zero-cost env``, trains on an env with the spaces of
``grid-ieee14 sequential (increasing)`` that does no work (a constant observation, every action
legal, episodes of c + 1 decisions): its rate is MaskablePPO's own cost per decision, so its
ratio is the most any env in that format could reach this way.

The settings take turns within each repeat so a change of load hits them alike. Rates are env
decisions per CPU second of this process (wall-clock rates printed too); each ratio is against
the bitmask in the same way. Target: the sequential format at >= 20x the bitmask's decisions per
second; the verdict is printed for each way (exit status 0 when ``train.py``'s default way, 8
envs, meets it).

    python benchmarks/seq_throughput.py [--steps 1024] [--repeats 2]
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np
import torch

import fdia_env  # noqa: F401 - registers the Gymnasium ids

TARGET = 20.0
GYM_ID = "fdia_env/SparseAttack-v2"
VECTOR_ENVS = 8
BASELINE = "ieee14-rtu bitmask"
WAYS = ("1 env", f"{VECTOR_ENVS} envs")
BOUND = "zero-cost env"


class ZeroCostEnv(gym.Env):
    """The spaces of ``env``, no work: a constant observation, every action legal.

    An episode takes ``length`` decisions (the plan's c picks and its stop).
    """

    def __init__(self, env: gym.Env, length: int) -> None:
        self.observation_space, self.action_space = env.observation_space, env.action_space
        self._obs = np.zeros(self.observation_space.shape, np.float32)
        self._mask = np.ones(int(self.action_space.n), dtype=bool)
        self._length, self._t = length, 0

    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple:
        """Start an episode."""
        super().reset(seed=seed)
        self._t = 0
        return self._obs.copy(), {}

    def step(self, action: Any) -> tuple:
        """One decision: reward 0, the episode ends after ``length``."""
        self._t += 1
        return self._obs.copy(), 0.0, self._t >= self._length, False, {}

    def action_masks(self) -> np.ndarray:
        """Every action legal."""
        return self._mask.copy()


def train_setup(num_envs: int | None = None) -> Any:
    """``train.py attacker --scenario grid-ieee14 --algo MaskablePPO [--num-envs N]``'s setup."""
    from agents.config import Hyperparameters
    from agents.training import run_setup

    hp = Hyperparameters()
    return run_setup(
        "sparse_attack_v2", "attacker", "grid-ieee14", {}, "MaskablePPO", hp, num_envs=num_envs
    )


def train_settings() -> dict[str, dict[str, Any]]:
    """Way -> MaskablePPO's options as ``train.py`` resolves them (``n_steps`` per member).

    Raises:
        ValueError: When ``train.py``'s default is not :data:`VECTOR_ENVS` native members.
    """
    from agents.config import algo_kwargs

    default, one = train_setup(), train_setup(num_envs=1)
    if default.num_envs != VECTOR_ENVS:
        raise ValueError(
            f"train.py trains grid-ieee14 on {default.num_envs} envs by default, not "
            f"{VECTOR_ENVS}: update VECTOR_ENVS"
        )
    return {
        WAYS[0]: algo_kwargs(one.algo, one.hp),
        WAYS[1]: algo_kwargs(default.algo, default.hp),
    }


def formats() -> dict[str, dict[str, Any]]:
    """Name -> env options of each timed setting."""
    from fdia_env.systems import grid_system

    rtu = grid_system("ieee14", sensors="bus")
    base = {"budget": 6, "horizon": 6, "objective": "logdet"}
    plan = train_setup().env_kwargs["order"]  # the plan-first order train.py picks (increasing)
    return {
        BASELINE: {"scenario": rtu, "action": "bitmask", **base},
        "ieee14-rtu sequential (time)": {
            "scenario": rtu, "action": "sequential", "order": "time", **base
        },
        f"ieee14-rtu sequential ({plan})": {
            "scenario": rtu, "action": "sequential", "order": plan, **base
        },
        "grid-ieee14 sequential (time)": {
            "scenario": "grid-ieee14", "action": "sequential", "order": "time", **base
        },
        f"grid-ieee14 sequential ({plan})": {
            "scenario": "grid-ieee14", "action": "sequential", "order": plan, **base
        },
        BOUND: {
            "scenario": "grid-ieee14", "action": "sequential", "order": plan, "zero_cost": True,
            **base,
        },
    }  # fmt: skip


def make_model(kwargs: dict[str, Any], way: str, settings: dict[str, Any], seed: int) -> Any:
    """A fresh MaskablePPO on the env of ``kwargs``, one env or the native vector env."""
    from agents.algos import build_model

    settings = dict(settings)
    if kwargs.get("zero_cost"):
        real = gym.make(GYM_ID, **{k: v for k, v in kwargs.items() if k != "zero_cost"})
        env: Any = ZeroCostEnv(real, int(kwargs["budget"]) + 1)
    elif way == WAYS[0]:
        env = gym.make(GYM_ID, **kwargs)
    else:
        from fdia_env.vector.sb3 import make_sb3_vec_env

        env = make_sb3_vec_env(GYM_ID, VECTOR_ENVS, **kwargs)
    return build_model("MaskablePPO", env, settings, seed=seed)


def learn_rate(model: Any, steps: int) -> tuple[float, float]:
    """Decisions per wall-clock second and per CPU second of ``model.learn(steps)``."""
    wall, cpu = time.perf_counter(), time.process_time()
    model.learn(steps)
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    return model.num_timesteps / wall, model.num_timesteps / cpu


def main(argv: Sequence[str] | None = None) -> int:
    """Print the rates and the sequential/bitmask ratios; 0 when train.py's default meets it."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--steps", type=int, default=1024, help="decisions per timed run")
    parser.add_argument("--repeats", type=int, default=2, help="timed runs per setting")
    args = parser.parse_args(argv)
    settings = train_settings()
    rollout = max(s["n_steps"] * (VECTOR_ENVS if w == WAYS[1] else 1) for w, s in settings.items())
    if args.steps < rollout or args.repeats < 1:
        parser.error(f"--steps must be >= {rollout} (one rollout) and --repeats >= 1")
    torch.set_num_threads(1)
    envs = formats()
    timed = [
        (name, way)
        for way in WAYS
        for name in envs
        if way == WAYS[0] or not ("(time)" in name or name == BOUND)
    ]
    for name, way in timed:  # warm-up: imports, the grid build, first allocations
        learn_rate(make_model(envs[name], way, settings[way], seed=0), 1)
    rates: dict[tuple[str, str], list[tuple[float, float]]] = {key: [] for key in timed}
    for r in range(args.repeats):
        for name, way in timed:
            rates[name, way].append(
                learn_rate(make_model(envs[name], way, settings[way], r), args.steps)
            )
    median = {key: tuple(np.median(np.array(v), axis=0)) for key, v in rates.items()}
    keys = ("n_steps", "batch_size", "n_epochs", "ent_coef", "gamma")
    shown = {way: {k: settings[way][k] for k in keys} for way in WAYS}
    print(
        f"MaskablePPO with train.py's grid settings {shown}, {args.steps} decisions x "
        f"{args.repeats} repeats, one torch thread; {platform.processor() or platform.machine()}, "
        f"{os.cpu_count()} CPUs, load {os.getloadavg()[0]:.1f}, "
        f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}"
    )
    print(
        f"{'setting':36s} {'way':>7s} {'decisions/s (CPU)':>18s} {'(wall)':>10s} "
        f"{'x bitmask (CPU)':>16s}"
    )
    met = {}
    for way in WAYS:
        base_cpu = median[BASELINE, way][1]
        ok = True
        for (name, w), (wall, cpu) in median.items():
            if w != way:
                continue
            ratio = cpu / base_cpu
            print(f"{name:36s} {way:>7s} {cpu:18.0f} {wall:10.0f} {ratio:15.1f}x")
            if "sequential" in name:
                ok = ok and ratio >= TARGET
        met[way] = ok
    for way in WAYS:
        verdict = "met" if met[way] else "NOT met"
        print(f"target: every sequential setting >= {TARGET:.0f}x the bitmask, {way}: {verdict}")
    return 0 if met[WAYS[1]] else 1


if __name__ == "__main__":
    raise SystemExit(main())
