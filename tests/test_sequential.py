"""The sparse attacker's sequential, masked action format (fdia_env/envs/sequential.py)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from pettingzoo.test import api_test, parallel_api_test

from baselines.sparse import SparsePolicy, branch_and_bound, sfs
from baselines.sparse.testbeds import mixed_tracking
from fdia_env import sparse_attack_v0
from fdia_env.attacks import SparseAttack
from fdia_env.envs.sequential import STOP, SequentialSetEnv, play_plan


def random_plan(rng: np.random.Generator, M: int, N: int, c: int) -> list[list[int]]:
    """A random attack plan (1-based sensors per window step) spending at most ``c`` pairs."""
    pairs = rng.choice(M * N, size=int(rng.integers(0, c + 1)), replace=False)
    plan: list[list[int]] = [[] for _ in range(N)]
    for p in pairs:
        plan[p // M].append(int(p % M) + 1)
    return plan


def bitmask_rewards(plan: list[list[int]], seed: int = 0, **kwargs) -> list[float]:
    """Per-window-step rewards of ``plan`` played in the ``"bitmask"`` format."""
    env = sparse_attack_v0.parallel_env(action="bitmask", illegal_action="error", **kwargs)
    env.reset(seed=seed)
    return [
        env.step({"attacker": sum(1 << (j - 1) for j in sensors)})[1]["attacker"]
        for sensors in plan
    ]


def sequential_rewards(plan: list[list[int]], seed: int = 0, **kwargs) -> list[float]:
    """Per-window-step rewards of ``plan`` in the sequential format, every stop played."""
    parallel = sparse_attack_v0.parallel_env(action="multibinary", illegal_action="error", **kwargs)
    env = SequentialSetEnv(parallel, illegal_action="error", skip_forced=False)
    env.reset(seed=seed)
    out = []
    for sensors in plan:
        for j in sorted(sensors):
            assert env.step({"attacker": j})[1]["attacker"] == 0.0  # picks pay nothing
        out.append(env.step({"attacker": STOP})[1]["attacker"])
    assert env.agents == []
    return out


@pytest.mark.parametrize("reward_mode", ["terminal", "shaped", "per_step"])
@pytest.mark.parametrize("objective", ["trace", "logdet"])
def test_same_rewards_as_bitmask_on_random_plans(reward_mode, objective):
    kwargs = dict(
        scenario=mixed_tracking(5),
        budget=4,
        horizon=5,
        reward_mode=reward_mode,
        objective=objective,
    )
    rng = np.random.default_rng(1)
    for _ in range(6):
        plan = random_plan(rng, 5, 5, 4)
        expected = bitmask_rewards(plan, **kwargs)
        assert sequential_rewards(plan, **kwargs) == expected  # step by step, exactly
        env = sparse_attack_v0.parallel_env(action="sequential", **kwargs)  # skip_forced
        assert play_plan(env, plan, seed=0) == pytest.approx(sum(expected), rel=1e-12, abs=0)


def test_sampled_dynamics_same_rewards_as_bitmask_for_the_same_seed():
    kwargs = dict(scenario="ch4-position", budget=3, horizon=6, dynamics="sampled")
    plan = [[], [1], [], [2, 3], [], []]
    assert sequential_rewards(plan, seed=7, **kwargs) == bitmask_rewards(plan, seed=7, **kwargs)


def test_solver_sets_replayed_return_their_value():
    system = mixed_tracking(6)
    for result in (branch_and_bound(system, 4, 5), sfs(system, 4, 5)):
        plan: list[list[int]] = [[] for _ in range(5)]
        for k, i in result.attacks:
            plan[k].append(i + 1)
        env = sparse_attack_v0.parallel_env(
            scenario=system, budget=4, horizon=5, action="sequential"
        )
        assert play_plan(env, plan) == pytest.approx(result.value, rel=1e-12)
    assert branch_and_bound(system, 4, 5).proved_optimal


def test_same_return_as_multibinary_on_grid_preset():
    kwargs = dict(scenario="grid-ieee14", objective="logdet")
    M, N, c = 34, 6, 6
    rng = np.random.default_rng(3)
    for _ in range(3):
        plan = random_plan(rng, M, N, c)
        multi = sparse_attack_v0.parallel_env(
            action="multibinary", illegal_action="error", **kwargs
        )
        multi.reset(seed=0)
        total = 0.0
        for sensors in plan:
            a = np.zeros(M, dtype=np.int8)
            a[np.asarray(sensors, dtype=int) - 1] = 1
            total += multi.step({"attacker": a})[1]["attacker"]
        env = sparse_attack_v0.parallel_env(action="sequential", **kwargs)
        assert play_plan(env, plan, seed=0) == pytest.approx(total, rel=1e-12, abs=0)


def test_mask_forbids_chosen_and_over_budget_and_skips_forced_stops():
    env = sparse_attack_v0.parallel_env(
        scenario="ch4-position", budget=2, horizon=4, action="sequential", illegal_action="error"
    )
    obs, _ = env.reset(seed=0)
    assert obs["attacker"]["action_mask"].tolist() == [1, 1, 1, 1]
    obs = env.step({"attacker": 2})[0]["attacker"]
    assert obs["action_mask"].tolist() == [1, 1, 0, 1]  # sensor 2 is in the set
    assert obs["observation"][-4:].tolist() == [0.0, 1.0, 0.0, 0.5]  # set, budget left after
    assert env.inner.sim.k == 0
    obs, rew, term, _, info = env.step({"attacker": STOP})
    assert env.inner.sim.k == 1 and info["attacker"]["attacked"].tolist() == [0, 1, 0]
    assert obs["attacker"]["action_mask"].tolist() == [1, 1, 1, 1]  # one pair left
    # the last pair: the set now uses the budget, so the env stops and plays the empty
    # remaining window steps itself; the episode ends at this decision with the terminal reward
    obs, rew, term, _, info = env.step({"attacker": 1})
    assert term["attacker"] and env.agents == [] and env.inner.sim.k == 4
    assert rew["attacker"] == pytest.approx(info["attacker"]["phi"], rel=1e-12)
    assert info["attacker"]["budget_left"] == 0


def test_masked_random_policy_never_errors_on_grid_preset():
    env = sparse_attack_v0.parallel_env(
        scenario="grid-ieee14", action="sequential", illegal_action="error"
    )
    rng = np.random.default_rng(0)
    for episode in range(5):
        obs, _ = env.reset(seed=episode)
        decisions, spent = 0, 0
        while env.agents:
            mask = obs["attacker"]["action_mask"]
            assert mask[STOP] == 1 and mask.dtype == np.int8 and mask.shape == (35,)
            assert np.array_equal(mask, env.action_masks())
            a = int(rng.choice(np.flatnonzero(mask)))
            obs, _, _, _, info = env.step({"attacker": a})
            decisions += 1
            spent = 6 - info["attacker"]["budget_left"]
        assert 0 <= spent <= 6
        assert decisions <= 6 + 6  # at most N + c decisions


def test_illegal_actions():
    def make(rule: str) -> SequentialSetEnv:
        env = sparse_attack_v0.parallel_env(
            scenario="ch4-position", budget=3, horizon=4, action="sequential", illegal_action=rule
        )
        env.reset(seed=0)
        env.step({"attacker": 1})
        return env

    with pytest.raises(ValueError, match="sensor 1 is already in this step's set"):
        make("error").step({"attacker": 1})
    for rule in ("trim", "noop"):  # acts as stop: the window step is taken with {1}
        env = make(rule)
        info = env.step({"attacker": 1})[4]["attacker"]
        assert env.inner.sim.k == 1 and info["attacked"].tolist() == [1, 0, 0]
    with pytest.raises(ValueError, match=r"integer in \[0, 4\)"):
        make("error").step({"attacker": 4})
    with pytest.raises(ValueError, match="budget must be >= 1"):
        sparse_attack_v0.parallel_env(scenario="ch4-position", budget=0, action="sequential")
    with pytest.raises(ValueError, match="budget must be <= M"):
        sparse_attack_v0.parallel_env(
            scenario="ch4-position", budget=13, horizon=4, action="sequential"
        )
    with pytest.raises(ValueError, match="illegal_action must be one of"):
        sparse_attack_v0.parallel_env(
            scenario="ch4-position", action="sequential", illegal_action="x"
        )
    with pytest.raises(ValueError, match="not an attack model format"):
        SparseAttack(3, action="sequential")
    with pytest.raises(ValueError, match="not available in the native vector env"):
        gym.make_vec(
            "fdia_env/SparseAttack-v0",
            num_envs=2,
            vectorization_mode="vector_entry_point",
            action="sequential",
        )
    from agents.evaluate import evaluate

    view = gym.make("fdia_env/SparseAttack-v0", scenario="ch4-position", action="sequential")
    with pytest.raises(TypeError, match="not available in the native vector env"):
        evaluate("random", view, n_episodes=2, num_envs=2)  # the batched evaluation path
    with pytest.raises(RuntimeError, match="before reset"):
        sparse_attack_v0.parallel_env(scenario="ch4-position", action="sequential").step(
            {"attacker": 0}
        )


def test_pettingzoo_api_and_aec_mask_in_observation():
    parallel_api_test(
        sparse_attack_v0.parallel_env(scenario="grid-ieee14", action="sequential"), num_cycles=60
    )
    api_test(sparse_attack_v0.env(scenario="ch4-position", action="sequential"), num_cycles=30)
    aec = sparse_attack_v0.env(scenario="ch4-position", budget=1, action="sequential")
    aec.reset(seed=0)
    assert aec.observe("attacker")["action_mask"].tolist() == [1, 1, 1, 1]
    aec.step(3)
    assert aec.terminations["attacker"]  # the only pair spent: the env played the rest


def test_gymnasium_view_and_maskable_ppo_on_grid_preset():
    sb3_contrib = pytest.importorskip("sb3_contrib")
    from gymnasium.utils.env_checker import check_env

    env = gym.make("fdia_env/SparseAttack-v0", scenario="grid-ieee14", action="sequential")
    check_env(env.unwrapped)
    obs, info = env.reset(seed=0)
    n = 13  # features: steps left, n log-variance ratios, n(n-1)/2 correlations, budget left
    assert obs.shape == (1 + n + n * (n - 1) // 2 + 1 + 34 + 1,)  # + the set, budget after it
    assert info["action_mask"].shape == (35,)
    assert env.unwrapped.action_masks().dtype == bool
    model = sb3_contrib.MaskablePPO(
        "MlpPolicy", env, n_steps=64, batch_size=32, n_epochs=1, seed=0, device="cpu"
    )
    model.learn(total_timesteps=256)
    assert model.num_timesteps >= 256
    obs, _ = env.reset(seed=1)
    done, ret = False, 0.0
    while not done:
        action, _ = model.predict(obs, action_masks=env.unwrapped.action_masks())
        assert env.unwrapped.action_masks()[int(action)]
        obs, r, term, trunc, _ = env.step(action)
        ret, done = ret + r, term or trunc
    assert np.isfinite(ret)
    vec = gym.make_vec(
        "fdia_env/SparseAttack-v0",
        num_envs=2,
        vectorization_mode="sync",
        scenario="ch4-position",
        budget=1,
        action="sequential",
    )
    _, info = vec.reset(seed=0)
    assert info["action_mask"].tolist() == [[1, 1, 1, 1]] * 2
    terminated = vec.step(np.array([2, 0]))[2]
    assert terminated.tolist() == [True, False]  # the only pair spent: the rest played by the env


def test_solver_policy_in_sequential_format_returns_its_value():
    for scenario, budget, horizon in (("ch4-position", 5, 6), ("grid-ieee14", 6, 6)):
        result = sfs(scenario, budget, horizon)
        policy = result.policy("sequential")
        env = gym.make(
            "fdia_env/SparseAttack-v0",
            scenario=scenario,
            budget=budget,
            horizon=horizon,
            action="sequential",
            illegal_action="error",
        )
        obs, _ = env.reset(seed=0)
        total, done = 0.0, False
        while not done:
            action, _ = policy.predict(obs)
            obs, reward, terminated, truncated, _ = env.step(action)
            total, done = total + reward, terminated or truncated
        assert total == pytest.approx(result.value, rel=1e-12)
    batch = np.zeros((2, 9), dtype=np.float32)  # ch4-position: 5 features + 3 set + budget
    batch[:, 0] = 1.0  # step K+1 (6 steps left of 6)
    batch[1, 5] = 1.0  # member 1 already has sensor 1 in the set
    plan = SparsePolicy([[1, 1, 0]] + [[0, 0, 0]] * 5, sequential=True)
    assert plan.predict(batch)[0].tolist() == [1, 2]
    with pytest.raises(ValueError, match=r"needs an \(N, M\) 0/1 plan"):
        SparsePolicy([1, 3], sequential=True)


def test_train_py_attacker_on_the_sequential_format_scores_the_optimum(tmp_path, capsys):
    import json
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # train.py is at the root
    import train

    result = train.main(
        [
            "attacker", "--env-kwargs", "action", '"sequential"', "--algo", "MaskablePPO",
            "--total-timesteps", "128", "--eval-freq", "0", "--checkpoint-freq", "128",
            "--no-progress-bar", "--final-eval-episodes", "3", "--n-steps", "64",
            "--batch-size", "32", "--n-epochs", "1", "--runs-root", str(tmp_path / "runs"),
        ]
    )  # fmt: skip
    scores = json.loads((result.run_dir / "scores.json").read_text())["evaluations"]
    assert scores["EXS"]["score"] == pytest.approx(1.0, rel=1e-12)  # its plan, one by one
    assert 0 < scores["learned (MaskablePPO)"]["score"] <= 1 + 1e-12
