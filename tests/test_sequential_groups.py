"""Group actions of the sequential format's plan-first orders (``groups="state"``).

A group action adds, in one decision, every pair of one window step whose sensor sees one state;
the env's dynamics and rewards are unchanged, so a plan built with groups returns exactly what
the same plan returns built pair by pair.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from pettingzoo.test import api_test, parallel_api_test

from fdia_env import sparse_attack_v0
from fdia_env.envs.sequential import STOP, SequentialSetEnv, play_plan, state_groups

OPTIMUM = 0.00017685454306509148  # dc-ieee14-50: branch and bound's proved optimum


def make(order: str = "increasing", rule: str = "error", **kwargs) -> SequentialSetEnv:
    return sparse_attack_v0.parallel_env(
        action="sequential", order=order, groups="state", illegal_action=rule, **kwargs
    )


def plan_of(obs: np.ndarray, N: int, M: int) -> list[list[int]]:
    """The plan (1-based sensors per window step) in a plan-first observation."""
    bits = obs[-1 - N * M : -1].reshape(N, M)
    return [(np.flatnonzero(row) + 1).tolist() for row in bits]


def test_a_group_is_every_sensor_that_sees_the_state():
    env = make(scenario="dc-ieee14-50")
    N, M, n, S = 6, 50, 13, 300
    assert env.action_space("attacker").n == S + 1 + N * n
    groups = state_groups(env.system, N)
    assert groups.shape == (N * n, S)
    # bus 8 (state 7, 1-based; a leaf on branch 7-8): its injection, bus 7's, both flow ends
    assert np.flatnonzero(groups[5 * n + 6]).tolist() == [5 * M + i for i in (6, 7, 27, 47)]
    assert np.flatnonzero(groups[5 * n + 12]).tolist() == [5 * M + i for i in (8, 12, 13, 30, 33)]
    # the RTU preset: a sensor of several rows sees a state if any of its rows does
    rtu = make(scenario="grid-ieee14-rtu")
    system = rtu.system
    sees = np.zeros((system.M, system.n), dtype=bool)
    for i, sensor in enumerate(system.sensors):
        sees[i] = (sensor.H != 0).any(axis=0)
    assert np.array_equal(state_groups(system, 2), np.kron(np.eye(2, dtype=bool), sees.T))


def test_the_optimum_by_a_group_and_a_pair_returns_the_proved_value():
    env = make(scenario="dc-ieee14-50")
    S, n = 300, 13
    obs, _ = env.reset(seed=0)
    mask = obs["attacker"]["action_mask"]
    # at the start only groups of at most c = 5 sensors are open: bus 8's (4) and bus 14's (5)
    open_groups = np.flatnonzero(mask[S + 1 :])
    assert open_groups.tolist() == [k * n + s for k in range(6) for s in (6, 12)]
    obs, rewards, *_ = env.step({"attacker": S + 1 + 5 * n + 6})
    assert rewards["attacker"] == 0.0 and env.agents  # a group pays nothing, as a pick
    mask = obs["attacker"]["action_mask"]
    assert not mask[S + 1 :].any()  # budget left 1: no group adds a single new pair of 1
    assert plan_of(obs["attacker"]["observation"], 6, 50)[5] == [7, 8, 28, 48]
    assert obs["attacker"]["observation"][-1] == pytest.approx(1 / 5)
    _, rewards, terms, *_ = env.step({"attacker": 1 + 5 * 50 + 13})  # the budget: played out
    assert terms["attacker"] and env.agents == []
    assert rewards["attacker"] == pytest.approx(OPTIMUM, rel=1e-10)
    pairs = make(scenario="dc-ieee14-50")
    assert play_plan(pairs, [[]] * 5 + [[7, 8, 14, 28, 48]], seed=0) == rewards["attacker"]


@pytest.mark.parametrize("order", ["plan", "increasing"])
@pytest.mark.parametrize("dynamics", ["expected", "sampled"])
def test_masked_random_plans_with_groups_return_the_pairs_value(order, dynamics):
    kwargs = dict(scenario="grid-ieee14", budget=6, horizon=3, dynamics=dynamics)
    env = make(order, **kwargs)
    plain = sparse_attack_v0.parallel_env(
        action="sequential", order=order, illegal_action="error", **kwargs
    )
    N, M = 3, 34
    S = N * M
    groups = state_groups(env.system, N)
    rng = np.random.default_rng(1)
    grouped = 0
    for episode in range(6):
        obs, _ = env.reset(seed=episode)
        total, picks, pairs = 0.0, [], np.zeros(S, dtype=bool)
        while env.agents:
            mask = obs["attacker"]["action_mask"]
            assert mask[STOP] == 1
            a = _group_first(rng, mask, S)
            obs, rewards, *_ = env.step({"attacker": a})
            total += rewards["attacker"]
            if a > S:
                pairs |= groups[a - S - 1]
            elif a != STOP:
                pairs[a - 1] = True
            picks.append(a)
        group_picks = [p for p in picks if p > S]
        assert group_picks == sorted(set(group_picks))  # groups in increasing order
        grouped += len(group_picks)
        assert pairs.sum() <= 6
        plan = [(np.flatnonzero(row) + 1).tolist() for row in pairs.reshape(N, M)]
        assert total == pytest.approx(play_plan(plain, plan, seed=episode), rel=1e-12, abs=0)
    assert grouped >= 3


def test_group_masks_and_illegal_groups():
    S = 300
    env = make(scenario="dc-ieee14-50")
    env.reset(seed=0)
    with pytest.raises(
        ValueError,
        match=r"action 301 \(the sensors that see state 1 at window "
        r"step 1\) is illegal: its 13 new pairs exceed the budget left \(5\)",
    ):
        env.step({"attacker": S + 1})
    env.step({"attacker": S + 1 + 6})  # bus 8 at window step 1
    with pytest.raises(
        ValueError, match=f"groups are picked in increasing order and the last group is {S + 1 + 6}"
    ):
        env.step({"attacker": S + 1 + 6})
    # a group after a pair: increasing order closes the pairs up to the last pick, not the
    # groups; after the last pair of the window a group is still open, so the env waits
    env.reset(seed=0)
    obs, *_ = env.step({"attacker": S})  # sensor 50 at window step 6, the last pair
    mask = obs["attacker"]["action_mask"]
    assert not mask[1 : S + 1].any() and env.agents
    assert np.flatnonzero(mask[S + 1 :]).tolist() == [k * 13 + 6 for k in range(6)]
    _, rewards, terms, *_ = env.step({"attacker": S + 1 + 5 * 13 + 6})  # bus 8: 5 pairs, played
    assert terms["attacker"] and env.agents == []
    plan = [[]] * 5 + [[7, 8, 28, 48, 50]]
    assert rewards["attacker"] == play_plan(make(scenario="dc-ieee14-50"), plan, seed=0)
    trim = make(scenario="dc-ieee14-50", rule="trim")
    trim.reset(seed=0)
    _, rewards, terms, *_ = trim.step({"attacker": S + 1})  # "trim": an illegal group stops
    assert terms["attacker"] and rewards["attacker"] > 0  # the empty plan played out
    # overlapping groups: only the pairs not yet in the plan count against the budget
    env = make(scenario="grid-ieee14-rtu", budget=6, horizon=1)
    env.reset(seed=0)
    groups = state_groups(env.system, 1)
    g7 = np.flatnonzero(groups[6]).tolist()  # bus 8: sensors 7 and 8 (0-based 6, 7)
    obs, *_ = env.step({"attacker": 14 + 1 + 5})  # bus 7: sensors 3, 6, 7, 8 (0-based)
    assert obs["attacker"]["observation"][-1] == pytest.approx(2 / 6)
    mask = obs["attacker"]["action_mask"]
    assert set(g7) <= set(np.flatnonzero(groups[5]))  # bus 8's all in: no new pair
    assert mask[14 + 1 + 6] == 0
    with pytest.raises(ValueError, match="every pair of the group is already in the plan"):
        env.step({"attacker": 14 + 1 + 6})


def test_bad_groups_name_the_parameter():
    with pytest.raises(ValueError, match=r"groups must be one of \['state'\], got 'bus'"):
        sparse_attack_v0.parallel_env(action="sequential", order="plan", groups="bus")
    with pytest.raises(ValueError, match="groups='state' applies to the plan-first orders"):
        sparse_attack_v0.parallel_env(action="sequential", order="time", groups="state")
    with pytest.raises(ValueError, match="groups='state' applies to the plan-first orders"):
        sparse_attack_v0.parallel_env(action="bitmask", groups="state")
    with pytest.raises(ValueError, match="groups must be one of"):
        gym.make("fdia_env/SparseAttack-v2", scenario="grid-ieee14", groups=1)


def test_conformance_with_groups():
    from gymnasium.utils.env_checker import check_env

    kwargs = dict(scenario="ch4-position", budget=2, horizon=3, action="sequential",
                  order="increasing", groups="state")  # fmt: skip
    parallel_api_test(sparse_attack_v0.parallel_env(**kwargs), num_cycles=30)
    api_test(sparse_attack_v0.env(**kwargs), num_cycles=30)
    view = gym.make("fdia_env/SparseAttack-v2", **kwargs)  # check_env plays unmasked actions
    check_env(view.unwrapped, skip_render_check=True)
    parallel = sparse_attack_v0.parallel_env(**kwargs)
    N, M, n = 3, parallel.M, parallel.system.n
    assert view.action_space.n == N * M + 1 + N * n
    view.reset(seed=0)
    assert view.unwrapped.action_masks().shape == (N * M + 1 + N * n,)


def _group_first(rng: np.random.Generator, mask: np.ndarray, S: int) -> int:
    """Masked random play that takes a group half the time one is open, stops 20 % of the time."""
    legal = np.flatnonzero(mask)[1:]
    if legal.size and legal[-1] > S and rng.random() < 0.5:
        legal = legal[legal > S]
    return int(rng.choice(legal)) if legal.size and rng.random() < 0.8 else STOP


@pytest.mark.parametrize("order", ["plan", "increasing"])
def test_native_vector_env_with_groups_matches_sync_and_torch(order):
    from gymnasium.vector import SyncVectorEnv

    torch = pytest.importorskip("torch")
    kwargs = dict(scenario="grid-ieee14", budget=6, horizon=3, action="sequential", order=order,
                  groups="state", illegal_action="error")  # fmt: skip
    ID, B, S = "fdia_env/SparseAttack-v2", 3, 3 * 34
    native = gym.make_vec(ID, num_envs=B, vectorization_mode="vector_entry_point", **kwargs)
    on_torch = gym.make_vec(
        ID, num_envs=B, vectorization_mode="vector_entry_point", backend="torch", **kwargs
    )
    sync = SyncVectorEnv([lambda: gym.make(ID, **kwargs) for _ in range(B)])
    assert native.single_action_space == sync.single_action_space == gym.spaces.Discrete(S + 40)
    obs_n, info_n = native.reset(seed=3)
    obs_s, info_s = sync.reset(seed=3)
    obs_t, info_t = on_torch.reset(seed=3)
    rng = np.random.default_rng(0)
    ended = groups = 0
    for t in range(40):
        mask = info_s["action_mask"]
        np.testing.assert_array_equal(info_n["action_mask"], mask)
        np.testing.assert_array_equal(info_t["action_mask"].numpy(), mask)
        actions = np.array([_group_first(rng, m, S) for m in mask])
        groups += int((actions > S).sum())
        obs_n, r_n, te_n, tr_n, info_n = native.step(actions)
        obs_s, r_s, te_s, tr_s, info_s = sync.step(actions)
        obs_t, r_t, te_t, _, info_t = on_torch.step(torch.as_tensor(actions))
        np.testing.assert_array_equal(obs_n, obs_s, err_msg=f"step {t}")
        np.testing.assert_array_equal(r_n, r_s, err_msg=f"step {t}")
        np.testing.assert_array_equal(te_n, te_s)
        np.testing.assert_array_equal(tr_n, tr_s)
        np.testing.assert_allclose(r_t.numpy(), r_n, rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(obs_t.numpy(), obs_n, rtol=1e-5, atol=1e-5)
        np.testing.assert_array_equal(te_t.numpy(), te_n)
        ended += int(te_s.sum())
    assert ended >= 6 and groups >= 6
    native.reset(seed=0)
    first = S + 1  # state 1 at window step 1: 9 sensors, over the budget of 6
    with pytest.raises(ValueError, match=f"action {first} .* of member 1 is illegal: its 9 new"):
        native.step(np.array([0, first, 0]))


def test_torchrl_face_masks_the_groups():
    pytest.importorskip("torchrl")
    from torchrl.envs import ActionMask, TransformedEnv

    from fdia_env.torchrl import FdiaTorchRLEnv

    env = FdiaTorchRLEnv(
        "fdia_env/SparseAttack-v2", num_envs=2, action="sequential", order="plan",
        groups="state", scenario="grid-ieee14-rtu", budget=4, horizon=2, illegal_action="error",
    )  # fmt: skip
    S, G = 2 * 14, 2 * 13
    assert env.observation_spec["action_mask"].shape == (2, S + 1 + G)
    masked = TransformedEnv(env, ActionMask())  # random actions within the mask, groups too
    masked.set_seed(0)
    rollout = masked.rollout(30, break_when_any_done=False)
    assert bool(rollout["action_mask"].gather(-1, rollout["action"].unsqueeze(-1)).all())
    assert int((rollout["action"] > S).sum()) >= 3  # groups were played
    assert int(rollout["next", "done"].sum()) >= 4
