"""The torch backend of the vector env against the numpy backend, on the CPU (float64).

Expected dynamics must agree member by member (rewards and Φ to 1e-10 relative, float32
observations to float32 rounding) through several autoresets; sampled dynamics draw from another
generator, so they are compared by moments, with tolerances from the standard errors, and both
against the exact moments that expected dynamics give for the same attack.
"""

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

from fdia_env import LinearSystem, Sensor
from fdia_env.backend import NUMPY, get_backend, namespace
from fdia_env.envs.opponents import FixedMix
from fdia_env.kalman import inv2, joseph_update, logdet, predict_cov, psd_sqrt, small
from fdia_env.vector import FdiaVectorEnv

torch = pytest.importorskip("torch")
TORCH = get_backend("torch", "cpu")
# the member-by-member comparison runs on every device present (CI: the CPU only)
DEVICES = ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])

THREE_STATE = LinearSystem(
    F=np.array([[1.0, 1.0, 0.5], [0.0, 1.0, 1.0], [0.0, 0.0, 0.9]]),
    Q=0.01 * np.eye(3),
    sensors=(Sensor(H=[[1.0, 0.0, 0.0]], R=[[0.2]]), Sensor(H=[[0.0, 1.0, 1.0]], R=[[0.5]])),
    name="three-state",
)

SPARSE, COVARIANCE = "fdia_env/SparseAttack-v0", "fdia_env/CovarianceAttack-v0"

# (id, options, autoreset mode): every supported env type, 2-state (closed-form kernels and the
# generic path) and n > 2 (a 3-state system and the 13-state IEEE 14-bus grid)
EXPECTED_CASES = {
    "sparse-ch4": (SPARSE, {}, AutoresetMode.NEXT_STEP),
    "sparse-ch4-logdet-shaped-same-step": (
        SPARSE,
        {"objective": "logdet", "reward_mode": "shaped"},
        AutoresetMode.SAME_STEP,
    ),
    "sparse-warmup-noop": (SPARSE, {"warmup": 3, "illegal_action": "noop"}, "NextStep"),
    "sparse-single": (SPARSE, {"action": "single", "budget": 2}, AutoresetMode.NEXT_STEP),
    "sparse-3state-per-step": (
        SPARSE,
        {"scenario": THREE_STATE, "budget": 3, "horizon": 4, "reward_mode": "per_step"},
        AutoresetMode.SAME_STEP,
    ),
    "sparse-grid14-multibinary": (
        SPARSE,
        {"scenario": "grid-ieee14", "horizon": 3, "budget": 6},
        AutoresetMode.NEXT_STEP,
    ),
    "sparse-grid14-single-truncated": (
        SPARSE,
        {"scenario": "grid-ieee14", "horizon": 3, "action": "single", "max_episode_steps": 2},
        AutoresetMode.SAME_STEP,
    ),
    "covariance-pv-per-step": (
        COVARIANCE,
        {"scenario": "ch2-pv-2", "horizon": 3, "reward_mode": "per_step"},
        AutoresetMode.NEXT_STEP,
    ),
    "covariance-budget-diagonal-same-step": (
        COVARIANCE,
        {"horizon": 4, "power_mode": "budget", "structure": "diagonal"},
        AutoresetMode.SAME_STEP,
    ),
    "covariance-3state-logdet": (
        COVARIANCE,
        {
            "scenario": THREE_STATE,
            "power": 2.0,
            "horizon": 3,
            "objective": "logdet",
            "reward_mode": "shaped",
        },
        AutoresetMode.NEXT_STEP,
    ),
    # the sensor game: steady restarts (a DARE per distinct subset), leaks through A ∩ D, an
    # opponent (deterministic here, so that both backends see the same opponent actions)
    "game-attacker": (
        "fdia_env/SensorGameAttacker-v0",
        {"rounds": 3, "opponent": FixedMix([0, 0, 0, 0, 0, 1.0, 0])},
        AutoresetMode.NEXT_STEP,
    ),
    "game-defender-terminal-same-step": (
        "fdia_env/SensorGameDefender-v0",
        {"rounds": 2, "reward_mode": "terminal", "opponent": FixedMix([0, 0, 1.0, 0, 0, 0, 0])},
        AutoresetMode.SAME_STEP,
    ),
    "game-attacker-dependent-small": (
        "fdia_env/SensorGameAttacker-v0",
        {
            "rounds": 2,
            "allocation": "dependent",
            "max_subset_size": 2,
            "opponent": FixedMix([0, 0, 0, 0, 0, 0, 1.0]),
        },
        AutoresetMode.NEXT_STEP,
    ),
    # the detection game: the detector's step, exact expected errors computed on the host
    "detection-defender-static": (
        "fdia_env/DetectionDefender-v0",
        {"horizon": 2},
        AutoresetMode.NEXT_STEP,
    ),
    "detection-defender-tracking-same-step": (
        "fdia_env/DetectionDefender-v0",
        {"scenario": "ch3-tracking", "warmup": "steady", "horizon": 1},
        AutoresetMode.SAME_STEP,
    ),
    "detection-attacker-bayes-incorporate": (
        "fdia_env/DetectionAttacker-v0",
        {"criterion": "bayes_cost", "horizon": 2, "on_detect": "incorporate"},
        AutoresetMode.NEXT_STEP,
    ),
}

DTYPES = {
    np.dtype(np.float64): torch.float64,
    np.dtype(np.float32): torch.float32,
    np.dtype(np.int64): torch.int64,
    np.dtype(np.int8): torch.int8,
    np.dtype(np.bool_): torch.bool,
}


def make_pair(env_id, options, B, autoreset=AutoresetMode.NEXT_STEP, device="cpu"):
    """The numpy and the torch vector env of the same id and options."""
    kw = {"num_envs": B, "vectorization_mode": "vector_entry_point", "autoreset_mode": autoreset}
    np_env = gym.make_vec(env_id, **kw, **options)
    torch_env = gym.make_vec(env_id, **kw, backend="torch", device=device, **options)
    assert isinstance(torch_env, FdiaVectorEnv) and torch_env.backend == "torch"
    assert np_env.xp is NUMPY and torch_env.xp is get_backend("torch", device)
    return np_env, torch_env


def assert_same(numpy_value, torch_value, where, rtol=1e-10, atol=1e-12, device=None):
    """A torch tensor equal to a numpy array: same shape, the matching dtype, equal values."""
    assert isinstance(torch_value, torch.Tensor), f"{where}: {type(torch_value)}"
    assert torch_value.device == (device or TORCH.device), where
    assert tuple(torch_value.shape) == numpy_value.shape, where
    assert torch_value.dtype == DTYPES[numpy_value.dtype], f"{where}: {torch_value.dtype}"
    got = torch_value.cpu().numpy()
    if np.issubdtype(numpy_value.dtype, np.floating):
        np.testing.assert_allclose(got, numpy_value, rtol=rtol, atol=atol, err_msg=where)
    else:
        np.testing.assert_array_equal(got, numpy_value, err_msg=where)


def assert_infos_same(np_infos, torch_infos, where, device=None):
    assert sorted(np_infos) == sorted(torch_infos), where
    for key, value in np_infos.items():
        if key == "final_obs":  # numpy: an object array of rows; torch: a (B, d) tensor
            mask = np_infos["_final_obs"]
            rows = torch_infos[key].cpu().numpy()
            for i in np.flatnonzero(mask):
                np.testing.assert_allclose(rows[i], value[i], rtol=1e-6, atol=1e-6)
            assert not rows[~mask].any(), f"{where}: rows of members that did not end"
        elif isinstance(value, dict):
            assert_infos_same(value, torch_infos[key], f"{where}/{key}", device)
        else:
            assert_same(value, torch_infos[key], f"{where}/{key}", device=device)


def random_actions(env, rng, infos):
    """(B, ...) numpy actions: legal under the action mask, or uniform in the Box."""
    space, B = env.single_action_space, env.num_envs
    if isinstance(space, gym.spaces.Discrete):
        mask = env.action_masks()
        return np.array([rng.choice(np.flatnonzero(m)) for m in mask], dtype=np.int64)
    if isinstance(space, gym.spaces.MultiBinary):
        return (rng.random((B, *space.shape)) < 0.15).astype(np.int64)
    return rng.uniform(-1, 1, size=(B, *space.shape)).astype(np.float32)


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("case", sorted(EXPECTED_CASES))
def test_expected_dynamics_equal_numpy_member_by_member(case, device):
    env_id, options, autoreset = EXPECTED_CASES[case]
    B = 6
    np_env, torch_env = make_pair(env_id, options, B, autoreset, device)
    dev = torch_env.xp.device
    obs_n, info_n = np_env.reset(seed=3)
    obs_t, info_t = torch_env.reset(seed=3)
    assert_same(obs_n, obs_t, "reset obs", rtol=1e-6, atol=1e-6, device=dev)
    assert_infos_same(info_n, info_t, "reset", dev)
    rng = np.random.default_rng(1)
    episodes = 0
    horizon = np_env.spec_episode.horizon
    for t in range(2 * (horizon + 1) + 1):  # two episodes of every member and their autoresets
        actions = random_actions(np_env, rng, info_n)
        obs_n, r_n, te_n, tr_n, info_n = np_env.step(actions)
        obs_t, r_t, te_t, tr_t, info_t = torch_env.step(torch.as_tensor(actions, device=dev))
        assert_same(obs_n, obs_t, f"step {t} obs", rtol=1e-6, atol=1e-6, device=dev)
        assert_same(r_n, r_t, f"step {t} reward", device=dev)
        assert_same(te_n, te_t, f"step {t} terminated", device=dev)
        assert_same(tr_n, tr_t, f"step {t} truncated", device=dev)
        assert_infos_same(info_n, info_t, f"step {t}", dev)
        assert_same(np_env.action_masks(), torch_env.action_masks(), f"step {t} masks", device=dev)
        M_t = torch_env.sim.M.cpu().numpy()
        np.testing.assert_allclose(M_t, np_env.sim.M, rtol=1e-10, atol=1e-14)
        episodes += int((te_n | tr_n).sum())
    assert episodes >= 2 * B  # every member went through at least two autoresets


def test_default_backend_is_numpy():
    env = gym.make_vec(SPARSE, num_envs=3, vectorization_mode="vector_entry_point")
    obs, infos = env.reset(seed=0)
    assert env.backend == "numpy" and isinstance(obs, np.ndarray)
    assert all(isinstance(v, np.ndarray) for v in infos.values())


# --- sampled dynamics: moments -------------------------------------------------------------


def sampled_errors(env_id, options, backend, B, plan, seed):
    """(steps, B) squared estimation errors of B members under a fixed action plan."""
    kw = {"backend": backend} if backend == "torch" else {}
    env = gym.make_vec(
        env_id,
        num_envs=B,
        vectorization_mode="vector_entry_point",
        dynamics="sampled",
        reward_mode="per_step",
        **kw,
        **options,
    )
    env.reset(seed=seed)
    out = []
    for action in plan:
        batch = np.repeat(np.asarray(action)[None], B, axis=0)
        if backend == "torch":
            batch = torch.as_tensor(batch)
        _, reward, *_ = env.step(batch)
        out.append(np.asarray(reward))
    return np.array(out)


def exact_moments(env_id, options, plan):
    """Mean and variance of |e|² per step from expected dynamics: tr M and 2 tr M² (e Gaussian)."""
    env = gym.make_vec(env_id, num_envs=1, vectorization_mode="vector_entry_point", **options)
    env.reset(seed=0)
    mean, var = [], []
    for action in plan:
        env.step(np.asarray(action)[None])
        M = env.sim.M[0]
        mean.append(np.trace(M))
        var.append(2.0 * np.trace(M @ M))
    return np.array(mean), np.array(var)


SAMPLED_CASES = {
    # dropped sensors, no bias (ch4-position, 2 states)
    "sparse-ch4": (SPARSE, {"budget": 5, "horizon": 6}, [0, 0, 1, 1, 1, 3]),
    # a 3-state system, int warm-up (the sampled reset's warm-up steps)
    "sparse-3state-warmup": (
        SPARSE,
        {"scenario": THREE_STATE, "budget": 3, "horizon": 4, "warmup": 2},
        [1, 2, 0, 1],
    ),
    # a bias that reaches the filter: the bias draws and the Joseph form
    "covariance-pv": (
        COVARIANCE,
        {"scenario": "ch2-pv-2", "horizon": 3},
        [np.full(10, 0.3, np.float32), np.linspace(-1, 1, 10, dtype=np.float32)] * 2,
    ),
    # the sensor game: steady restarts drawing the error afresh, a bias leaking through A ∩ D
    "game-attacker": (
        "fdia_env/SensorGameAttacker-v0",
        {"rounds": 3, "opponent": FixedMix([0, 0, 0, 0, 0, 1.0, 0])},
        [0, 3, 6],
    ),
}


@pytest.mark.parametrize("case", sorted(SAMPLED_CASES))
def test_sampled_dynamics_moments_equal_numpy_and_exact(case):
    env_id, options, plan = SAMPLED_CASES[case]
    plan = plan[: options.get("horizon", options.get("rounds"))]
    B = 16000  # 5 standard errors of the mean of |e|² are about 4 % of it
    e_np = sampled_errors(env_id, options, "numpy", B, plan, seed=10)
    e_t = sampled_errors(env_id, options, "torch", B, plan, seed=10)
    mean, var = exact_moments(env_id, options, plan)
    for name, e in (("numpy", e_np), ("torch", e_t)):
        # mean of |e|²: standard error sqrt(var / B); 5 SE is exceeded with probability 6e-7
        se = np.sqrt(var / B)
        np.testing.assert_array_less(np.abs(e.mean(axis=1) - mean), 5 * se, err_msg=name)
        # variance of |e|²: standard error from the sample's own fourth moment
        dev2 = (e - e.mean(axis=1, keepdims=True)) ** 2
        se_var = dev2.std(axis=1) / np.sqrt(B)
        np.testing.assert_array_less(np.abs(dev2.mean(axis=1) - var), 5 * se_var, err_msg=name)
    # the two backends against each other: the difference of two independent means
    se_diff = np.sqrt(e_np.var(axis=1) / B + e_t.var(axis=1) / B)
    np.testing.assert_array_less(np.abs(e_np.mean(axis=1) - e_t.mean(axis=1)), 5 * se_diff)


def test_sampled_detection_game_means_equal_numpy_and_exact():
    """H1 drawn with probability p, the test decides per member, the filter continues.

    The error is then a Gaussian mixture: its mean at the first step is the exact expected
    error (expected dynamics, horizon 1); later steps are compared between the backends only
    (expected dynamics stop after one detection in the tracking setting).
    """
    env_id = "fdia_env/DetectionDefender-v0"
    options = {"scenario": "ch3-tracking", "warmup": "steady", "horizon": 3}
    plan = [np.array([x], np.float32) for x in (0.9, 0.2, -0.5)]  # 0.9: rarely detected
    B = 16000
    e_np = -sampled_errors(env_id, options, "numpy", B, plan, seed=10)  # the defender pays −Φ
    e_t = -sampled_errors(env_id, options, "torch", B, plan, seed=10)
    mean, _ = exact_moments(env_id, {**options, "horizon": 1}, plan[:1])
    for name, e in (("numpy", e_np), ("torch", e_t)):
        assert abs(e[0].mean() - mean[0]) < 5 * e[0].std() / np.sqrt(B), name
    se_diff = np.sqrt(e_np.var(axis=1) / B + e_t.var(axis=1) / B)
    np.testing.assert_array_less(np.abs(e_np.mean(axis=1) - e_t.mean(axis=1)), 5 * se_diff)


def test_sampled_torch_seed_reproduces_and_differs():
    options = {"budget": 5, "horizon": 6}
    plan = [0, 0, 1, 1, 1, 3]
    a = sampled_errors(SPARSE, options, "torch", 64, plan, seed=5)
    b = sampled_errors(SPARSE, options, "torch", 64, plan, seed=5)
    c = sampled_errors(SPARSE, options, "torch", 64, plan, seed=6)
    np.testing.assert_array_equal(a, b)
    assert np.abs(a - c).max() > 1e-3


# --- the backend's primitives ----------------------------------------------------------------


def test_kalman_primitives_equal_on_both_backends():
    rng = np.random.default_rng(0)
    A = rng.standard_normal((7, 3, 3))
    P = A @ A.swapaxes(-1, -2) + 0.1 * np.eye(3)
    P2 = P[:, :2, :2]
    F = rng.standard_normal((3, 3))
    W = rng.standard_normal((7, 3, 2))
    H, R = rng.standard_normal((2, 3)), np.diag([0.5, 2.0])
    t = TORCH.asarray
    pairs = {
        "inv2": (inv2(P2), inv2(t(P2))),
        "logdet": (logdet(P), logdet(t(P))),
        "predict_cov": (predict_cov(P, F, np.eye(3)), predict_cov(t(P), t(F), TORCH.eye(3))),
        "joseph": (joseph_update(P, W, H, R), joseph_update(t(P), t(W), t(H), t(R))),
        "inv2_stacked": (
            small.inv2_stacked(np.stack([P2[:, 0, 0], P2[:, 0, 1], P2[:, 1, 1]])),
            small.inv2_stacked(t(np.stack([P2[:, 0, 0], P2[:, 0, 1], P2[:, 1, 1]]))),
        ),
    }
    for name, (a, b) in pairs.items():
        assert namespace(b) is TORCH, name
        np.testing.assert_allclose(b.numpy(), a, rtol=1e-12, atol=1e-14, err_msg=name)
    np.testing.assert_allclose(inv2(P2) @ P2, np.broadcast_to(np.eye(2), (7, 2, 2)), atol=1e-12)
    root = psd_sqrt(t(P)).numpy()  # a factor, not a unique matrix: check L L' = P
    np.testing.assert_allclose(root @ root.swapaxes(-1, -2), P, rtol=1e-10)


# --- bad input -----------------------------------------------------------------------------


def test_unknown_backend_is_rejected():
    with pytest.raises(ValueError, match=r"backend must be one of \['numpy', 'torch'\]"):
        gym.make_vec(SPARSE, num_envs=2, vectorization_mode="vector_entry_point", backend="jax")


@pytest.mark.skipif(torch.cuda.is_available(), reason="a GPU is present")
def test_cuda_without_gpu_is_rejected():
    with pytest.raises(ValueError, match=r"device='cuda' needs a CUDA GPU.*use device='cpu'"):
        gym.make_vec(
            SPARSE, num_envs=2, vectorization_mode="vector_entry_point", backend="torch",
            device="cuda",
        )  # fmt: skip


@pytest.mark.parametrize(
    ("device", "match"),
    [("tpu", "device must be"), (3.5, "device must be a torch.device or a string")],
)
def test_bad_device_is_rejected(device, match):
    with pytest.raises(ValueError, match=match):
        get_backend("torch", device)


def test_device_with_numpy_backend_is_rejected():
    with pytest.raises(ValueError, match="device must be None or 'cpu' for backend='numpy'"):
        get_backend("numpy", "cuda")


def test_model_without_torch_batch_is_rejected():
    """Every registered id runs on torch; a user's model without a torch batch is refused."""
    from fdia_env import fdia_v0
    from fdia_env.defenses import PerfectDetection

    class NumpyOnlyDefense(PerfectDetection):
        batch_backends = ("numpy",)

    parallel = fdia_v0.parallel_env(defense=NumpyOnlyDefense(), attack_kwargs={"budget": 2})
    with pytest.raises(ValueError, match=r"NumpyOnlyDefense has no torch batch .*supports"):
        FdiaVectorEnv(parallel, 2, backend="torch")
    FdiaVectorEnv(parallel, 2).reset(seed=0)  # numpy still takes it


def torch_env(env_id=SPARSE, **options):
    env = gym.make_vec(
        env_id, num_envs=3, vectorization_mode="vector_entry_point", backend="torch", **options
    )
    env.reset(seed=0)
    return env


@pytest.mark.parametrize(
    ("actions", "error", "match"),
    [
        (np.zeros(3, np.int64), TypeError, r"must be a torch.Tensor .* got numpy.ndarray"),
        ([0, 1, 2], TypeError, r"must be a torch.Tensor .* got builtins.list"),
        (torch.zeros(3), TypeError, r"must have an integer dtype .* got torch.float32"),
        (torch.zeros(3, dtype=torch.bool), TypeError, "must have an integer dtype"),
        (torch.zeros(3, dtype=torch.int64, device="meta"), ValueError, "env's device cpu"),
        (torch.zeros(4, dtype=torch.int64), ValueError, r"shape \(3,\) .* got shape \(4,\)"),
        (torch.tensor([0, 8, 1]), ValueError, r"lie in Discrete\(8\); member 1 has 8"),
        (torch.tensor([0, -1, 1]), ValueError, "member 1 has -1"),
    ],
)
def test_bad_torch_actions_are_rejected(actions, error, match):
    env = torch_env()
    with pytest.raises(error, match=match):
        env.step(actions)
    obs, *_ = env.step(torch.zeros(3, dtype=torch.int64))  # the env still steps afterwards
    assert obs.shape == (3, 5)


@pytest.mark.parametrize(
    ("actions", "error", "match"),
    [
        (torch.zeros((3, 10), dtype=torch.complex64), TypeError, "a real dtype"),
        (torch.full((3, 10), float("nan")), ValueError, "finite"),
        (torch.full((3, 10), 1.5), ValueError, r"lie in \[-1, 1\]"),
        (torch.zeros((3, 9)), ValueError, r"shape \(3, 10\)"),
    ],
)
def test_bad_torch_box_actions_are_rejected(actions, error, match):
    env = torch_env(COVARIANCE, scenario="ch2-pv-2")
    with pytest.raises(error, match=match):
        env.step(actions)
    env.step(torch.zeros((3, 10), dtype=torch.int64))  # an integer member is cast, as on numpy


def test_multibinary_torch_actions_must_be_binary():
    env = torch_env(scenario="grid-ieee14", horizon=3)
    with pytest.raises(ValueError, match="must be 0/1"):
        env.step(torch.full((3, 34), 2, dtype=torch.int64))
    env.step(torch.ones((3, 34), dtype=torch.bool))  # bool is a 0/1 action


def test_torch_seed_list_is_rejected():
    env = torch_env()
    with pytest.raises(ValueError, match="seed must be an int or None for backend='torch'"):
        env.reset(seed=[0, 1, 2])


def test_illegal_action_error_names_the_budget_on_torch():
    env = torch_env(illegal_action="error", budget=1)
    with pytest.raises(ValueError, match="is illegal: it attacks 3 sensors with 1 of the budget"):
        env.step(torch.tensor([0, 7, 0]))


@pytest.mark.parametrize(
    ("scenario", "options"),
    [("ch4-position", {"power": 1.0}), ("ch2-pv-2", {}), ("grid-ieee14", {"horizon": 3})],
)
def test_engine_partial_resets_equal_numpy(scenario, options):
    """Members reset at different times (the engine's masked reset), covariance attack leaks."""
    from fdia_env import covariance_attack_v0
    from fdia_env.envs.engine import BatchedSimulation

    single = covariance_attack_v0.parallel_env(scenario=scenario, **options).sim
    system, B = single.system, 5
    spec = single.spec
    sims = {
        "numpy": BatchedSimulation(system, spec, B),
        "torch": BatchedSimulation(system, spec, B, TORCH),
    }
    rng = np.random.default_rng(2)
    for step in range(6):
        used = rng.integers(0, 2 ** min(system.M, 30), size=B)
        leak_on = rng.random(B) < 0.5
        A = rng.standard_normal((B, system.nz, system.nz))
        leak = A @ A.swapaxes(-1, -2) * leak_on[:, None, None]
        where = rng.random(B) < 0.4  # these members restart after the step
        for name, sim in sims.items():
            x = NUMPY if name == "numpy" else TORCH
            sim.step(x.asarray(used), x.asarray(leak), x.asarray(leak_on), False)
            sim.reset(x.asarray(where))
        M_np, M_t = sims["numpy"].M, sims["torch"].M.numpy()
        np.testing.assert_allclose(M_t, M_np, rtol=1e-10, atol=1e-14, err_msg=f"step {step}")
        np.testing.assert_allclose(sims["torch"].phi.numpy(), sims["numpy"].phi, rtol=1e-10)
        np.testing.assert_array_equal(sims["torch"].k.numpy(), sims["numpy"].k)
        np.testing.assert_allclose(M_np[where], np.broadcast_to(single.P_start, M_np[where].shape))
        assert (sims["numpy"].k[where] == 0).all() and (sims["numpy"].k[~where] > 0).all()


def test_default_opponent_mix_draws_its_probabilities_on_torch():
    """The sensor game's default opponent (uniform FixedMix) draws from the device generator."""
    B = 20000
    env = gym.make_vec(
        "fdia_env/SensorGameAttacker-v0",
        num_envs=B,
        vectorization_mode="vector_entry_point",
        backend="torch",
    )
    env.reset(seed=0)
    actions = env._opponent_actions(torch.ones(B, dtype=torch.bool))
    assert actions.dtype == torch.int64 and actions.device == TORCH.device
    n = env.parallel.action_space("defender").n
    freq = np.bincount(actions.numpy(), minlength=n) / B
    p = 1.0 / n
    np.testing.assert_array_less(np.abs(freq - p), 5 * np.sqrt(p * (1 - p) / B))
    env.step(torch.zeros(B, dtype=torch.int64))  # the whole step runs with that opponent


def test_torch_batch_limit_is_larger_than_numpys():
    from fdia_env.vector.env import MAX_NUM_ENVS, MAX_NUM_ENVS_TORCH

    kw = {"vectorization_mode": "vector_entry_point"}
    with pytest.raises(ValueError, match=rf"num_envs must be <= {MAX_NUM_ENVS_TORCH}"):
        gym.make_vec(SPARSE, num_envs=MAX_NUM_ENVS_TORCH + 1, backend="torch", **kw)
    with pytest.raises(ValueError, match=rf"num_envs must be <= {MAX_NUM_ENVS}"):
        gym.make_vec(SPARSE, num_envs=MAX_NUM_ENVS + 1, **kw)
    env = gym.make_vec(SPARSE, num_envs=MAX_NUM_ENVS + 1, backend="torch", **kw)
    obs, _ = env.reset(seed=0)
    assert obs.shape == (MAX_NUM_ENVS + 1, 5)


def test_backends_unpickle_to_the_same_instances():
    import pickle

    assert pickle.loads(pickle.dumps(NUMPY)) is NUMPY
    assert pickle.loads(pickle.dumps(TORCH)) is TORCH
    env = gym.make_vec(SPARSE, num_envs=3, vectorization_mode="vector_entry_point")
    env.reset(seed=0)
    clone = pickle.loads(pickle.dumps(env.unwrapped))
    assert clone.xp is NUMPY and clone.sim.xp is NUMPY and clone.attack.xp is NUMPY


@pytest.mark.parametrize("mode", ["sync", "async"])
def test_torch_backend_outside_the_native_vector_env_names_the_way_to_it(mode):
    # make_vec's sync/async modes build single envs, which run numpy: a clear ValueError (it
    # was a TypeError about an unexpected keyword from deep inside the env creator)
    with pytest.raises(ValueError, match="vector_entry_point"):
        gym.make_vec(
            "fdia_env/SparseAttack-v0", num_envs=2, vectorization_mode=mode, backend="torch"
        )
    with pytest.raises(ValueError, match="backend='numpy', device='cpu'"):
        gym.make("fdia_env/SparseAttack-v0", device="cuda")
    env = gym.make("fdia_env/SparseAttack-v0", backend="numpy", device="cpu")  # the defaults
    assert env.reset(seed=0)[0].shape == (5,)
