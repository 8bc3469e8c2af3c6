"""The sparse attacker's sequential, masked action format (fdia_env/envs/sequential.py)."""

from __future__ import annotations

import itertools

import gymnasium as gym
import numpy as np
import pytest
from pettingzoo.test import api_test, parallel_api_test

from baselines.sparse import SparsePolicy, branch_and_bound, exhaustive, sfs
from baselines.sparse.testbeds import mixed_tracking
from fdia_env import sparse_attack_v0
from fdia_env.attacks import SparseAttack
from fdia_env.envs.sequential import STOP, SequentialSetEnv, plan_actions, play_plan


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


def multibinary_return(plan: list[list[int]], M: int, seed: int = 0, **kwargs) -> float:
    """The return of ``plan`` played in the ``"multibinary"`` format (``M`` sensors)."""
    multi = sparse_attack_v0.parallel_env(action="multibinary", illegal_action="error", **kwargs)
    multi.reset(seed=seed)
    total = 0.0
    for sensors in plan:
        a = np.zeros(M, dtype=np.int8)
        a[np.asarray(sensors, dtype=int) - 1] = 1
        total += multi.step({"attacker": a})[1]["attacker"]
    return total


def solver_plan(result, horizon: int) -> list[list[int]]:
    """The attack plan (1-based sensors per window step) of a solver result's ``attacks``."""
    plan: list[list[int]] = [[] for _ in range(horizon)]
    for k, i in result.attacks:
        plan[k].append(i + 1)
    return plan


def _view_return(view: gym.Env, policy) -> float:
    """The return of one episode of ``policy`` (deterministic ``predict``) in a Gymnasium view."""
    obs, _ = view.reset(seed=0)
    total, done = 0.0, False
    while not done:
        obs, r, term, trunc, _ = view.step(int(policy.predict(obs)[0]))
        total, done = total + r, term or trunc
    return total


def sequential_rewards(
    plan: list[list[int]], seed: int = 0, order: str = "time", **kwargs
) -> list[float]:
    """Per-window-step rewards of ``plan`` in the sequential format's ``order``, every stop played.

    ``"time"``: each window step's picks, then its stop; ``"plan"``: the plan's picks, then one
    stop per window step as the plan plays out (stop the only legal action).
    """
    parallel = sparse_attack_v0.parallel_env(action="multibinary", illegal_action="error", **kwargs)
    env = SequentialSetEnv(parallel, illegal_action="error", skip_forced=False, order=order)
    env.reset(seed=seed)
    if order == "time":
        steps = [(sorted(sensors), STOP) for sensors in plan]
    else:
        *picks, stop = plan_actions(env, plan)
        steps = [(picks, stop)] + [([], stop)] * (len(plan) - 1)
    out = []
    for picks, stop in steps:
        for a in picks:
            assert env.step({"attacker": a})[1]["attacker"] == 0.0  # picks pay nothing
        out.append(env.step({"attacker": stop})[1]["attacker"])
        if order != "time":  # the plan plays out: stop is the only legal action now
            assert env.action_mask()[1:].sum() == 0
    assert env.agents == []
    return out


@pytest.mark.parametrize("reward_mode", ["terminal", "shaped", "per_step"])
@pytest.mark.parametrize("objective", ["trace", "logdet"])
@pytest.mark.parametrize(("order", "rng_seed"), [("time", 1), ("plan", 2)], ids=["time", "plan"])
def test_same_rewards_as_bitmask_on_random_plans(order, rng_seed, reward_mode, objective):
    kwargs = dict(
        scenario=mixed_tracking(5),
        budget=4,
        horizon=5,
        reward_mode=reward_mode,
        objective=objective,
    )
    rng = np.random.default_rng(rng_seed)
    for _ in range(6):
        plan = random_plan(rng, 5, 5, 4)
        expected = bitmask_rewards(plan, **kwargs)
        assert sequential_rewards(plan, order=order, **kwargs) == expected  # step by step, exactly
        env = sparse_attack_v0.parallel_env(action="sequential", order=order, **kwargs)
        # skip_forced: the env plays the forced stops itself
        assert play_plan(env, plan, seed=0) == pytest.approx(sum(expected), rel=1e-12, abs=0)


def test_sampled_dynamics_same_rewards_as_bitmask_for_the_same_seed():
    kwargs = dict(scenario="ch4-position", budget=3, horizon=6, dynamics="sampled")
    plan = [[], [1], [], [2, 3], [], []]
    assert sequential_rewards(plan, seed=7, **kwargs) == bitmask_rewards(plan, seed=7, **kwargs)


@pytest.mark.parametrize("order", ["time", "plan"])
def test_solver_sets_replayed_return_their_value(order):
    system = mixed_tracking(6)
    bnb = branch_and_bound(system, 4, 5)
    for result in (bnb, sfs(system, 4, 5)):
        env = sparse_attack_v0.parallel_env(
            scenario=system, budget=4, horizon=5, action="sequential", order=order
        )
        assert play_plan(env, solver_plan(result, 5)) == pytest.approx(result.value, rel=1e-12)
    assert bnb.proved_optimal


def test_same_return_as_multibinary_on_grid_preset():
    kwargs = dict(scenario="grid-ieee14", objective="logdet")
    M, N, c = 34, 6, 6
    rng = np.random.default_rng(3)
    for _ in range(3):
        plan = random_plan(rng, M, N, c)
        total = multibinary_return(plan, M, **kwargs)
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
    from agents.evaluate import evaluate

    # the batched evaluation path plays the native vector env of the format: same returns
    kwargs = dict(scenario="ch4-position", budget=3, horizon=5, action="sequential")
    view = gym.make("fdia_env/SparseAttack-v0", **kwargs)
    result = sfs("ch4-position", 3, 5)
    one = evaluate(result.policy("sequential"), view, n_episodes=2, reference=result.value)
    batched = evaluate(
        result.policy("sequential"), view, n_episodes=3, num_envs=3, reference=result.value
    )
    assert one.returns.tolist() == pytest.approx([result.value] * 2, rel=1e-12)
    assert batched.returns.tolist() == pytest.approx([result.value] * 3, rel=1e-12)
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
        assert _view_return(env, policy) == pytest.approx(result.value, rel=1e-12)
    batch = np.zeros((2, 9), dtype=np.float32)  # ch4-position: 5 features + 3 set + budget
    batch[:, 0] = 1.0  # step K+1 (6 steps left of 6)
    batch[1, 5] = 1.0  # member 1 already has sensor 1 in the set
    plan = SparsePolicy([[1, 1, 0]] + [[0, 0, 0]] * 5, sequential=True)
    assert plan.predict(batch)[0].tolist() == [1, 2]
    with pytest.raises(ValueError, match=r"needs an \(N, M\) 0/1 plan"):
        SparsePolicy([1, 3], sequential=True)


def train_sequential_scores(tmp_path, agent: str, algo: str, final_eval_episodes: int) -> dict:
    """The final evaluations (scores.json) of a short train.py run in the sequential format."""
    import json
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # train.py is at the root
    import train

    result = train.main(
        [
            agent, "--env-kwargs", "action", '"sequential"', "--algo", algo,
            "--total-timesteps", "128", "--eval-freq", "0", "--checkpoint-freq", "128",
            "--no-progress-bar", "--final-eval-episodes", str(final_eval_episodes),
            "--n-steps", "64", "--batch-size", "32", "--n-epochs", "1",
            "--runs-root", str(tmp_path / "runs"),
        ]
    )  # fmt: skip
    return json.loads((result.run_dir / "scores.json").read_text())["evaluations"]


def test_train_py_attacker_on_the_sequential_format_scores_the_optimum(tmp_path, capsys):
    scores = train_sequential_scores(tmp_path, "attacker", "MaskablePPO", final_eval_episodes=3)
    assert scores["EXS"]["score"] == pytest.approx(1.0, rel=1e-12)  # its plan, one by one
    assert 0 < scores["learned (MaskablePPO)"]["score"] <= 1 + 1e-12


# --- The sensor game's sequential format (SequentialSubsetEnv) ---------------------------------


def seq_round(env, plans: dict[str, list[int]]) -> dict[str, float]:
    """Play one round: each player sends its plan's picks, then stop; return the rewards."""
    queues = {p: list(v) for p, v in plans.items()}
    total = dict.fromkeys(env.agents, 0.0)
    while True:
        acts = {p: queues[p].pop(0) if queues[p] else STOP for p in env.agents}
        rewards = env.step(acts)[1]
        for p in total:
            total[p] += rewards[p]
        if env.committed:
            return total


def game_pairs(M: int, k: int | None):
    from fdia_env.attacks.subsets import game_subsets

    return game_subsets(M, k, "attacker"), game_subsets(M, k, "defender")


@pytest.mark.parametrize("k", [None, 1, 2])
def test_sensor_game_every_subset_pair_pays_as_in_the_subset_format(k):
    from fdia_env import sensor_game_v0
    from fdia_env.envs.sequential import SequentialSubsetEnv, subset_actions

    old = sensor_game_v0.parallel_env(max_subset_size=k)
    seq = sensor_game_v0.parallel_env(
        max_subset_size=k, action="sequential", illegal_action="error"
    )
    assert isinstance(seq, SequentialSubsetEnv)
    attacks, defenses = game_pairs(3, k)
    assert [old.attack.subsets, old.defense.subsets] == [attacks, defenses]
    for a, A in enumerate(attacks):
        for d, D in enumerate(defenses):
            old.reset(seed=0)
            want = old.step({"attacker": a, "defender": d})[1]
            seq.reset(seed=0)
            plans = {p: subset_actions(seq, p, S) for p, S in [("attacker", A), ("defender", D)]}
            assert len(plans["attacker"]) == len(A) and len(plans["defender"]) == 3 - len(D)
            got = seq_round(seq, plans)
            assert got["attacker"] == want["attacker"] > 0
            assert got["defender"] == want["defender"] == -want["attacker"]
            assert seq.agents == []  # rounds=1: the episode ended with the round


def test_sensor_game_only_the_subset_formats_sets_are_legal():
    """Every pick set is tried: it is legal exactly when its subset is a strategy."""
    from fdia_env import sensor_game_v0

    for k in (None, 1, 2):
        env = sensor_game_v0.parallel_env(
            max_subset_size=k, action="sequential", illegal_action="error"
        )
        for p, other in (("attacker", "defender"), ("defender", "attacker")):
            reached = set()
            for r in range(4):
                for picks in itertools.combinations(range(1, 4), r):
                    env.reset(seed=0)
                    plans = {p: list(picks), other: [1] if other == "attacker" else []}
                    try:
                        seq_round(env, plans)
                    except ValueError as exc:
                        assert "is illegal" in str(exc)
                        continue
                    chosen = {j - 1 for j in picks}
                    induced = tuple(sorted(set(range(3)) - chosen if p == "defender" else chosen))
                    if env.models[p].last_subset == induced:  # else the round ended before
                        reached.add(induced)
            model = env.models[p]
            assert reached == set(model.subsets), (k, p)


def test_sensor_game_repeated_random_rounds_match_the_subset_format():
    from fdia_env import sensor_game_v0
    from fdia_env.envs.sequential import subset_actions

    rng = np.random.default_rng(3)
    kw = dict(rounds=4, types=("independent", "dependent"), reward_mode="per_step")
    for dynamics in ("expected", "sampled"):
        old = sensor_game_v0.parallel_env(dynamics=dynamics, **kw)
        seq = sensor_game_v0.parallel_env(dynamics=dynamics, action="sequential", **kw)
        for seed in range(3):
            o_obs, o_inf = old.reset(seed=seed)
            _, s_inf = seq.reset(seed=seed)
            assert o_inf["attacker"]["type"] == s_inf["attacker"]["type"]
            while old.agents:
                a, d = (int(rng.integers(7)) for _ in range(2))
                o_obs, want, *_ = old.step({"attacker": a, "defender": d})
                plans = {
                    "attacker": subset_actions(seq, "attacker", old.attack.subsets[a]),
                    "defender": subset_actions(seq, "defender", old.defense.subsets[d]),
                }
                got = seq_round(seq, plans)
                assert got == want
                for p in ("attacker", "defender"):  # the same features, then an empty set
                    obs = seq.inner_observation(p)
                    np.testing.assert_array_equal(obs, o_obs[p])
            assert seq.agents == []


def test_sensor_game_masks_forced_stops_and_waiting():
    from fdia_env import sensor_game_v0
    from fdia_env.envs.sequential import SequentialSubsetEnv

    env = sensor_game_v0.parallel_env(max_subset_size=1, rounds=2, action="sequential")
    obs, _ = env.reset(seed=0)
    assert obs["attacker"]["action_mask"].tolist() == [0, 1, 1, 1]  # at least one sensor
    assert obs["defender"]["action_mask"].tolist() == [1, 1, 1, 1]  # may keep every sensor
    obs, rewards, *_ = env.step({"attacker": 2, "defender": 3})
    assert env.committed and rewards["attacker"] > 0  # both used their one pick: round played
    assert env.inner.attack.last_subset == (1,) and env.inner.defense.last_subset == (0, 1)
    np.testing.assert_array_equal(obs["attacker"]["observation"][-3:], [0, 0, 0])
    obs, rewards, *_ = env.step({"attacker": 1, "defender": 0})  # the defender stops at once
    assert env.committed and rewards["attacker"] > 0 and env.agents == []
    assert env.inner.defense.last_subset == (0, 1, 2)
    env = sensor_game_v0.parallel_env(action="sequential")  # every subset: up to 3 picks
    env.reset(seed=0)
    obs, rewards, *_ = env.step({"attacker": 1, "defender": 0})
    assert not env.committed and rewards["attacker"] == 0.0
    assert obs["defender"]["action_mask"].tolist() == [1, 0, 0, 0]  # stopped: waits
    obs, rewards, *_ = env.step({"attacker": 2, "defender": 0})
    assert obs["attacker"]["action_mask"].tolist() == [1, 0, 0, 1]
    np.testing.assert_array_equal(obs["attacker"]["observation"][-3:], [1, 1, 0])
    env.step({"attacker": 3, "defender": 0})  # every sensor picked: the env stops for it
    assert env.committed and env.inner.attack.last_subset == (0, 1, 2)
    free = SequentialSubsetEnv(sensor_game_v0.parallel_env(), "error", skip_forced=False)
    free.reset(seed=0)
    free.step({"attacker": 1, "defender": 0})
    obs = free.step({"attacker": 2, "defender": 0})[0]
    assert obs["defender"]["action_mask"].tolist() == [1, 0, 0, 0]  # stopped: waits
    assert obs["attacker"]["action_mask"].tolist() == [1, 0, 0, 1]
    free.step({"attacker": 3, "defender": 0})
    assert not free.committed  # every sensor picked, stop not yet taken
    assert free.action_masks("attacker").tolist() == [1, 0, 0, 0]
    free.step({"attacker": 0, "defender": 0})
    assert free.committed and free.inner.attack.last_subset == (0, 1, 2)


def test_sensor_game_sequential_illegal_actions():
    from fdia_env import sensor_game_v0
    from fdia_env.envs.sequential import SequentialSubsetEnv

    def make(rule):
        env = sensor_game_v0.parallel_env(action="sequential", illegal_action=rule)
        env.reset(seed=0)
        return env

    with pytest.raises(ValueError, match="attacker's set is empty"):
        make("error").step({"attacker": 0, "defender": 0})
    env = make("error")
    env.step({"attacker": 1, "defender": 0})
    with pytest.raises(ValueError, match="sensor 1 is already picked"):
        env.step({"attacker": 1, "defender": 0})
    with pytest.raises(ValueError, match="defender has stopped this round and waits"):
        env.step({"attacker": 2, "defender": 2})
    env = SequentialSubsetEnv(sensor_game_v0.parallel_env(), "error", skip_forced=False)
    env.reset(seed=0)
    env.step({"attacker": 1, "defender": 1})
    env.step({"attacker": 2, "defender": 2})
    with pytest.raises(ValueError, match="defender has used its 2 picks"):
        env.step({"attacker": 3, "defender": 3})
    for rule in ("trim", "noop"):
        env = make(rule)
        env.step({"attacker": 0, "defender": 2})  # an illegal stop is ignored
        assert env.action_mask("attacker").tolist() == [0, 1, 1, 1] and not env.committed
        env.step({"attacker": 1, "defender": 3})  # the defender's 2 picks: it has stopped
        env.step({"attacker": 1, "defender": 1})  # a repeated pick stops; a waiting one: ignored
        assert env.committed
        assert env.inner.attack.last_subset == (0,) and env.inner.defense.last_subset == (0,)
    with pytest.raises(ValueError, match=r"integer in \[0, 4\)"):
        make("error").step({"attacker": 4, "defender": 0})
    with pytest.raises(ValueError, match="exactly one entry per live agent"):
        make("error").step({"attacker": 1})
    with pytest.raises(ValueError, match="action must be one of"):
        sensor_game_v0.parallel_env(action="bitmask")
    with pytest.raises(ValueError, match="illegal_action applies to action='sequential' only"):
        sensor_game_v0.parallel_env(illegal_action="error")
    with pytest.raises(ValueError, match="illegal_action must be one of"):
        sensor_game_v0.parallel_env(action="sequential", illegal_action="x")
    # the native vector env of the format (tests/test_sequential_game_vector.py) applies the
    # same rule
    native = gym.make_vec(
        "fdia_env/SensorGameAttacker-v0",
        num_envs=2,
        vectorization_mode="vector_entry_point",
        action="sequential",
        illegal_action="error",
    )
    native.reset(seed=0)
    with pytest.raises(ValueError, match="the attacker's set is empty"):
        native.step(np.array([1, 0]))


def test_sensor_game_sequential_pettingzoo_api_and_aec_mask():
    from fdia_env import sensor_game_v0

    parallel_api_test(sensor_game_v0.parallel_env(rounds=3, action="sequential"), num_cycles=40)
    parallel_api_test(
        sensor_game_v0.parallel_env(scenario="grid-ieee14", action="sequential"), num_cycles=20
    )
    api_test(sensor_game_v0.env(rounds=3, action="sequential"), num_cycles=40)
    aec = sensor_game_v0.env(max_subset_size=1, action="sequential")
    aec.reset(seed=0)
    assert aec.observe("attacker")["action_mask"].tolist() == [0, 1, 1, 1]
    aec.step(2)  # the attacker picks z2
    assert aec.observe("defender")["action_mask"].tolist() == [1, 1, 1, 1]
    aec.step(0)  # the defender keeps every sensor: the round is played
    assert aec.terminations["attacker"] and aec.rewards["attacker"] > 0


@pytest.mark.parametrize("agent", ["attacker", "defender"])
def test_sensor_game_gymnasium_view_matches_the_subset_formats_view(agent):
    from gymnasium.utils.env_checker import check_env

    from fdia_env.envs.opponents import FixedMix
    from fdia_env.envs.sequential import SequentialGameView, subset_actions

    gid = (
        "fdia_env/SensorGameAttacker-v0"
        if agent == "attacker"
        else "fdia_env/SensorGameDefender-v0"
    )
    kw = dict(scenario="ch5-game", rounds=3)
    old = gym.make(gid, opponent=FixedMix([0.2, 0.1, 0.3, 0.1, 0.1, 0.1, 0.1]), **kw)
    seq = gym.make(
        gid, opponent=FixedMix([0.2, 0.1, 0.3, 0.1, 0.1, 0.1, 0.1]), action="sequential", **kw
    )
    assert isinstance(seq.unwrapped, SequentialGameView)
    check_env(gym.make(gid, action="sequential", **kw).unwrapped)
    rng = np.random.default_rng(0)
    for seed in range(4):
        old.reset(seed=seed)
        obs, info = seq.reset(seed=seed)
        assert obs.shape == (4 + 3 + 3,) and info["action_mask"].dtype == np.int8
        done = False
        while not done:
            j = int(rng.integers(7))
            _, want, term, trunc, _ = old.step(j)
            view = seq.unwrapped
            queue = subset_actions(view.parallel, agent, view.parallel.models[agent].subsets[j])
            got, view.parallel.committed = 0.0, False
            while not view.parallel.committed:
                a = queue.pop(0) if queue else STOP
                assert view.action_masks()[a]
                _, r, s_term, s_trunc, _ = seq.step(a)
                got += r
            assert got == want and (s_term, s_trunc) == (term, trunc)
            done = term or trunc


def test_sensor_game_maskable_ppo_on_grid_preset():
    sb3_contrib = pytest.importorskip("sb3_contrib")

    env = gym.make("fdia_env/SensorGameAttacker-v0", scenario="grid-ieee14", action="sequential")
    obs, info = env.reset(seed=0)
    assert env.action_space.n == 35 and info["action_mask"].sum() == 34  # no stop yet
    model = sb3_contrib.MaskablePPO("MlpPolicy", env, n_steps=64, batch_size=32, seed=0)
    model.learn(total_timesteps=256)
    assert model.num_timesteps == 256
    total, rounds = 0.0, 0
    obs, _ = env.reset(seed=1)
    for _ in range(20):
        action, _ = model.predict(
            obs, action_masks=env.unwrapped.action_masks(), deterministic=True
        )
        obs, r, term, trunc, _ = env.step(action)
        total += r
        if term or trunc:
            rounds += 1
            obs, _ = env.reset()
    assert rounds >= 10 and total > 0  # the preset's k = 2: at most 2 decisions per round


def test_covariance_game_page_sequential_snippet_prints_what_the_page_shows(capsys):
    import pathlib
    import re

    page = pathlib.Path(__file__).parents[1] / "docs" / "guide" / "covariance_game.md"
    section = page.read_text(encoding="utf-8").split("## Sequential action format")[1]
    code, shown = re.findall(r"^```(?:python)?\n(.*?)^```", section, re.S | re.M)[:2]
    exec(compile(code, "<covariance_game.md>", "exec"), {})
    assert capsys.readouterr().out == shown


def test_sensor_game_sequential_evaluation_plays_subset_mixes_and_scores_learned_policies(
    tmp_path,
):
    from agents.evaluate import evaluate
    from agents.registry import get
    from baselines.game import MixedStrategyPolicy

    entry = get("sensor_game_v0", "defender")
    old = gym.make("fdia_env/SensorGameDefender-v0")
    seq = gym.make("fdia_env/SensorGameDefender-v0", action="sequential")
    ref = entry.reference_of(seq)
    results = [
        evaluate(MixedStrategyPolicy(ref.policy.probs, seed=0), env, 12, 0, ref)
        for env in (old, seq)
    ]
    assert results[1].mean == pytest.approx(results[0].mean, rel=1e-12)  # the same rounds
    assert results[1].score == pytest.approx(0.0, abs=1e-9)  # the equilibrium: exploitability 0
    np.testing.assert_allclose(results[1].strategy, ref.policy.probs)
    scores = train_sequential_scores(tmp_path, "defender", "PPO", final_eval_episodes=4)
    learned = scores["learned (PPO)"]
    assert sorted(learned["strategy"]) == [0.0] * 6 + [1.0]  # one subset: its pure strategy
    assert learned["score"] >= 0 and scores["game value (LP)"]["score"] < 1e-9
    assert sum(scores["random"]["strategy"]) == pytest.approx(1.0)


def test_wrappers_pass_pettingzoo_api_tests_without_the_reset_options_warning():
    """PettingZoo's api tests reset with options={"options": 1}: no warning for that probe."""
    import warnings

    from fdia_env import sensor_game_v0
    from fdia_env.envs.sequential import SequentialBase, SequentialSubsetEnv

    envs = [
        lambda: sparse_attack_v0.parallel_env(scenario="ch4-position", action="sequential"),
        lambda: sensor_game_v0.parallel_env(rounds=2, action="sequential"),
    ]
    for make in envs:
        assert isinstance(make(), SequentialBase)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            parallel_api_test(make(), num_cycles=10)
        assert not [w for w in caught if "reset options" in str(w.message)]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        api_test(sensor_game_v0.env(rounds=2, action="sequential"), num_cycles=10)
    assert not [w for w in caught if "reset options" in str(w.message)]
    # a setting passed to reset by mistake still warns once, naming the caller's line
    for env in (envs[0](), envs[1]()):
        with pytest.warns(UserWarning, match=r"reset options \['budget'\] are ignored") as rec:
            env.reset(seed=0, options={"budget": 2})
        assert len(rec) == 1 and rec[0].filename == __file__
    view = envs[1]().gymnasium_view("defender")
    with pytest.warns(UserWarning, match=r"reset options \['budget'\] are ignored") as rec:
        view.reset(seed=0, options={"budget": 2})
    assert len(rec) == 1 and rec[0].filename == __file__  # once, not again by the wrapper
    # the shared base: max_cycles is the wrapper's (decisions), the wrapped env has none
    game = envs[1]()
    assert isinstance(game, SequentialSubsetEnv)
    game.max_cycles = 1
    assert game.inner.max_cycles is None and game.max_cycles == 1
    assert game.spec is game.inner.spec and game.system is game.inner.system


class SequentialModule:
    """A PettingZoo env module whose envs are ``module``'s in the sequential format."""

    def __init__(self, module, **kwargs):
        self.module, self.kwargs = module, kwargs

    def parallel_env(self, **kwargs):
        return self.module.parallel_env(action="sequential", **self.kwargs, **kwargs)

    def env(self, **kwargs):
        return self.module.env(action="sequential", **self.kwargs, **kwargs)


@pytest.mark.parametrize("game", [False, True], ids=["sparse", "sensor-game"])
def test_pettingzoo_seed_max_cycles_and_render_tests_pass_in_the_sequential_format(game):
    from pettingzoo.test import max_cycles_test, parallel_seed_test, seed_test

    from fdia_env import sensor_game_v0

    mod = (
        SequentialModule(sensor_game_v0, rounds=3)
        if game
        else SequentialModule(sparse_attack_v0, scenario="ch4-position", horizon=6)
    )
    seed_test(mod.env, num_cycles=20)
    parallel_seed_test(mod.parallel_env, num_cycles=20)
    max_cycles_test(mod)  # max_cycles counts decisions, as PettingZoo's test expects
    # rendering is the wrapped env's (PettingZoo's render_test runs on it in test_clients.py)
    aec = mod.env(render_mode="ansi")
    aec.reset(seed=0)
    assert "step 0/" in aec.render() and aec.render_mode == "ansi"
    env = mod.parallel_env(max_cycles=2)
    env.reset(seed=0)
    env.step(dict.fromkeys(env.agents, 1))
    truncs = env.step(dict.fromkeys(env.agents, 0 if not game else 2))[3]
    assert all(truncs.values()) and env.agents == []
    with pytest.raises(ValueError, match="max_cycles must be"):
        env.max_cycles = 0


# --- order="plan": the (sensor, window step) pairs of the whole horizon first ------------------


SMALL = dict(scenario="ch4-position", budget=2, horizon=2, reward_mode="shaped")


def _every_small_plan() -> list[list[list[int]]]:
    """The 22 plans of at most 2 pairs of :data:`SMALL` (M = 3, N = 2), sensors 1-based."""
    pairs = list(itertools.product(range(2), range(1, 4)))
    plans = []
    for size in range(3):
        for chosen in itertools.combinations(pairs, size):
            plan: list[list[int]] = [[], []]
            for k, j in chosen:
                plan[k].append(j)
            plans.append(plan)
    return plans


def test_plan_order_every_attack_set_reachable_and_only_those():
    """M = 3, N = 2, c = 2: each of the 22 sets of <= 2 pairs, and no larger set, is played."""
    kwargs = SMALL
    env = sparse_attack_v0.parallel_env(
        action="sequential", order="plan", illegal_action="error", **kwargs
    )
    plans = _every_small_plan()
    for plan in plans:
        expected = sum(bitmask_rewards(plan, **kwargs))
        assert play_plan(env, plan, seed=0) == pytest.approx(expected, rel=1e-12, abs=0)
    assert len(plans) == 22
    env.reset(seed=0)
    env.step({"attacker": 1})
    assert env.action_mask().tolist() == [1, 0, 1, 1, 1, 1, 1]
    env.step({"attacker": 6})  # the budget is used: the env plays the plan out at once
    assert env.agents == []


def test_plan_order_same_return_as_multibinary_on_grid_preset_and_masked_random_play():
    kwargs = dict(scenario="grid-ieee14", objective="logdet")
    M, N, c = 34, 6, 6
    rng = np.random.default_rng(4)
    env = sparse_attack_v0.parallel_env(
        action="sequential", order="plan", illegal_action="error", **kwargs
    )
    assert env.action_space("attacker").n == N * M + 1
    for _ in range(2):
        plan = random_plan(rng, M, N, c)
        total = multibinary_return(plan, M, **kwargs)
        assert play_plan(env, plan, seed=0) == pytest.approx(total, rel=1e-12, abs=0)
    for episode in range(3):  # a masked random policy never meets the "error" rule
        obs, _ = env.reset(seed=episode)
        decisions = 0
        while env.agents:
            mask = obs["attacker"]["action_mask"]
            assert mask.shape == (N * M + 1,) and mask[STOP] == 1
            obs, *_ = env.step({"attacker": int(rng.choice(np.flatnonzero(mask)))})
            decisions += 1
        assert decisions <= c + 1  # the plan's picks and one stop (skip_forced)


def test_plan_order_mask_observation_and_illegal_actions():
    def make(rule: str) -> SequentialSetEnv:
        return sparse_attack_v0.parallel_env(
            scenario="ch4-position",
            budget=2,
            horizon=3,
            action="sequential",
            order="plan",
            illegal_action=rule,
        )

    env = make("error")
    obs, _ = env.reset(seed=0)
    assert obs["attacker"]["observation"].shape == (5 + 9 + 1,)
    obs = env.step({"attacker": 5})[0]["attacker"]  # sensor 2 at window step 2
    assert obs["action_mask"].tolist() == [1, 1, 1, 1, 1, 0, 1, 1, 1, 1]
    assert obs["observation"][-10:].tolist() == [0, 0, 0, 0, 1, 0, 0, 0, 0, 0.5]
    assert env.inner.sim.k == 0  # nothing played while planning
    with pytest.raises(ValueError, match=r"sensor 2 at window step 2\) is illegal: this pair is"):
        env.step({"attacker": 5})
    with pytest.raises(ValueError, match=r"integer in \[0, 10\)"):
        env.step({"attacker": 10})
    for rule in ("trim", "noop"):  # an illegal pick stops: the plan plays out
        env = make(rule)
        env.reset(seed=0)
        env.step({"attacker": 5})
        _, _, term, _, info = env.step({"attacker": 5})
        assert term["attacker"] and info["attacker"]["budget_left"] == 1
    parallel = sparse_attack_v0.parallel_env(
        action="multibinary", scenario="ch4-position", budget=2, horizon=3
    )
    slow = SequentialSetEnv(parallel, illegal_action="error", skip_forced=False, order="plan")
    slow.reset(seed=0)
    slow.step({"attacker": 0})
    with pytest.raises(ValueError, match="the plan is committed and plays out"):
        slow.step({"attacker": 1})
    with pytest.raises(ValueError, match="order must be one of"):
        sparse_attack_v0.parallel_env(action="sequential", order="random")
    with pytest.raises(ValueError, match="order='plan' applies to action='sequential' only"):
        sparse_attack_v0.parallel_env(action="bitmask", order="plan")
    with pytest.raises(ValueError, match=r"must be in a plan-first order \['plan', 'increasing'\]"):
        plan_actions(sparse_attack_v0.parallel_env(action="sequential"), [[1]])


def test_plan_order_pettingzoo_and_gymnasium_conformance():
    from gymnasium.utils.env_checker import check_env

    parallel_api_test(
        sparse_attack_v0.parallel_env(scenario="ch4-position", action="sequential", order="plan"),
        num_cycles=30,
    )
    api_test(
        sparse_attack_v0.env(scenario="ch4-position", action="sequential", order="plan"),
        num_cycles=30,
    )
    mod = SequentialModule(sparse_attack_v0, scenario="ch4-position", horizon=6, order="plan")
    from pettingzoo.test import parallel_seed_test, seed_test

    seed_test(mod.env, num_cycles=20)
    parallel_seed_test(mod.parallel_env, num_cycles=20)
    env = mod.parallel_env(max_cycles=2)  # max_cycles counts decisions, the picks too
    env.reset(seed=0)
    assert not env.step({"attacker": 1})[3]["attacker"]
    assert env.step({"attacker": 2})[3]["attacker"] and env.agents == []
    view = gym.make(
        "fdia_env/SparseAttack-v1",
        scenario="ch4-position",
        horizon=3,
        action="sequential",
        order="plan",
    )
    check_env(view.unwrapped, skip_render_check=True)
    view.reset(seed=0)
    assert view.unwrapped.action_masks().tolist() == [True] * 10


def test_plan_order_reference_policy_plays_the_solver_set_in_the_env_format():
    from agents.registry import sparse_reference
    from fdia_env.envs.sequential import PlanOrderPolicy

    env = sparse_attack_v0.parallel_env(
        scenario="ch4-position", budget=2, horizon=3, action="sequential", order="plan"
    )
    ref = sparse_reference(env)
    best = exhaustive("ch4-position", budget=2, horizon=3)
    assert ref.value == pytest.approx(best.value, rel=1e-12)
    assert isinstance(ref.policy, PlanOrderPolicy)
    view = gym.make(
        "fdia_env/SparseAttack-v0",
        scenario="ch4-position",
        budget=2,
        horizon=3,
        action="sequential",
        order="plan",
        illegal_action="error",
    )
    assert _view_return(view, ref.policy) == pytest.approx(best.value, rel=1e-12)
    with pytest.raises(ValueError, match=r"attacks must be \(step, sensor\) pairs"):
        PlanOrderPolicy([(3, 0)], num_sensors=3, horizon=3)


def test_plan_playout_reads_the_wrapped_observation_once_and_hands_out_copies(monkeypatch):
    kwargs = dict(scenario="ch4-position", budget=2, horizon=4)
    env = sparse_attack_v0.parallel_env(action="sequential", order="plan", **kwargs)
    M, N = env.M, 4
    reads: list[str] = []
    observe = env.inner._observe
    monkeypatch.setattr(env.inner, "_observe", lambda agent: reads.append(agent) or observe(agent))
    obs, _ = env.reset(seed=0)
    obs["attacker"]["action_mask"][:] = 0  # the caller's arrays, not the env's state
    obs["attacker"]["observation"][:] = 7.0
    assert env.action_mask().sum() == N * M + 1
    reads.clear()
    obs = env.step({"attacker": 1 + 2 * M + 1})[0]["attacker"]  # sensor 2 at window step 3
    assert reads == [] and env.inner.sim.k == 0  # a pick plays no window step
    assert obs["observation"][-(N * M + 1) :].sum() == pytest.approx(1 + 1 / 2)
    obs, rewards, term, _, infos = env.step({"attacker": STOP})  # the plan's 4 window steps
    assert reads == ["attacker"] and env.inner.sim.k == N and term["attacker"]
    assert env.inner.agents == [] and env.agents == []  # both episodes over
    multi = sparse_attack_v0.parallel_env(action="multibinary", **kwargs)
    multi.reset(seed=0)
    total = 0.0
    for k in range(N):
        a = np.zeros(M, dtype=np.int8)
        a[1] = k == 2
        out = multi.step({"attacker": a})
        total += out[1]["attacker"]
    assert rewards["attacker"] == pytest.approx(total, rel=1e-12, abs=0)
    np.testing.assert_array_equal(
        obs["attacker"]["observation"][: -(N * M + 1)], out[0]["attacker"]
    )
    assert infos["attacker"].keys() == out[4]["attacker"].keys()
    for key, value in out[4]["attacker"].items():
        np.testing.assert_array_equal(infos["attacker"][key], value)
    assert obs["attacker"]["action_mask"].tolist() == [1] + [0] * (N * M)


# --- order="increasing": the plan-first picks in increasing order ----------------------------


def make_increasing(rule: str = "error", skip_forced: bool = True, **kwargs) -> SequentialSetEnv:
    kwargs = {"scenario": "ch4-position", "budget": 3, "horizon": 3, **kwargs}
    parallel = sparse_attack_v0.parallel_env(action="multibinary", **kwargs)
    return SequentialSetEnv(
        parallel, illegal_action=rule, skip_forced=skip_forced, order="increasing"
    )


def test_increasing_order_mask_after_picks_and_refused_picks():
    env = make_increasing()  # M = 3, N = 3: pairs 1..9, step-major
    assert env.plan_first and env.increasing and env.action_space("attacker").n == 10
    obs, _ = env.reset(seed=0)
    assert obs["attacker"]["action_mask"].tolist() == [1] * 10
    obs = env.step({"attacker": 5})[0]["attacker"]  # sensor 2 at window step 2
    assert obs["action_mask"].tolist() == [1, 0, 0, 0, 0, 0, 1, 1, 1, 1]
    assert obs["observation"][-10:].tolist() == [0, 0, 0, 0, 1, 0, 0, 0, 0, pytest.approx(2 / 3)]
    obs = env.step({"attacker": 7})[0]["attacker"]
    assert obs["action_mask"].tolist() == [1, 0, 0, 0, 0, 0, 0, 0, 1, 1]
    assert env.inner.sim.k == 0  # nothing played while planning
    with pytest.raises(
        ValueError,
        match=r"action 6 \(sensor 3 at window step 2\) is illegal: order='increasing' picks "
        r"the pairs in increasing order and the last pick is action 7; legal actions are those "
        r"with action_mask\[a\] = 1: \[0, 8, 9\]",
    ):
        env.step({"attacker": 6})
    with pytest.raises(ValueError, match="this pair is already in the plan"):
        env.step({"attacker": 7})
    assert env.action_mask().tolist() == [1, 0, 0, 0, 0, 0, 0, 0, 1, 1]  # refused: no change
    for rule in ("trim", "noop"):  # a pick below the last one stops: the plan {5, 7} plays out
        env = make_increasing(rule)
        env.reset(seed=0)
        env.step({"attacker": 5})
        env.step({"attacker": 7})
        _, _, term, _, info = env.step({"attacker": 2})
        assert term["attacker"] and info["attacker"]["budget_left"] == 1
        assert env.inner.sim.k == 3
    # the last pair leaves no pair above it: stop is forced (played by the env with skip_forced)
    env = make_increasing()
    env.reset(seed=0)
    env.step({"attacker": 2})
    _, _, term, _, info = env.step({"attacker": 9})
    assert term["attacker"] and info["attacker"]["budget_left"] == 1
    slow = make_increasing(skip_forced=False)
    slow.reset(seed=0)
    assert slow.step({"attacker": 9})[0]["attacker"]["action_mask"].tolist() == [1] + [0] * 9
    with pytest.raises(ValueError, match=r"order must be one of \['time', 'plan', 'increasing'\]"):
        sparse_attack_v0.parallel_env(action="sequential", order="increasng")
    with pytest.raises(ValueError, match="order='increasing' applies to action='sequential'"):
        sparse_attack_v0.parallel_env(action="multibinary", order="increasing")


def test_increasing_order_every_attack_set_reachable_with_the_plan_orders_value():
    """M = 3, N = 2, c = 2: each of the 22 sets plays as in "plan" and the bitmask, exactly."""
    kwargs = SMALL
    inc = sparse_attack_v0.parallel_env(
        action="sequential", order="increasing", illegal_action="error", **kwargs
    )
    plan_env = sparse_attack_v0.parallel_env(
        action="sequential", order="plan", illegal_action="error", **kwargs
    )
    plans = _every_small_plan()
    for plan in plans:
        value = play_plan(inc, plan, seed=0)
        assert value == play_plan(plan_env, plan, seed=0)
        assert value == pytest.approx(sum(bitmask_rewards(plan, **kwargs)), rel=1e-12, abs=0)
    assert len(plans) == 22


@pytest.mark.parametrize("dynamics", ["expected", "sampled"])
def test_increasing_order_solver_sets_replayed_return_their_value(dynamics):
    system = mixed_tracking(6)
    bnb = branch_and_bound(system, 4, 5)
    assert bnb.proved_optimal
    for result in (bnb, sfs(system, 4, 5)):
        plan = solver_plan(result, 5)
        kwargs = dict(scenario=system, budget=4, horizon=5, action="sequential", dynamics=dynamics)
        inc = sparse_attack_v0.parallel_env(order="increasing", **kwargs)
        value = play_plan(inc, plan, seed=3)
        assert value == play_plan(sparse_attack_v0.parallel_env(order="plan", **kwargs), plan, 3)
        if dynamics == "expected":
            assert value == pytest.approx(result.value, rel=1e-12)


def test_increasing_order_masked_random_play_never_errors_on_grid_preset():
    env = sparse_attack_v0.parallel_env(
        scenario="grid-ieee14", objective="logdet", action="sequential", order="increasing",
        illegal_action="error",
    )  # fmt: skip
    N, M, c = 6, 34, 6
    rng = np.random.default_rng(5)
    for episode in range(4):
        obs, _ = env.reset(seed=episode)
        picks = []
        while env.agents:
            mask = obs["attacker"]["action_mask"]
            assert mask.shape == (N * M + 1,) and mask[STOP] == 1
            if picks:  # only the pairs above the last pick are open
                assert not mask[1 : picks[-1] + 1].any()
            legal = np.flatnonzero(mask)
            a = int(rng.choice(legal[1:])) if len(legal) > 1 and rng.random() < 0.9 else STOP
            obs, *_ = env.step({"attacker": a})
            picks += [a] if a != STOP else []
        assert picks == sorted(set(picks)) and len(picks) <= c


def test_increasing_order_reference_policy_and_gymnasium_view():
    from gymnasium.utils.env_checker import check_env

    from agents.registry import sparse_reference
    from fdia_env.envs.sequential import PlanOrderPolicy

    kwargs = dict(scenario="ch4-position", budget=2, horizon=3, action="sequential")
    ref = sparse_reference(sparse_attack_v0.parallel_env(order="increasing", **kwargs))
    best = exhaustive("ch4-position", budget=2, horizon=3)
    assert isinstance(ref.policy, PlanOrderPolicy)
    view = gym.make(
        "fdia_env/SparseAttack-v2", order="increasing", illegal_action="error", **kwargs
    )
    check_env(view.unwrapped, skip_render_check=True)
    assert _view_return(view, ref.policy) == pytest.approx(best.value, rel=1e-12)
    parallel_api_test(sparse_attack_v0.parallel_env(order="increasing", **kwargs), num_cycles=30)
    api_test(sparse_attack_v0.env(order="increasing", **kwargs), num_cycles=30)
