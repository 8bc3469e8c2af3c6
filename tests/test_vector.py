"""Native vector envs: identical to B single envs, Gymnasium autoreset, the SB3 adapter."""

import gymnasium as gym
import numpy as np
import pytest
from conftest import assert_infos_equal
from gymnasium.vector import AutoresetMode, SyncVectorEnv
from sb3_contrib import MaskablePPO
from stable_baselines3 import PPO
from stable_baselines3.common.vec_env import DummyVecEnv, VecCheckNan

from fdia_env import LinearSystem, Sensor
from fdia_env.envs.opponents import FixedMix
from fdia_env.vector import FdiaVectorEnv
from fdia_env.vector.sb3 import SB3VecEnv, make_sb3_vec_env

THREE_STATE = LinearSystem(
    F=np.array([[1.0, 1.0, 0.5], [0.0, 1.0, 1.0], [0.0, 0.0, 0.9]]),
    Q=0.01 * np.eye(3),
    sensors=(Sensor(H=[[1.0, 0.0, 0.0]], R=[[0.2]]), Sensor(H=[[0.0, 1.0, 1.0]], R=[[0.5]])),
    name="three-state",
)

CASES = {
    "sparse-expected": ("fdia_env/SparseAttack-v0", {}),
    "sparse-sampled": ("fdia_env/SparseAttack-v0", {"dynamics": "sampled"}),
    "sparse-shaped-3state": (
        "fdia_env/SparseAttack-v0",
        {"scenario": THREE_STATE, "budget": 3, "horizon": 4, "reward_mode": "shaped"},
    ),
    "sparse-warmup-sampled": ("fdia_env/SparseAttack-v0", {"warmup": 3, "dynamics": "sampled"}),
    "covariance-pv": (
        "fdia_env/CovarianceAttack-v0",
        {"scenario": "ch2-pv-2", "horizon": 3, "reward_mode": "per_step"},
    ),
    "covariance-budget-sampled": (
        "fdia_env/CovarianceAttack-v0",
        {"horizon": 4, "power_mode": "budget", "dynamics": "sampled", "reward_mode": "per_step"},
    ),
    "game-attacker": ("fdia_env/SensorGameAttacker-v0", {"rounds": 3}),
    "game-defender-sampled": ("fdia_env/SensorGameDefender-v0", {"dynamics": "sampled"}),
    "detection-defender-static": ("fdia_env/DetectionDefender-v0", {"horizon": 2}),
    "detection-defender-sampled-bayes": (
        "fdia_env/DetectionDefender-v0",
        {"dynamics": "sampled", "criterion": "bayes_cost", "horizon": 3},
    ),
    "detection-attacker-tracking-sampled": (
        "fdia_env/DetectionAttacker-v0",
        {
            "scenario": "ch3-tracking",
            "warmup": 3,
            "dynamics": "sampled",
            "horizon": 2,
            "on_detect": "incorporate",
            "statistic": "chi2",
        },
    ),
    "detection-defender-tracking": (
        "fdia_env/DetectionDefender-v0",
        {"scenario": "ch3-tracking", "warmup": "steady"},
    ),
}


def opponent_for(env_id):
    if "SensorGame" in env_id:  # deterministic, so B separate copies and one batch agree
        return {"opponent": FixedMix([0, 0, 0, 0, 0, 1.0, 0])}
    return {}


def random_actions(space, rng, mask=None):
    if isinstance(space, gym.spaces.Discrete):
        if mask is None:
            return rng.integers(0, space.n, size=len(mask) if mask is not None else None)
        return np.array([rng.choice(np.flatnonzero(m)) for m in mask])
    return rng.uniform(-1, 1, size=space.shape).astype(np.float32)


def compare_with_sync(
    env_id, kwargs, B=5, steps=14, autoreset=AutoresetMode.NEXT_STEP, exact=True, native=None
):
    """The native vector env against SyncVectorEnv of the single env (bit for bit if exact).

    Every numpy member equals its single env bit for bit (the single env is the engine's batch
    of one and every per-member operation is independent of B), hence ``exact`` by default.
    """
    native = native or gym.make_vec(
        env_id,
        num_envs=B,
        vectorization_mode="vector_entry_point",
        autoreset_mode=autoreset,
        **kwargs,
    )
    assert isinstance(native, FdiaVectorEnv) and native.autoreset_mode == autoreset
    sync = SyncVectorEnv(
        [lambda: gym.make(env_id, **kwargs) for _ in range(B)], autoreset_mode=autoreset
    )
    obs_n, info_n = native.reset(seed=11)
    obs_s, info_s = sync.reset(seed=11)
    if exact:
        np.testing.assert_array_equal(obs_n, obs_s)
        np.testing.assert_array_equal(info_n["phi"], info_s["phi"])
    np.testing.assert_allclose(obs_n, obs_s, rtol=1e-6, atol=1e-7)
    assert_infos_equal(info_n, info_s, "reset")
    rng = np.random.default_rng(0)
    single = native.single_action_space
    ended = 0
    for t in range(steps):  # several episodes, including the autoreset steps
        if isinstance(single, gym.spaces.Discrete):
            mask = info_s.get("action_mask")
            actions = np.array(
                [
                    rng.choice(np.flatnonzero(m)) if mask is not None else rng.integers(single.n)
                    for m in (mask if mask is not None else [None] * B)
                ]
            )
        else:
            actions = rng.uniform(-1, 1, size=(B, *single.shape)).astype(np.float32)
        obs_n, r_n, te_n, tr_n, info_n = native.step(actions)
        obs_s, r_s, te_s, tr_s, info_s = sync.step(actions)
        if exact:
            np.testing.assert_array_equal(obs_n, obs_s, err_msg=f"step {t}")
            np.testing.assert_array_equal(r_n, r_s, err_msg=f"step {t}")
            np.testing.assert_array_equal(info_n["phi"], info_s["phi"], err_msg=f"step {t}")
        np.testing.assert_allclose(obs_n, obs_s, rtol=1e-6, atol=1e-6)
        np.testing.assert_allclose(r_n, r_s, rtol=1e-9, atol=1e-12)
        np.testing.assert_array_equal(te_n, te_s)
        np.testing.assert_array_equal(tr_n, tr_s)
        assert_infos_equal(info_n, info_s, f"step {t}")
        ended += int((te_s | tr_s).sum())
    assert ended >= B  # every member went through at least one autoreset
    return native


@pytest.mark.parametrize("case", sorted(CASES))
def test_vector_env_equals_sync_vector_env_of_single_envs(case):
    env_id, kwargs = CASES[case]
    compare_with_sync(env_id, {**kwargs, **opponent_for(env_id)})


@pytest.mark.parametrize(
    "env_id", ["fdia_env/SensorGameAttacker-v0", "fdia_env/SensorGameDefender-v0"]
)
@pytest.mark.parametrize("dynamics", ["expected", "sampled"])
def test_sensor_game_default_random_opponent_replays_each_member(env_id, dynamics):
    # the uniform FixedMix opponent draws from one generator per member, seeded as the single env
    compare_with_sync(env_id, {"dynamics": dynamics, "rounds": 2})


@pytest.mark.parametrize("autoreset", [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP])
@pytest.mark.parametrize(
    "env_id, kwargs",
    [
        ("fdia_env/SparseAttack-v0", {"max_episode_steps": 4}),  # truncates before N = 6
        ("fdia_env/SparseAttack-v0", {"max_episode_steps": 6}),  # truncated and terminated
        ("fdia_env/CovarianceAttack-v0", {"horizon": 5, "max_episode_steps": 3}),
        ("fdia_env/SensorGameAttacker-v0", {"rounds": 4, "max_episode_steps": 2}),
        ("fdia_env/SparseAttack-v0", {"max_cycles": 3, "horizon": 6}),  # the env's own limit
    ],
)
def test_vector_env_truncation_and_infos_match_sync(env_id, kwargs, autoreset):
    compare_with_sync(env_id, kwargs, B=4, steps=13, autoreset=autoreset)


def test_same_step_autoreset_reports_the_final_observation():
    kwargs = {"num_envs": 3, "vectorization_mode": "vector_entry_point"}
    nxt = gym.make_vec("fdia_env/SparseAttack-v0", **kwargs)
    same = gym.make_vec(
        "fdia_env/SparseAttack-v0", autoreset_mode=AutoresetMode.SAME_STEP, **kwargs
    )
    nxt.reset(seed=0)
    first, _ = same.reset(seed=0)
    actions = np.array([1, 2, 4])
    for _ in range(5):
        nxt.step(actions)
        same.step(actions)
    last_n, r_n, te_n, _, _ = nxt.step(actions)
    obs_s, r_s, te_s, _, info = same.step(actions)
    assert te_n.all() and te_s.all()
    np.testing.assert_array_equal(r_n, r_s)
    assert info["final_obs"].dtype == object  # one entry per member, as SyncVectorEnv
    np.testing.assert_array_equal(np.stack(info["final_obs"]), last_n)
    assert info["_final_obs"].all() and info["_final_info"].all()
    np.testing.assert_array_equal(info["final_info"]["step"], [6, 6, 6])
    np.testing.assert_array_equal(obs_s, first)  # already reset


def test_sb3_adapter_passes_checks_and_trains():
    venv = make_sb3_vec_env("fdia_env/SparseAttack-v0", num_envs=8)
    checked = VecCheckNan(venv, raise_exception=True)
    checked.seed(5)
    obs = checked.reset()
    assert obs.shape == (8, 5) and obs.dtype == np.float32
    rng = np.random.default_rng(0)
    for t in range(12):
        masks = np.stack(venv.env_method("action_masks"))
        actions = np.array([rng.choice(np.flatnonzero(m)) for m in masks])
        obs, rewards, dones, infos = checked.step(actions)
        assert rewards.shape == (8,) and len(infos) == 8
        if t == 5:
            assert dones.all() and all("terminal_observation" in i for i in infos)
            assert all(i["terminal_observation"][0] == 0.0 for i in infos)  # no steps left
    PPO("MlpPolicy", venv, n_steps=32, batch_size=64, seed=0).learn(256)
    MaskablePPO("MlpPolicy", venv, n_steps=32, batch_size=64, seed=0).learn(256)
    box = make_sb3_vec_env("fdia_env/CovarianceAttack-v0", num_envs=4)
    PPO("MlpPolicy", box, n_steps=32, batch_size=64, seed=0).learn(128)


@pytest.mark.parametrize(
    "kwargs",
    [
        {"dynamics": "expected"},
        {"dynamics": "sampled", "max_episode_steps": 4},  # TimeLimit.truncated set
        {"action": "sequential", "order": "plan"},
    ],
)
def test_sb3_adapter_infos_are_dummy_vec_envs_of_single_envs(kwargs):
    """Each env's info (the step's, the final step's at an end) and reset_infos as DummyVecEnv."""
    native = make_sb3_vec_env("fdia_env/SparseAttack-v0", num_envs=4, **kwargs)
    dummy = DummyVecEnv([lambda: gym.make("fdia_env/SparseAttack-v0", **kwargs) for _ in range(4)])
    for venv in (native, dummy):
        venv.seed(3)
    np.testing.assert_array_equal(native.reset(), dummy.reset())
    rng = np.random.default_rng(1)
    ended, cut = 0, False
    for _ in range(20):
        masks = np.stack(native.env_method("action_masks"))
        actions = np.array([rng.choice(np.flatnonzero(m)) for m in masks])
        got, want = native.step(actions), dummy.step(actions)
        for a, b in zip(got[:3], want[:3], strict=True):
            np.testing.assert_array_equal(a, b)
        for mine, theirs in ((got[3], want[3]), (native.reset_infos, dummy.reset_infos)):
            for i, j in zip(mine, theirs, strict=True):
                assert i.keys() == j.keys()
                for key in i:
                    np.testing.assert_array_equal(i[key], j[key], err_msg=key)
        ended += int(got[2].sum())
        cut = cut or any(i["TimeLimit.truncated"] for i in got[3])
    assert ended >= 8  # two episodes each: the final step's info and the reset's were compared
    assert cut == ("max_episode_steps" in kwargs)


def test_sb3_seeds_reproduce_sampled_rollouts():
    def run():
        venv = make_sb3_vec_env("fdia_env/SparseAttack-v0", num_envs=4, dynamics="sampled")
        venv.seed(9)
        out = [venv.reset()]
        for _ in range(8):
            out.append(venv.step(np.array([1, 0, 3, 7]))[0])
        return np.concatenate(out)

    np.testing.assert_array_equal(run(), run())


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"num_envs": 0}, "num_envs must be >= 1"),
        ({"num_envs": 2, "autoreset_mode": AutoresetMode.DISABLED}, "NEXT_STEP or SAME_STEP"),
        ({"num_envs": 2, "render_mode": "ansi"}, "render_mode is not supported"),
    ],
)
def test_bad_vector_arguments_raise(kwargs, match):
    with pytest.raises(ValueError, match=match):
        gym.make_vec("fdia_env/SparseAttack-v0", vectorization_mode="vector_entry_point", **kwargs)


def test_vector_step_before_reset_and_bad_actions_raise():
    venv = gym.make_vec(
        "fdia_env/SparseAttack-v0", num_envs=2, vectorization_mode="vector_entry_point"
    )
    with pytest.raises(RuntimeError, match="before reset"):
        venv.step(np.array([0, 0]))
    venv.reset(seed=0)
    with pytest.raises(ValueError, match=r"integers in \[0, 8\)"):
        venv.step(np.array([0, 9]))
    cov = gym.make_vec(
        "fdia_env/CovarianceAttack-v0", num_envs=2, vectorization_mode="vector_entry_point"
    )
    cov.reset(seed=0)
    with pytest.raises(ValueError, match="finite"):
        cov.step(np.full((2, 3), np.nan, dtype=np.float32))
    with pytest.raises(ValueError, match="SAME_STEP"):
        SB3VecEnv(venv)


@pytest.mark.parametrize(
    "kwargs",
    [
        {},
        {"objective": "logdet", "reward_mode": "shaped", "budget": 2},
        {"scenario": "ch2-pv-2", "budget": 1, "horizon": 3, "warmup": 2},
    ],
)
@pytest.mark.parametrize("autoreset", [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP])
def test_members_sharing_histories_equal_the_single_env_bit_for_bit(kwargs, autoreset):
    # 2-state expected dynamics: the members are nodes of the history table, each node computed
    # by the single env's own kernel, so observations, rewards and Φ are the single env's exactly
    native = compare_with_sync(
        "fdia_env/SparseAttack-v0", kwargs, B=16, steps=16, autoreset=autoreset, exact=True
    )
    assert native.sim.shares_histories
    table = native.sim._history
    assert 1 < table.size < 16 * 16  # shared: fewer nodes than member-steps


def test_history_table_full_falls_back_to_the_closed_form():
    # a table that holds only the root and a few children: the engine leaves it at the step
    # that would overflow it and goes on with the closed form on every member: the same
    # kernel on component arrays, so still bit for bit
    native = gym.make_vec(
        "fdia_env/SparseAttack-v0", num_envs=16, vectorization_mode="vector_entry_point"
    )
    native.reset(seed=11)
    native.sim._history.max_nodes = 4
    compare_with_sync("fdia_env/SparseAttack-v0", {}, B=16, steps=16, native=native)
    assert not native.sim.shares_histories
    assert native.sim._history.size <= 4


def test_history_table_nodes_are_the_single_env_kernel():
    # every node: the covariance, features and Φ the single env's float kernel gives for the
    # node's history, bit for bit
    import math

    from fdia_env.envs.history import HistoryTable
    from fdia_env.kalman import small

    rng = np.random.default_rng(5)
    F, q = (1.0, 0.7, -0.2, 0.9), (0.3, 0.05, 0.2)
    start = (1.5, 0.4, 0.8)
    j = [tuple(float(v) for v in (x * x, x * y, y * y)) for x, y in rng.normal(size=(8, 2))]
    j[0] = (0.0, 0.0, 0.0)
    for objective in ("trace", "logdet"):
        table = HistoryTable(start, F, q, j, objective)
        node = np.zeros(50, dtype=np.int32)
        p = [start] * 50
        for _ in range(4):
            used = rng.integers(0, 8, size=50)
            node = table.step(node, used)
            p = [small.info_update2(small.predict2(p[i], F, q), j[used[i]]) for i in range(50)]
            for i in range(50):
                assert tuple(table.comps[:, node[i]]) == p[i]
                assert list(table.feats64[:, node[i]]) == small.shape_features2(p[i], start)
                want = small.trace2(p[i]) if objective == "trace" else small.logdet2(p[i])
                assert table.phi[node[i]] == want and not math.isnan(want)
        assert table.size < 1 + 50 * 4
        assert table.feats.dtype == np.float32


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_closed_form_2x2_update_is_the_float_kernel_and_the_generic_update(seed):
    # the engine's 2-state update on (3, B) components: each member is the single env's float
    # kernel bit for bit (whatever B), and equals (P_pred⁻¹ + J)⁻¹ by inverses to round-off,
    # over random SPD covariances, PSD information sums (J = 0 included), F with F[1,0] != 0
    from fdia_env.envs.engine import update2
    from fdia_env.kalman import information_update, predict_cov, small

    rng = np.random.default_rng(seed)
    B = 200
    L = rng.normal(size=(B, 2, 2))
    P = L @ L.transpose(0, 2, 1) + 0.1 * np.eye(2)
    G = rng.normal(size=(B, 2, 2)) * (rng.random((B, 1, 1)) < 0.8)  # some members use nothing
    J = G @ G.transpose(0, 2, 1)
    F = rng.normal(size=(2, 2))
    Q = np.array([[0.3, 0.1], [0.1, 0.2]])
    comp = np.stack([P[:, 0, 0], P[:, 0, 1], P[:, 1, 1]])
    j = np.stack([J[:, 0, 0], J[:, 0, 1], J[:, 1, 1]])
    f, q = small.to_mat2(F), small.to_sym2(Q)
    out = update2(comp, f, q, j)
    for i in range(B):
        p = tuple(float(v) for v in comp[:, i])
        ji = tuple(float(v) for v in j[:, i])
        assert tuple(out[:, i].tolist()) == small.info_update2(small.predict2(p, f, q), ji)
        one = update2(comp[:, i : i + 1], f, q, j[:, i : i + 1])  # the batch of one
        np.testing.assert_array_equal(one[:, 0], out[:, i])
    want = np.stack([information_update(predict_cov(P[i], F, Q), J[i][None]) for i in range(B)])
    got = np.stack([[[a, b], [b, d]] for a, b, d in out.T])
    np.testing.assert_allclose(got, want, rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("scenario", ["ch2-pv-1", "ch2-position", "ch4-position", "ch4-random"])
def test_sparse_attacked_info_of_every_sensor_count_matches_sync(scenario):
    # the batched "attacked" info is looked up in a table of the subsets' sensor bits (M = 1, 2,
    # 3 packed in machine words, 10 as rows); each member must report its own trimmed subset
    kwargs = {"scenario": scenario, "budget": 2, "horizon": 3}
    if scenario == "ch4-random":
        kwargs["action"] = "bitmask"
    compare_with_sync("fdia_env/SparseAttack-v0", kwargs, B=6, steps=8)


@pytest.mark.parametrize("autoreset", [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP])
def test_vector_infos_handed_out_never_change_afterwards(autoreset):
    # the infos hold the step's own arrays (no copies): later steps and the members' autoresets
    # must build new arrays, never write into ones already returned
    venv = gym.make_vec(
        "fdia_env/SparseAttack-v0",
        num_envs=4,
        vectorization_mode="vector_entry_point",
        autoreset_mode=autoreset,
        max_episode_steps=3,
        horizon=6,
    )
    _, info = venv.reset(seed=3)
    kept = [info]
    snapshots = [{k: np.copy(v) for k, v in info.items() if not isinstance(v, dict)}]
    rng = np.random.default_rng(0)
    for _ in range(8):
        _, _, _, _, info = venv.step(rng.integers(0, 8, size=4))
        kept.append(info)
        snapshots.append({k: np.copy(v) for k, v in info.items() if not isinstance(v, dict)})
    for t, (info, snap) in enumerate(zip(kept, snapshots, strict=True)):
        for key, value in snap.items():
            if value.dtype == object:
                continue
            np.testing.assert_array_equal(info[key], value, err_msg=f"step {t} key {key}")
    assert any(s["budget_left"].min() < 5 for s in snapshots)  # attacks were spent


@pytest.mark.parametrize("statistic", ["chi2", "quadratic"])
@pytest.mark.parametrize("on_detect", ["discard", "incorporate"])
@pytest.mark.parametrize("sampled", [False, True])
def test_single_detection_step_is_the_batched_step_of_one(statistic, on_detect, sampled):
    # one detection step: the single env runs batched_detection_step with B = 1; each member of
    # a batch (own threshold, covariance, Σ, p) equals its own step as a batch of one
    from fdia_env import scenarios
    from fdia_env.backend import NUMPY
    from fdia_env.defenses.base import BatchDetection
    from fdia_env.detection.step import SystemArrays, batched_detection_step
    from fdia_env.kalman import psd_sqrt

    system = scenarios.get("ch4-position").system
    n, nz = system.n, system.nz
    rng = np.random.default_rng(5)
    B = 4
    L = rng.normal(size=(B, n, n))
    P = L @ L.transpose(0, 2, 1) + 0.5 * np.eye(n)
    S = rng.normal(size=(B, nz, nz))
    sigma = S @ S.transpose(0, 2, 1)
    p = np.array([0.0, 0.3, 0.7, 1.0])
    thresholds = np.array([0.5, 2.0, 4.0, np.inf])
    assumed = 0.5 * np.eye(nz)
    arrays = SystemArrays.of(system, NUMPY, psd_sqrt(system.Q), psd_sqrt(system.R))
    rule = BatchDetection(statistic, thresholds, on_detect, assumed, False, "mse")
    x = rng.normal(size=(B, n)) if sampled else None
    x_hat = rng.normal(size=(B, n)) if sampled else None
    draw = None
    if sampled:  # each member's own generator, as the single env's
        seeds = [10, 11, 12, 13]

        def draw(prob):
            attacked, noise = np.zeros(B, bool), np.zeros((B, n + 2 * nz))
            for i, s in enumerate(seeds):
                g = np.random.default_rng(s)
                attacked[i] = g.random() < prob[i]
                count = n + nz + (nz if attacked[i] else 0)
                noise[i, :count] = g.standard_normal(count)
            return attacked, noise

    def one_draw(seed):
        def draw_one(prob):
            g = np.random.default_rng(seed)
            attacked = g.random() < prob[0]
            noise = np.zeros((1, n + 2 * nz))
            count = n + nz + (nz if attacked else 0)
            noise[0, :count] = g.standard_normal(count)
            return np.array([attacked]), noise

        return draw_one

    def _first(value):
        if value is None:
            return None
        if isinstance(value, dict):
            return {k: (bool(v[0]) if v.dtype == bool else float(v[0])) for k, v in value.items()}
        return value[0]

    batch = batched_detection_step(
        NUMPY, system, arrays, rule, sigma, p, P, draw=draw, x=x, x_hat=x_hat
    )
    for i in range(B):  # member i alone: a batch of one (the single env's step)
        one = batched_detection_step(
            NUMPY,
            system,
            arrays,
            BatchDetection(statistic, thresholds[i : i + 1], on_detect, assumed, False, "mse"),
            sigma[i : i + 1],
            p[i : i + 1],
            P[i : i + 1],
            draw=None if not sampled else one_draw(seeds[i]),
            x=None if x is None else x[i : i + 1],
            x_hat=None if x_hat is None else x_hat[i : i + 1],
        )
        one = type(one)(**{f: _first(getattr(one, f)) for f in one.__dataclass_fields__})
        np.testing.assert_allclose(one.P, batch.P[i], rtol=1e-12, atol=1e-14)
        if sampled:
            np.testing.assert_allclose(one.x_hat, batch.x_hat[i], rtol=1e-12, atol=1e-14)
            np.testing.assert_allclose(one.x, batch.x[i], rtol=1e-12, atol=1e-14)
            assert one.info["detected"] == bool(batch.info["detected"][i])
            assert one.info["attacked_now"] == bool(batch.info["attacked_now"][i])
        else:
            np.testing.assert_allclose(one.error_cov, batch.error_cov[i], rtol=1e-12)
            assert one.info["p_detection"] == pytest.approx(batch.info["p_detection"][i])
    if not sampled:  # τ = inf never detects; τ grows, P_fa falls
        assert batch.info["p_false_alarm"][3] == 0.0
        assert np.all(np.diff(batch.info["p_false_alarm"]) <= 0)


@pytest.mark.parametrize("mode", ["terminal", "shaped", "per_step"])
def test_one_reward_for_floats_and_batches(mode):
    from fdia_env.backend import NUMPY
    from fdia_env.envs.parallel import attacker_reward

    phi, prev = np.array([3.0, 5.0, -np.inf]), np.array([1.0, 5.5, 2.0])
    done = np.array([True, False, False])
    batch = attacker_reward(mode, phi, prev, done, NUMPY)
    single = [
        attacker_reward(mode, float(a), float(b), bool(d))
        for a, b, d in zip(phi, prev, done, strict=True)
    ]
    np.testing.assert_array_equal(batch, single)
    want = {"terminal": [3.0, 0.0, 0.0], "shaped": [2.0, -0.5, -np.inf], "per_step": phi}[mode]
    np.testing.assert_array_equal(batch, want)
    assert batch is not phi  # a new array: the vector env zeroes members' rewards in place


# (the property "one engine behind every face" is tests/properties/test_prop_engine.py)


@pytest.mark.parametrize("attack", ["sparse", "covariance"])
def test_sensor_selection_against_a_non_subset_attack_matches_sync(attack):
    # the defender's features are the attacker's last subset; an attack that picks no subset
    # leaves them at zero in the single env, and the native vector env crashed on it
    # (AttributeError reading the attack's subset table)
    from fdia_env.envs.single_agent import make_single_agent
    from fdia_env.vector.env import make_vector

    kwargs = {"scenario": "ch4-position", "attack": attack, "defense": "sensor_selection"}
    kwargs["attack_kwargs"] = {"budget": 2} if attack == "sparse" else {"power": 25.0}
    B = 3
    native = make_vector("fdia_env.fdia_v0", B, **kwargs)
    sync = SyncVectorEnv(
        [lambda: make_single_agent("fdia_env.fdia_v0", **kwargs) for _ in range(B)]
    )
    native.reset(seed=4)
    _, info = sync.reset(seed=4)
    rng = np.random.default_rng(4)
    for _ in range(4):
        actions = random_actions(native.single_action_space, rng, info.get("action_mask"))
        if actions.ndim == 0 or len(actions) != B:
            actions = np.array([random_actions(native.single_action_space, rng) for _ in range(B)])
        out_n, out_s = native.step(actions), sync.step(actions)
        np.testing.assert_allclose(out_n[0], out_s[0], rtol=1e-6, atol=1e-6)
        np.testing.assert_allclose(out_n[1], out_s[1], rtol=1e-9, atol=1e-12)
        info = out_s[4]
    assert not native.defense.b_opponent.any()  # the attack picks no subset: zeros


@pytest.mark.parametrize("sensors", [3, 12])
def test_single_env_attacked_info_lists_the_subset_of_every_action(sensors):
    # the single env's "attacked" info comes from a table of the subsets' bits for M <= 10 and
    # from the bitmask itself above; both must name exactly the sensors of the action
    from fdia_env import sparse_attack_v0

    system = LinearSystem(
        F=np.eye(2),
        Q=0.1 * np.eye(2),
        sensors=tuple(Sensor(H=[[1.0, 0.1 * i]], R=[[1.0 + 0.1 * i]]) for i in range(sensors)),
        name=f"{sensors}-sensors",
    )
    env = sparse_attack_v0.parallel_env(
        scenario=system, budget=sensors, horizon=1, action="bitmask"
    )
    for a in [0, 1, 5, 2**sensors - 1, 2 ** (sensors - 1) + 2]:
        env.reset(seed=0)
        _, _, _, _, infos = env.step({"attacker": a})
        attacked = infos["attacker"]["attacked"]
        assert attacked.dtype == np.int8 and attacked.shape == (sensors,)
        np.testing.assert_array_equal(attacked, [(a >> i) & 1 for i in range(sensors)])


@pytest.mark.parametrize(
    "case", ["sparse-sampled", "game-defender-sampled", "detection-defender-sampled-bayes"]
)
def test_reset_without_seed_keeps_each_members_generator_as_sync_does(case):
    """``reset(seed=3); reset()`` is reproducible: an unseeded reset continues each draw."""
    env_id, kwargs = CASES[case]
    kwargs = {**kwargs, **opponent_for(env_id)}
    B = 3

    def rollout(env):
        env.action_space.seed(5)
        out = [env.reset(seed=3)[0]]
        for _ in range(4):
            out.append(env.step(env.action_space.sample())[1])
        out.append(env.reset()[0])  # unseeded: continues each member's generator
        for _ in range(4):
            out.append(env.step(env.action_space.sample())[1])
        return out

    def native():
        return gym.make_vec(env_id, num_envs=B, vectorization_mode="vector_entry_point", **kwargs)

    first, second = rollout(native()), rollout(native())
    sync = rollout(SyncVectorEnv([lambda: gym.make(env_id, **kwargs) for _ in range(B)]))
    for a, b, s in zip(first, second, sync, strict=True):
        np.testing.assert_array_equal(a, b)
        np.testing.assert_allclose(a, s, rtol=1e-6, atol=1e-7)


def test_torch_cpu_members_share_the_history_table_too():
    # torch on the CPU uses the same host table (its tensors are views of its arrays): the same
    # observations and rewards as numpy, bit for bit, and torch tensors out
    torch = pytest.importorskip("torch")
    envs = {
        backend: gym.make_vec(
            "fdia_env/SparseAttack-v0",
            num_envs=32,
            vectorization_mode="vector_entry_point",
            backend=backend,
            objective="logdet",
        )
        for backend in ("numpy", "torch")
    }
    obs = {k: env.reset(seed=3)[0] for k, env in envs.items()}
    np.testing.assert_array_equal(obs["torch"].numpy(), obs["numpy"])
    rng = np.random.default_rng(3)
    for t in range(15):
        a = rng.integers(0, 8, size=32)
        out_n = envs["numpy"].step(a)
        out_t = envs["torch"].step(torch.as_tensor(a))
        assert isinstance(out_t[0], torch.Tensor) and isinstance(out_t[1], torch.Tensor)
        np.testing.assert_array_equal(out_t[0].numpy(), out_n[0], err_msg=f"step {t}")
        np.testing.assert_array_equal(out_t[1].numpy(), out_n[1], err_msg=f"step {t}")
        np.testing.assert_array_equal(out_t[4]["phi"].numpy(), out_n[4]["phi"])
    assert envs["torch"].sim.shares_histories and envs["numpy"].sim.shares_histories


def test_every_torch_id_builds_resets_and_steps_on_torch():
    # each id the registry lists with the torch backend, at its defaults: the native vector env
    # on torch (CPU) accepts it and gives (B, d) observations and finite rewards
    torch = pytest.importorskip("torch")
    from fdia_env.registration import torch_ids

    for env_id in torch_ids():
        env = gym.make_vec(
            env_id, num_envs=2, vectorization_mode="vector_entry_point", backend="torch"
        )
        obs, _ = env.reset(seed=0)
        assert tuple(obs.shape) == (2, *env.single_observation_space.shape), env_id
        env.single_action_space.seed(0)
        action = np.stack([env.single_action_space.sample() for _ in range(2)])
        if isinstance(env.single_action_space, gym.spaces.Discrete):  # a legal one per member
            mask = np.asarray(env.action_masks())
            action = np.array([np.flatnonzero(m)[0] for m in mask])
        out = env.step(torch.as_tensor(action))
        assert torch.isfinite(out[1]).all(), env_id
        env.close()


def test_make_vector_forwards_the_vector_options_of_the_class_and_the_rest_to_the_env():
    # make_vector takes every option as a keyword (as Gymnasium's entry points): the vector
    # env's options are FdiaVectorEnv's keyword parameters, the rest the env's own
    import inspect

    from fdia_env.vector.env import FdiaVectorEnv, make_vector, split_vector_options

    params = list(inspect.signature(FdiaVectorEnv.__init__).parameters)[3:]
    options, rest = split_vector_options({"max_episode_steps": 3, "scenario": "ch4-position"})
    assert list(options) == params
    assert options["max_episode_steps"] == 3 and options["backend"] == "numpy"
    assert rest == {"scenario": "ch4-position"}
    env = make_vector(
        "fdia_env.fdia_v0", 2, max_episode_steps=3, autoreset_mode="SameStep", max_cycles=7
    )
    assert env.max_episode_steps == 3 and env.autoreset_mode.name == "SAME_STEP"
    assert env.parallel.max_cycles == 7
    with pytest.raises(ValueError, match="autoreset_mode"):
        make_vector("fdia_env.fdia_v0", 2, autoreset_mode="later")
    with pytest.raises(TypeError, match="positional"):
        make_vector("fdia_env.fdia_v0", 2, "defender")
