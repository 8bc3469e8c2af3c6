"""The plan-first picks in increasing order (``order="increasing"``), as train.py uses them.

One sequence of picks per plan (so an entropy bonus cannot be met by reordering one plan's
picks), every plan still reachable with its value, the learned policy scored in the same env
it trained in, and the grid presets' defaults.
"""

import itertools

import gymnasium as gym
import numpy as np
import pytest

from agents.config import Hyperparameters, scenario_defaults
from agents.evaluate import evaluate
from agents.training import run_setup
from baselines.sparse import exhaustive

ID = "fdia_env/SparseAttack-v2"
SMALL = {"scenario": "ch4-position", "budget": 2, "horizon": 2, "action": "sequential"}


def increasing_env(**kwargs):
    return gym.make(ID, **{**SMALL, "order": "increasing", **kwargs})


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
    for a in np.flatnonzero(env.unwrapped.action_masks()):
        out += sequences(env, (*prefix, int(a)))
    return out


def test_each_plan_has_one_increasing_sequence_of_picks_and_its_value():
    env = increasing_env()
    M, N = 3, 2  # ch4-position: 3 sensors; 6 pairs, c = 2
    runs = sequences(env)
    plans = [tuple(a for a in seq if a) for seq, _ in runs]
    assert all(list(p) == sorted(p) for p in plans)  # picks in increasing order
    assert len(plans) == len(set(plans))  # one sequence per plan
    every = {c for k in range(3) for c in itertools.combinations(range(1, N * M + 1), k)}
    assert set(plans) == every  # 1 + 6 + 15 plans: none lost
    # the same values as order="plan", which reaches each plan in every order
    plain = gym.make(ID, **SMALL, order="plan")
    for (_, value), plan in zip(runs, plans, strict=True):
        plain.reset(seed=0)
        total, done = 0.0, False
        for a in reversed(plan) if plan else (0,):  # decreasing: illegal in "increasing"
            _, reward, term, trunc, _ = plain.step(a)
            total, done = total + reward, term or trunc
        while not done:
            _, reward, term, trunc, _ = plain.step(0)
            total, done = total + reward, term or trunc
        assert total == value
    best = exhaustive("ch4-position", budget=2, horizon=2)
    assert max(v for _, v in runs) == pytest.approx(best.value, rel=1e-12)


def test_the_mask_closes_the_pairs_up_to_the_last_pick_and_resets():
    env = increasing_env(budget=3)
    env.reset(seed=0)
    masks = env.unwrapped.action_masks
    assert masks().tolist() == [1] * 7
    env.step(4)
    assert masks().tolist() == [1, 0, 0, 0, 0, 1, 1]
    *_, term, _, info = env.step(6)  # the last pair: no pair above it, the plan plays out
    assert term and info["budget_left"] == 1
    env.reset(seed=1)
    assert masks().tolist() == [1] * 7
    plain = gym.make(ID, **{**SMALL, "budget": 3, "order": "plan"})  # every order legal there
    plain.reset(seed=0)
    plain.step(4)
    assert plain.unwrapped.action_masks().tolist() == [1, 1, 1, 1, 0, 1, 1]


def test_evaluate_plays_within_the_env_mask():
    env = increasing_env(budget=3, horizon=3, illegal_action="error")
    picks = []

    class Recorder(gym.Wrapper):
        def step(self, action):
            picks.append(int(action))
            return self.env.step(action)

    evaluate("random", Recorder(env), n_episodes=30, seed=0, reference=1.0)
    episodes, current = [], []
    for a in picks:  # an episode: its picks, then a stop (none after the third pick or pair 9)
        if a:
            current.append(a)
        if not a or len(current) == 3 or a == 9:
            episodes.append(current)
            current = []
    assert len(episodes) >= 30
    assert all(e == sorted(e) and len(set(e)) == len(e) for e in episodes)
    assert any(len(e) == 3 for e in episodes)  # random play picks, not only stops


def test_the_grid_presets_pick_in_increasing_order_by_default():
    hp = Hyperparameters()
    setup = run_setup("sparse_attack_v2", "attacker", "grid-ieee14", {}, None, hp)
    assert setup.env_kwargs["order"] == "increasing"
    assert setup.algo == "MaskablePPO" and setup.normalize_reward
    # every order of the picks by name, with the same defaults otherwise
    plan = run_setup("sparse_attack_v2", "attacker", "grid-ieee14", {"order": '"plan"'}, None, hp)
    assert plan.env_kwargs["order"] == "plan"
    assert plan.algo == "MaskablePPO" and plan.normalize_reward
    timed = run_setup("sparse_attack_v2", "attacker", "grid-ieee14", {"order": '"time"'}, None, hp)
    assert not timed.normalize_reward  # the table's row leaves with its order
    assert (
        scenario_defaults("sparse_attack_v2", "grid-ieee14", {"action": "sequential"}).algo is None
    )
    # torch-ppo trains on the native vector env, which takes the env option too
    torch = run_setup("sparse_attack_v2", "attacker", "grid-ieee14", {}, "torch-ppo", hp)
    assert torch.env_kwargs["order"] == "increasing"
    venv = gym.make_vec(
        ID, num_envs=2, vectorization_mode="vector_entry_point",
        **{**torch.env_kwargs, "budget": 2, "horizon": 2},
    )  # fmt: skip
    venv.reset(seed=0)
    venv.step(np.array([40, 1]))
    masks = venv.action_masks()
    assert not masks[0, 1:41].any() and masks[0, 41:].all() and masks[1, 2:].all()
