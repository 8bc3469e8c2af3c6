"""The sparse attacker's sequential format in the native vector env (vector/sequential.py)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from conftest import assert_infos_equal
from gymnasium.vector import AutoresetMode, SyncVectorEnv

from fdia_env.vector.sequential import SequentialVectorEnv

ID = "fdia_env/SparseAttack-v0"


def make_native(num_envs, env_id=ID, **kwargs):
    """The native vector env (vector_entry_point) of `env_id`, in the sequential format unless
    `kwargs` names another action."""
    kwargs.setdefault("action", "sequential")
    return gym.make_vec(
        env_id, num_envs=num_envs, vectorization_mode="vector_entry_point", **kwargs
    )


def compare_with_sync(kwargs, B=4, steps=30, autoreset=AutoresetMode.NEXT_STEP, stop_p=0.3):
    """Masked random decisions in the native vector env and in SyncVectorEnv of single views.

    Returns the number of episodes that ended and of decisions at which members both committed
    a window step and held theirs (so the test sees members finishing sets at different times).
    """
    native = make_native(B, autoreset_mode=autoreset, **kwargs)
    assert isinstance(native, SequentialVectorEnv) and native.autoreset_mode == autoreset
    sync = SyncVectorEnv(
        [lambda: gym.make(ID, action="sequential", **kwargs) for _ in range(B)],
        autoreset_mode=autoreset,
    )
    assert native.single_observation_space == sync.single_observation_space
    assert native.single_action_space == sync.single_action_space
    obs_n, info_n = native.reset(seed=11)
    obs_s, info_s = sync.reset(seed=11)
    np.testing.assert_allclose(obs_n, obs_s, rtol=1e-6, atol=1e-6)
    assert_infos_equal(info_n, info_s, "reset", atol=1e-15)
    rng = np.random.default_rng(0)
    ended = mixed = 0
    for t in range(steps):
        mask = info_s["action_mask"]
        np.testing.assert_array_equal(native.action_masks(), mask.astype(bool))
        actions = np.array(
            [0 if rng.random() < stop_p else int(rng.choice(np.flatnonzero(m))) for m in mask]
        )
        k_before = info_s["step"].copy()
        obs_n, r_n, te_n, tr_n, info_n = native.step(actions)
        obs_s, r_s, te_s, tr_s, info_s = sync.step(actions)
        np.testing.assert_allclose(obs_n, obs_s, rtol=1e-6, atol=1e-6, err_msg=f"step {t}")
        np.testing.assert_allclose(r_n, r_s, rtol=1e-9, atol=1e-15, err_msg=f"step {t}")
        np.testing.assert_array_equal(te_n, te_s)
        np.testing.assert_array_equal(tr_n, tr_s)
        assert_infos_equal(info_n, info_s, f"step {t}", atol=1e-15)
        moved = info_s["step"] != k_before
        mixed += bool(moved.any() and not moved.all())
        ended += int((te_s | tr_s).sum())
    return ended, mixed


@pytest.mark.parametrize(
    "kwargs",
    [
        {"scenario": "ch4-position", "budget": 3, "horizon": 5},
        {"scenario": "ch4-position", "budget": 2, "horizon": 4, "dynamics": "sampled"},
        {"scenario": "ch4-position", "budget": 3, "horizon": 5, "reward_mode": "shaped"},
        {"scenario": "ch4-position", "budget": 4, "objective": "logdet", "reward_mode": "per_step"},
        {"scenario": "grid-ieee14"},
        {"scenario": "ch4-position", "budget": 3, "horizon": 5, "order": "plan"},
        {
            "scenario": "ch4-position",
            "budget": 2,
            "horizon": 4,
            "dynamics": "sampled",
            "order": "plan",
        },
        {"scenario": "ch4-position", "budget": 4, "reward_mode": "per_step", "order": "plan"},
        {"scenario": "ch4-position", "budget": 3, "horizon": 5, "order": "increasing"},
        {
            "scenario": "ch4-position",
            "budget": 2,
            "horizon": 4,
            "dynamics": "sampled",
            "order": "increasing",
        },
        {"scenario": "grid-ieee14", "budget": 4, "horizon": 3, "order": "increasing"},
        # train.py's dc-ieee14-50 setting: 13 states, so the engine's general update, which
        # steps only the members that commit (the others are held)
        {"scenario": "dc-ieee14-50", "order": "plan", "groups": "state"},
    ],
)
def test_native_vector_env_matches_sync_vector_env_of_single_views(kwargs):
    grid = kwargs["scenario"].startswith(("grid", "dc-"))
    ended, mixed = compare_with_sync(kwargs, B=3 if grid else 4, steps=12 if grid else 30)
    assert ended >= (3 if grid else 4) and mixed >= 3


@pytest.mark.parametrize("autoreset", [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP])
@pytest.mark.parametrize(
    "kwargs",
    [
        {"scenario": "ch4-position", "budget": 3, "horizon": 6, "max_episode_steps": 4},
        {"scenario": "ch4-position", "budget": 3, "horizon": 6, "max_cycles": 3},
        {"scenario": "ch4-position", "budget": 3, "horizon": 6, "max_cycles": 3, "order": "plan"},
        {"scenario": "ch4-position", "budget": 3, "horizon": 6, "order": "increasing"},
    ],
)
def test_truncation_and_autoreset_match_sync(kwargs, autoreset):
    ended, _ = compare_with_sync(kwargs, B=3, steps=16, autoreset=autoreset)
    assert ended >= 3


def test_skip_forced_and_members_finishing_at_different_decisions():
    env = make_native(3, scenario="ch4-position", budget=2, horizon=4, illegal_action="error")
    obs, info = env.reset(seed=0)
    assert obs.shape == (3, 5 + 4) and info["action_mask"].tolist() == [[1, 1, 1, 1]] * 3
    # member 0 picks 2, member 1 stops (window step 1 with nothing), member 2 picks 1
    obs, r, term, _, info = env.step(np.array([2, 0, 1]))
    assert info["step"].tolist() == [0, 1, 0]
    assert info["action_mask"].tolist() == [[1, 1, 0, 1], [1, 1, 1, 1], [1, 0, 1, 1]]
    assert obs[0, -4:].tolist() == [0.0, 1.0, 0.0, 0.5]  # the set {2}, half the budget left
    # member 0 picks 3: its set uses the budget, the env plays the rest of its episode
    obs, r, term, _, info = env.step(np.array([3, 0, 0]))
    assert term.tolist() == [True, False, False] and info["step"].tolist() == [4, 2, 1]
    assert r[0] == pytest.approx(info["phi"][0], rel=1e-12) and r[1] == r[2] == 0.0
    assert info["attacked"].tolist() == [[0, 0, 0], [0, 0, 0], [1, 0, 0]]
    assert info["budget_left"].tolist() == [0, 2, 1]
    # member 0 restarts (NEXT_STEP, its action ignored); member 1 picks 2; member 2 picks 2,
    # which spends its budget: the env plays its last window steps
    obs, r, term, _, info = env.step(np.array([3, 2, 2]))
    assert term.tolist() == [False, False, True] and info["step"].tolist() == [0, 2, 4]
    assert info["budget_left"].tolist() == [2, 2, 0] and obs[0, -4:].tolist() == [0, 0, 0, 1]
    with pytest.raises(ValueError, match=r"member 1 is illegal: sensor 2 is already in"):
        env.step(np.array([0, 2, 0]))
    # the check raised before any change: the same decision with a legal action goes on
    obs, r, term, _, info = env.step(np.array([0, 0, 0]))
    assert info["step"].tolist() == [1, 3, 0] and info["attacked"][1].tolist() == [0, 1, 0]


def test_illegal_actions_and_bad_input():
    def make(rule, **kwargs):
        env = make_native(
            2, scenario="ch4-position", budget=2, horizon=3, illegal_action=rule, **kwargs
        )
        env.reset(seed=0)
        env.step(np.array([1, 2]))  # both pick a sensor: one pair of the budget left
        return env

    with pytest.raises(ValueError, match=r"member 1 is illegal: sensor 2 is already in"):
        make("error").step(np.array([3, 2]))
    for rule in ("trim", "noop"):  # an illegal pick stops: member 1's set {2} is committed
        env = make(rule, autoreset_mode=AutoresetMode.SAME_STEP)
        _, _, term, _, info = env.step(np.array([3, 2]))
        assert term.tolist() == [True, False] and info["final_info"]["step"][0] == 3
        assert info["step"].tolist() == [0, 1]  # member 0 restarted in the same step
        assert info["attacked"][1].tolist() == [0, 1, 0] and info["budget_left"].tolist() == [2, 1]
    with pytest.raises(ValueError, match=r"integers in \[0, 4\); member 1 has 4"):
        env.step(np.array([0, 4]))
    with pytest.raises(ValueError, match="budget must be >= 1"):
        make_native(2, budget=0)
    with pytest.raises(ValueError, match="num_envs"):
        make_native(0)
    with pytest.raises(RuntimeError, match="before reset"):
        make_native(2).step(np.array([0, 0]))


@pytest.mark.parametrize("order", ["time", "plan", "increasing"])
@pytest.mark.parametrize("dynamics", ["expected", "sampled"])
def test_torch_backend_matches_numpy(dynamics, order):
    torch = pytest.importorskip("torch")
    kwargs = dict(order=order, scenario="ch4-position", budget=3, horizon=5, dynamics=dynamics)
    tv = make_native(6, backend="torch", device="cpu", **kwargs)
    nv = make_native(6, **kwargs)
    obs_t, info_t = tv.reset(seed=1)
    obs_n, info_n = nv.reset(seed=1)
    rng = np.random.default_rng(2)
    steps = ended = 0
    for _ in range(20):
        mask = info_n["action_mask"]
        assert np.array_equal(info_t["action_mask"].numpy(), mask)
        a = np.array([0 if rng.random() < 0.3 else rng.choice(np.flatnonzero(m)) for m in mask])
        obs_t, r_t, te_t, _, info_t = tv.step(torch.as_tensor(a))
        obs_n, r_n, te_n, _, info_n = nv.step(a)
        assert isinstance(obs_t, torch.Tensor) and obs_t.dtype == torch.float32
        np.testing.assert_array_equal(te_t.numpy(), te_n)
        np.testing.assert_array_equal(info_t["step"].numpy(), info_n["step"])
        np.testing.assert_array_equal(info_t["attacked"].numpy(), info_n["attacked"])
        if dynamics == "expected":
            np.testing.assert_allclose(r_t.numpy(), r_n, rtol=1e-10, atol=1e-12)
            np.testing.assert_allclose(obs_t.numpy(), obs_n, rtol=1e-5, atol=1e-5)
        else:  # one device generator: the same schedule, other draws (a finite reward)
            assert torch.isfinite(r_t).all()
        steps += 1
        ended += int(te_n.sum())
    assert ended >= 6
    with pytest.raises(TypeError, match=r"torch\.Tensor"):
        tv.step(np.zeros(6, dtype=np.int64))


@pytest.mark.parametrize("backend", ["numpy", "torch"])
def test_torchrl_face_serves_the_sequential_format_with_its_action_mask(backend):
    torch = pytest.importorskip("torch")
    pytest.importorskip("torchrl")
    from torchrl.envs import ActionMask, TransformedEnv
    from torchrl.envs.utils import check_env_specs

    from fdia_env.torchrl import FdiaTorchRLEnv

    def make(rule):
        return FdiaTorchRLEnv(
            ID,
            num_envs=3,
            backend=backend,
            action="sequential",
            scenario="ch4-position",
            budget=2,
            horizon=4,
            illegal_action=rule,
        )

    env = make("trim")  # check_env_specs plays unmasked random actions
    assert isinstance(env.venv, SequentialVectorEnv)
    assert env.observation_spec["action_mask"].shape == (3, 4)
    check_env_specs(env, seed=0)
    env = make("error")
    masked = TransformedEnv(env, ActionMask())  # random actions drawn within the mask
    masked.set_seed(0)
    rollout = masked.rollout(12, break_when_any_done=False)
    assert tuple(rollout.batch_size) == (3, 12)
    mask, action = rollout["action_mask"], rollout["action"]
    assert bool(mask.gather(-1, action.unsqueeze(-1)).all())  # "error": none was illegal
    assert int(rollout["next", "done"].sum()) >= 3  # every member ended at least once
    assert bool(torch.isfinite(rollout["next", "reward"]).all())
    for order in ("plan", "increasing"):
        plan = FdiaTorchRLEnv(
            ID, num_envs=2, backend=backend, action="sequential", order=order,
            scenario="ch4-position", budget=2, horizon=4, illegal_action="error",
        )  # fmt: skip
        assert plan.observation_spec["action_mask"].shape == (2, 4 * 3 + 1)
        masked = TransformedEnv(plan, ActionMask())
        masked.set_seed(0)
        rollout = masked.rollout(8, break_when_any_done=False)
        assert bool(rollout["action_mask"].gather(-1, rollout["action"].unsqueeze(-1)).all())
        assert int(rollout["next", "done"].sum()) >= 2  # a plan ends within c + 1 decisions


@pytest.mark.parametrize("action", ["sequential", "multibinary"])
def test_sb3_ppo_and_a2c_train_on_grid_ieee14_in_the_native_vector_env(action):
    from stable_baselines3 import A2C, PPO

    from fdia_env.vector.sb3 import make_sb3_vec_env

    venv = make_sb3_vec_env(ID, num_envs=8, scenario="grid-ieee14", action=action)
    assert isinstance(venv.venv, SequentialVectorEnv) == (action == "sequential")
    for algo, kwargs in ((PPO, {"n_epochs": 1, "batch_size": 128}), (A2C, {})):
        model = algo("MlpPolicy", venv, n_steps=16, seed=0, device="cpu", **kwargs)
        model.learn(total_timesteps=256)  # float actions of MultiBinary, ints of Discrete
        assert model.num_timesteps >= 256
    if action == "sequential":
        sb3_contrib = pytest.importorskip("sb3_contrib")
        masks = np.stack(venv.env_method("action_masks"))
        assert masks.shape == (8, 35) and masks[:, 0].all()
        model = sb3_contrib.MaskablePPO(
            "MlpPolicy", venv, n_steps=16, batch_size=128, n_epochs=1, seed=0, device="cpu"
        )
        model.learn(total_timesteps=256)
        assert model.num_timesteps >= 256


def test_sparse_attack_v1_defaults_to_the_sequential_format_above_16_sensors():
    from fdia_env import sparse_attack_v0, sparse_attack_v1
    from fdia_env.envs.sequential import SequentialSetEnv

    grid = sparse_attack_v1.parallel_env(scenario="grid-ieee14")  # 34 meters
    assert isinstance(grid, SequentialSetEnv) and grid.action_space("attacker").n == 35
    assert grid.metadata["name"] == "sparse_attack_v1"
    assert sparse_attack_v0.parallel_env(scenario="grid-ieee14").attack.format == "multibinary"
    small = sparse_attack_v1.parallel_env(scenario="ch4-position")  # 3 sensors: the bitmask
    assert small.attack.format == "bitmask" and small.action_space("attacker").n == 8
    # a budget of 0 has no decision to make: v0's format; the old formats stay by name
    assert sparse_attack_v1.parallel_env(scenario="grid-ieee14", budget=0).attack.format == (
        "multibinary"
    )
    multi = sparse_attack_v1.parallel_env(scenario="grid-ieee14", action="multibinary")
    assert multi.attack.format == "multibinary"
    venv = gym.make_vec("fdia_env/SparseAttack-v1", num_envs=2, scenario="grid-ieee14")
    assert isinstance(venv, SequentialVectorEnv) and venv.single_action_space.n == 35
    venv = gym.make_vec("fdia_env/SparseAttack-v1", num_envs=2, vectorization_mode="sync")
    assert venv.single_action_space.n == 8
    with pytest.warns(DeprecationWarning, match="SparseAttack-v0 is out of date"):
        gym.make("fdia_env/SparseAttack-v0")  # Gymnasium's notice for a superseded version


def test_sparse_attack_v2_defaults_to_the_plan_first_order_above_16_sensors():
    from baselines.sparse import sfs
    from fdia_env import sparse_attack_v1, sparse_attack_v2
    from fdia_env.envs.sequential import SequentialSetEnv, play_plan

    grid = sparse_attack_v2.parallel_env(scenario="grid-ieee14")  # 34 meters, N = 6
    assert isinstance(grid, SequentialSetEnv) and grid.order == "plan"
    assert grid.action_space("attacker").n == 6 * 34 + 1
    assert grid.metadata["name"] == grid.inner.metadata["name"] == "sparse_attack_v2"
    # v1's time-major order and the other formats stay by name; the bitmask up to 16 sensors
    assert sparse_attack_v2.parallel_env(scenario="grid-ieee14", order="time").order == "time"
    assert sparse_attack_v1.parallel_env(scenario="grid-ieee14").order == "time"
    multi = sparse_attack_v2.parallel_env(scenario="grid-ieee14", action="multibinary")
    assert multi.attack.format == "multibinary"
    assert sparse_attack_v2.parallel_env(scenario="ch4-position").attack.format == "bitmask"
    assert sparse_attack_v2.parallel_env(scenario="ch4-position", action="sequential").order == (
        "plan"
    )
    with pytest.raises(ValueError, match="order='plan' applies to action='sequential' only"):
        sparse_attack_v2.parallel_env(scenario="ch4-position", order="plan")
    # the same attack set returns the same value in v2's default and in v1's plan order
    best = sfs("grid-ieee14", 3, 4)
    plan = [[j + 1 for k, j in best.attacks if k == step] for step in range(4)]
    kw = {"scenario": "grid-ieee14", "budget": 3, "horizon": 4}
    v2 = play_plan(sparse_attack_v2.parallel_env(**kw), plan)
    v1 = play_plan(sparse_attack_v1.parallel_env(**kw, order="plan"), plan)
    assert v2 == v1 == pytest.approx(best.value, rel=1e-12)
    venv = gym.make_vec("fdia_env/SparseAttack-v2", num_envs=2, scenario="grid-ieee14")
    assert isinstance(venv, SequentialVectorEnv) and venv.single_action_space.n == 6 * 34 + 1
    with pytest.warns(DeprecationWarning, match="SparseAttack-v1 is out of date"):
        gym.make("fdia_env/SparseAttack-v1")


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"agent": np.array([])}, "agent"),  # found by the constructor property test
        ({"action": np.array([1])}, "action"),
        ({"action": "seq"}, "action must be one of .*'sequential'"),
    ],
)
def test_make_vec_of_v1_names_a_bad_agent_or_action(kwargs, name):
    with pytest.raises(ValueError, match=name):
        gym.make_vec(
            "fdia_env/SparseAttack-v1", num_envs=2, vectorization_mode="vector_entry_point",
            **kwargs,
        )  # fmt: skip


@pytest.mark.parametrize("budget", [np.zeros(0), np.array([1, 2]), 2.5, -1])
def test_v1_names_a_bad_budget_on_a_large_grid(budget):
    # an empty array gave numpy's "truth value of an empty array" error (property test)
    from fdia_env import sparse_attack_v1

    with pytest.raises(ValueError, match="budget must be"):
        sparse_attack_v1.parallel_env(scenario="grid-ieee14", budget=budget)


@pytest.mark.parametrize("action", ["bitmask", "sequential"])  # FdiaVectorEnv, SequentialVectorEnv
@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"autoreset_mode": "sometimes"}, "autoreset_mode must be one of"),
        ({"autoreset_mode": AutoresetMode.DISABLED}, "autoreset_mode must be NEXT_STEP or SAME"),
        ({"max_episode_steps": 0}, "max_episode_steps"),
        ({"max_episode_steps": 2.5}, "max_episode_steps"),
    ],
)
def test_both_native_vector_envs_check_their_episode_options_alike(action, kwargs, match):
    with pytest.raises(ValueError, match=match):
        make_native(2, "fdia_env/SparseAttack-v0", action=action, **kwargs)


def test_plan_order_members_plan_then_play_out_their_plans():
    env = make_native(
        3, order="plan", scenario="ch4-position", budget=2, horizon=3, illegal_action="error"
    )
    obs, info = env.reset(seed=0)
    M = 3  # action 1 + k*M + (j - 1): sensor j at window step k + 1
    assert obs.shape == (3, 5 + 3 * M + 1) and info["action_mask"].shape == (3, 3 * M + 1)
    assert info["action_mask"].all()
    # member 0 picks sensor 1 at step 3; member 1 stops (an empty plan: the episode plays out);
    # member 2 picks sensor 2 at step 1
    obs, r, term, _, info = env.step(np.array([1 + 2 * M, 0, 2]))
    assert term.tolist() == [False, True, False] and info["step"].tolist() == [0, 3, 0]
    assert obs[0, -(3 * M + 1) :].tolist() == [0] * 6 + [1, 0, 0, 0.5]
    assert info["action_mask"][0].tolist() == [1] + [1] * 6 + [0, 1, 1]
    with pytest.raises(ValueError, match=r"member 0 is illegal: this pair is already in the plan"):
        env.step(np.array([1 + 2 * M, 0, 0]))
    # member 0 picks sensor 3 at step 3: the budget is used, the plan plays out at once;
    # member 2 stops: its plan plays out
    obs, r, term, _, info = env.step(np.array([3 + 2 * M, 0, 0]))
    assert term.tolist() == [True, False, True] and info["step"].tolist() == [3, 0, 3]
    assert info["attacked"][0].tolist() == [1, 0, 1] and info["attacked"][2].tolist() == [0, 0, 0]
    assert info["budget_left"].tolist() == [0, 2, 1]
    assert r[0] == pytest.approx(info["phi"][0], rel=1e-12)


def test_plan_order_playing_out_is_one_window_step_per_stop_without_skip_forced():
    from fdia_env import sparse_attack_v0
    from fdia_env.envs.sequential import SequentialSetEnv

    parallel = sparse_attack_v0.parallel_env(
        action="multibinary", scenario="ch4-position", budget=2, horizon=3, illegal_action="error"
    )
    env = SequentialSetEnv(parallel, illegal_action="error", skip_forced=False, order="plan")
    vec = SequentialVectorEnv(env, 2)
    vec.reset(seed=0)
    steps = []
    for a in ([4, 2], [0, 0], [0, 0], [0, 0]):
        *_, term, _, info = vec.step(np.array(a))
        steps.append(info["step"].tolist())
        if a == [0, 0]:
            assert info["action_mask"][:, 1:].sum() == 0  # playing out: stop only
    assert steps == [[0, 0], [1, 1], [2, 2], [3, 3]] and term.all()
    vec.reset(seed=0)
    vec.step(np.array([4, 2]))
    vec.step(np.array([0, 0]))
    with pytest.raises(ValueError, match=r"member 0 is illegal: the plan is committed and plays"):
        vec.step(np.array([1, 0]))


def test_increasing_order_masks_and_refused_picks_member_by_member():
    """Each member's mask closes the pairs up to its own last pick; a pick below it is refused."""

    def make(rule):
        env = make_native(
            3, scenario="ch4-position", budget=3, horizon=3, order="increasing", illegal_action=rule
        )
        env.reset(seed=0)
        env.step(np.array([5, 2, 9]))  # member 2 picks the last pair: its plan plays out
        return env

    env = make("error")
    masks = env.action_masks()
    assert masks[0].tolist() == [True] + [False] * 5 + [True] * 4
    assert masks[1].tolist() == [True, False, False] + [True] * 7
    assert masks[2].tolist() == [True] + [False] * 9  # its plan played out (restarts next)
    with pytest.raises(
        ValueError,
        match=r"action 4 \(sensor 1 at window step 2\) of member 0 is illegal: order='increasing' "
        r"picks the pairs in increasing order and the last pick is action 5",
    ):
        env.step(np.array([4, 3, 0]))
    env = make("trim")  # the refused pick stops: member 0's plan {5} plays out, member 1 goes on
    _, _, term, _, info = env.step(np.array([4, 3, 0]))
    assert term.tolist() == [True, False, False] and info["budget_left"][0] == 2
    masks = env.action_masks()
    assert masks[1].tolist() == [True, False, False, False] + [True] * 6
    assert masks[2].tolist() == [True] * 10  # restarted (NEXT_STEP): a fresh plan


def test_held_members_keep_their_exact_state_while_another_member_plays_its_plan():
    """The engine steps every member; the held ones are put back bit for bit after the run."""
    env = make_native(
        3,
        "fdia_env/SparseAttack-v2",
        scenario="grid-ieee14",
        budget=3,
        horizon=3,
        order="increasing",
    )
    env.reset(seed=0)
    env.step(np.array([1, 40, 70]))  # every member picks a pair; nobody plays
    sim, attack = env.inner.sim, env.attack

    def state():
        return [xp.copy() for xp in (sim.P, sim.M, sim.k, sim.phi, attack.b_remaining)]

    before = state()
    masks_before = env.action_masks()
    obs, reward, term, _, info = env.step(np.array([0, 41, 75]))  # member 0 plays {1} out
    after = state()
    assert term.tolist() == [True, False, False] and info["step"].tolist() == [3, 0, 0]
    assert reward[0] != 0.0 and reward[1:].tolist() == [0.0, 0.0]
    assert info["budget_left"].tolist() == [2, 3, 3]  # member 0 spent one pair, once
    for old, new in zip(before, after, strict=True):  # members 1 and 2: not a bit moved
        np.testing.assert_array_equal(new[1:], old[1:])
    assert not np.array_equal(after[0][0], before[0][0])  # member 0's covariance did move
    np.testing.assert_array_equal(obs[1:, :14], env.inner._observe("attacker")[1:, :14])
    # the masks follow the new picks of members 1 and 2 (what was computed before is forgotten)
    masks = env.action_masks()
    assert masks_before[1, 41] and not masks[1, 41] and masks[1, 42]  # action j: column j
    assert masks_before[2, 74] and not masks[2, 74] and not masks[2, 75] and masks[2, 76]
    np.testing.assert_array_equal(masks, info["action_mask"].astype(bool))


def test_action_masks_are_the_callers_own_array():
    env = make_native(2, scenario="ch4-position", budget=2, horizon=3, order="increasing")
    _, info = env.reset(seed=0)
    masks = env.action_masks()
    assert masks.all()
    masks[:] = False  # the caller's array: the env's masks do not change with it
    assert env.action_masks().all() and info["action_mask"].all()
    _, _, _, _, info = env.step(np.array([2, 0]))
    np.testing.assert_array_equal(env.action_masks(), info["action_mask"].astype(bool))
    masks = env.action_masks()
    assert masks[0].tolist() == [True, False, False] + [True] * 7  # pairs above action 2
    assert masks[1].tolist() == [True] + [False] * 9  # its empty plan played out
