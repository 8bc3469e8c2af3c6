"""The plan-first picks in increasing order (agents.increasing_picks), as train.py uses them.

One sequence of picks per plan (so an entropy bonus cannot be met by reordering one plan's
picks), every plan still reachable with its value, the learned policy scored as it was
trained, and the grid presets' defaults.
"""

import itertools
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # train.py lives at the root

import train
from agents.config import Hyperparameters, TrainConfig
from agents.evaluate import evaluate
from agents.increasing_picks import IncreasingPicks
from agents.training import run_setup
from baselines.sparse import exhaustive

ID = "fdia_env/SparseAttack-v2"
SMALL = {"scenario": "ch4-position", "budget": 2, "horizon": 2, "action": "sequential"}


def plan_env(**kwargs):
    return IncreasingPicks(gym.make(ID, **{**SMALL, "order": "plan", **kwargs}))


def sequences(env, prefix=()):
    """Every legal sequence of decisions of ``env`` (replayed from a reset), with its return."""
    env.reset(seed=0)
    total, done = 0.0, False
    for a in prefix:
        _, reward, term, trunc, _ = env.step(a)
        total, done = total + reward, term or trunc
    if done:
        return [(prefix, total)]
    out = []
    for a in np.flatnonzero(env.action_masks()):
        out += sequences(env, (*prefix, int(a)))
    return out


def test_each_plan_has_one_increasing_sequence_of_picks_and_its_value():
    env = plan_env()
    M, N = 3, 2  # ch4-position: 3 sensors; 6 pairs, c = 2
    runs = sequences(env)
    plans = [tuple(a for a in seq if a) for seq, _ in runs]
    assert all(list(p) == sorted(p) for p in plans)  # picks in increasing order
    assert len(plans) == len(set(plans))  # one sequence per plan
    every = {c for k in range(3) for c in itertools.combinations(range(1, N * M + 1), k)}
    assert set(plans) == every  # 1 + 6 + 15 plans: none lost
    # the same values as the env without the wrapper, which reaches each plan in every order
    plain = gym.make(ID, **SMALL, order="plan")
    for (_, value), plan in zip(runs, plans, strict=True):
        plain.reset(seed=0)
        total, done = 0.0, False
        for a in reversed(plan) if plan else (0,):  # decreasing: illegal under the wrapper
            _, reward, term, trunc, _ = plain.step(a)
            total, done = total + reward, term or trunc
        while not done:
            _, reward, term, trunc, _ = plain.step(0)
            total, done = total + reward, term or trunc
        assert total == value
    best = exhaustive("ch4-position", budget=2, horizon=2)
    assert max(v for _, v in runs) == pytest.approx(best.value, rel=1e-12)


def test_the_mask_forbids_the_pairs_below_the_last_pick_and_resets():
    env = plan_env(budget=3)
    env.reset(seed=0)
    assert env.action_masks().tolist() == [1] * 7
    env.step(4)
    assert env.action_masks().tolist() == [1, 0, 0, 0, 0, 1, 1]
    env.step(6)  # the last pair: stop only (the env itself still allows pairs 1-5)
    assert env.action_masks().tolist() == [1, 0, 0, 0, 0, 0, 0]
    assert env.unwrapped.action_masks().tolist() == [1, 1, 1, 1, 0, 1, 0]
    env.reset(seed=1)
    assert env.action_masks().tolist() == [1] * 7
    with pytest.raises(ValueError, match="plan-first order"):
        IncreasingPicks(gym.make(ID, **SMALL, order="time"))
    with pytest.raises(ValueError, match="plan-first order"):
        IncreasingPicks(gym.make(ID, scenario="ch4-position", action="bitmask"))


def test_evaluate_plays_with_the_wrappers_mask():
    env = plan_env(budget=3, horizon=3)
    picks = []

    class Recorder(gym.Wrapper):
        def step(self, action):
            picks.append(int(action))
            return self.env.step(action)

    evaluate("random", Recorder(env), n_episodes=30, seed=0, reference=1.0)
    episodes, current = [], []
    for a in picks:
        if a == 0 or len(current) == 2:
            episodes.append(current + ([a] if a else []))
            current = []
        else:
            current.append(a)
    assert len(episodes) >= 30
    assert all(e == sorted(e) and len(set(e)) == len(e) for e in episodes)
    assert any(len(e) == 3 for e in episodes)  # random play picks, not only stops


def test_the_grid_presets_pick_in_increasing_order_by_default():
    hp = Hyperparameters()
    setup = run_setup("sparse_attack_v2", "attacker", "grid-ieee14", {}, None, hp)
    assert setup.increasing_picks
    timed = run_setup("sparse_attack_v2", "attacker", "grid-ieee14", {"order": '"time"'}, None, hp)
    assert not timed.increasing_picks  # the table's row (and this default) leaves
    off = run_setup("sparse_attack_v2", "attacker", "grid-ieee14", {}, None, hp, None, False)
    assert not off.increasing_picks  # the command line wins
    assert not run_setup("sparse_attack_v2", "attacker", None, {}, None, hp).increasing_picks
    with pytest.raises(TypeError, match="--increasing-picks"):
        TrainConfig(increasing_picks="yes")


def test_torch_ppo_refuses_increasing_picks(tmp_path):
    args = ["attacker", "--scenario", "grid-ieee14", "--runs-root", str(tmp_path / "runs")]
    with pytest.raises(ValueError, match="--increasing-picks applies to the stable-baselines3"):
        train.main([*args, "--algo", "torch-ppo", "--increasing-picks", "True"])
    assert not (tmp_path / "runs").exists()
