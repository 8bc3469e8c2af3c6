"""The native vector env of ``fdia_env/StealthAttack-v0`` against the single env."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from fdia_env.stealth import GYM_ID, static_estimation, stealth_attack_v0, stealth_dynamic_v0


@pytest.fixture(scope="module")
def est():
    return static_estimation("ieee14")


def _vec(est, num_envs, **kwargs):
    return gym.make_vec(
        GYM_ID, num_envs=num_envs, vectorization_mode="vector_entry_point", scenario=est, **kwargs
    )


@pytest.mark.parametrize("action", ["shift", "box_shift", "free"])
def test_expected_rewards_and_infos_equal_the_single_env(est, action):
    kwargs = {"budget": 5, "action": action, "dynamics": "expected", "protected": [3]}
    kwargs |= {"a_max": 0.05} if action == "box_shift" else {}
    vec = _vec(est, 16, **kwargs)
    vec.reset(seed=0)
    vec.action_space.seed(1)
    actions = vec.action_space.sample()
    _, rewards, terms, _, infos = vec.step(actions)
    single = stealth_attack_v0.parallel_env(scenario=est, **kwargs)
    for i in range(16):
        single.reset(seed=0)
        _, r, _, _, info = single.step({"attacker": actions[i]})
        assert rewards[i] == pytest.approx(r["attacker"], rel=1e-12, abs=1e-15)
        assert infos["meters_used"][i] == info["attacker"]["meters_used"]
        assert infos["detection_probability"][i] == pytest.approx(
            info["attacker"]["detection_probability"], rel=1e-12
        )
    assert terms.all()


def test_next_step_autoreset(est):
    vec = _vec(est, 4, horizon=2)
    obs, _ = vec.reset(seed=0)
    assert obs[:, 0].tolist() == [1.0] * 4
    bits = np.zeros((4, est.n), dtype=np.int8)
    _, _, terms, _, _ = vec.step(bits)
    assert not terms.any()
    _, _, terms, _, _ = vec.step(bits)
    assert terms.all()
    obs, rewards, terms, truncs, _ = vec.step(bits)  # the reset step
    assert obs[:, 0].tolist() == [1.0] * 4
    assert not rewards.any() and not terms.any() and not truncs.any()


def test_sampled_alarm_rate_matches_the_exact_probability(est):
    a = np.zeros(est.m)
    a[0] = 0.06
    p = float(est.detection_probability(a))
    vec = _vec(est, 8000, budget=1, action="free", a_max=0.06)
    vec.reset(seed=5)
    _, rewards, _, _, infos = vec.step(np.tile((a / 0.06).astype(np.float32), (8000, 1)))
    rate = infos["detected"].mean()
    assert abs(rate - p) < 4 * np.sqrt(p * (1 - p) / 8000)
    np.testing.assert_array_equal(rewards == 0.0, infos["detected"])


def _tensor(x, dtype=None):
    torch = pytest.importorskip("torch")
    return torch.as_tensor(np.asarray(x), dtype=dtype)


def _np(x):
    return x.detach().cpu().numpy() if hasattr(x, "detach") else np.asarray(x)


@pytest.mark.parametrize("action", ["shift", "box_shift", "free"])
def test_torch_backend_equals_numpy_in_expected_dynamics(est, action):
    torch = pytest.importorskip("torch")
    kwargs = {"budget": 5, "action": action, "dynamics": "expected", "protected": [3]}
    kwargs |= {"horizon": 2, "on_detect": "penalty", "penalty": 0.3, "magnitude": 0.005}
    kwargs |= {"a_max": 0.02} if action == "box_shift" else {}
    vec, tvec = _vec(est, 64, **kwargs), _vec(est, 64, backend="torch", **kwargs)
    assert tvec.unwrapped.backend == "torch"
    obs, _ = vec.reset(seed=0)
    tobs, _ = tvec.reset(seed=0)
    np.testing.assert_array_equal(_np(tobs), obs)
    vec.action_space.seed(2)
    seen = []
    for _ in range(3):  # the third step is the autoreset step
        actions = vec.action_space.sample()
        if action == "free":
            actions[:8] *= 0.01  # small injections: detection probabilities inside (α, 1)
        dtype = torch.float32 if action == "free" else torch.int8
        out = vec.step(actions)
        tout = tvec.step(_tensor(actions, dtype))
        for want, got in zip(out[:4], tout[:4], strict=True):
            assert isinstance(got, torch.Tensor)
            np.testing.assert_allclose(_np(got), want, rtol=0, atol=1e-10)
        assert set(tout[4]) == set(out[4])
        for key, want in out[4].items():
            np.testing.assert_allclose(_np(tout[4][key]), want, rtol=1e-10, atol=1e-10)
        seen.append(out[4]["detection_probability"])
    p = np.concatenate(seen)
    assert ((p > 0.05 + 1e-6) & (p < 1.0 - 1e-6)).sum() > 8  # the ncx2 series was exercised


@pytest.mark.parametrize("test", ["chi2", "lnr"])
def test_torch_backend_equals_numpy_given_the_same_noise(est, test, monkeypatch):
    torch = pytest.importorskip("torch")
    kwargs = {"budget": 2, "action": "free", "a_max": 0.05, "test": test, "on_detect": "end"}
    vec = _vec(est, 256, **kwargs).unwrapped
    tvec = _vec(est, 256, backend="torch", **kwargs).unwrapped
    noise = np.random.default_rng(3).standard_normal((256, est.m))
    monkeypatch.setattr(vec, "noise", lambda: noise.copy())
    monkeypatch.setattr(tvec, "noise", lambda: torch.as_tensor(noise))
    vec.reset(seed=0)
    tvec.reset(seed=0)
    actions = np.random.default_rng(4).uniform(-1, 1, (256, est.m)).astype(np.float32)
    out, tout = vec.step(actions), tvec.step(torch.as_tensor(actions))
    assert 0 < out[4]["detected"].sum() < 256
    for want, got in zip(out[:4], tout[:4], strict=True):
        np.testing.assert_allclose(_np(got), want, rtol=0, atol=1e-10)
    for key, want in out[4].items():
        np.testing.assert_allclose(_np(tout[4][key]), want, rtol=1e-10, atol=1e-10)


def test_torch_sampled_alarm_rate_matches_the_exact_probability(est):
    torch = pytest.importorskip("torch")
    a = np.zeros(est.m)
    a[0] = 0.06
    p = float(est.detection_probability(a))
    vec = _vec(est, 8000, budget=1, action="free", a_max=0.06, backend="torch")
    vec.reset(seed=5)
    actions = torch.as_tensor(np.tile((a / 0.06).astype(np.float32), (8000, 1)))
    _, rewards, _, _, infos = vec.step(actions)
    rate = float(infos["detected"].double().mean())
    assert abs(rate - p) < 4 * np.sqrt(p * (1 - p) / 8000)
    np.testing.assert_array_equal(_np(rewards) == 0.0, _np(infos["detected"]))


def test_torch_backend_refuses_numpy_actions_and_a_float_seed(est):
    torch = pytest.importorskip("torch")
    vec = _vec(est, 2, backend="torch")
    vec.reset()
    with pytest.raises(TypeError, match=r"attacker actions must be a torch\.Tensor"):
        vec.step(np.zeros((2, est.n), dtype=np.int8))
    with pytest.raises(ValueError, match="seed must be a non-negative int or None"):
        vec.reset(seed=1.5)
    _, _, terms, _, _ = vec.step(torch.zeros((2, est.n), dtype=torch.int8))
    assert terms.all()
    with pytest.raises(ValueError, match="backend must be one of"):
        _vec(est, 2, backend="jax")


@pytest.mark.parametrize("seed", [1.5, [1, 2], True, -1, "3"])
def test_numpy_backend_names_a_bad_seed(est, seed):
    vec = _vec(est, 2)
    with pytest.raises(ValueError, match="seed must be a non-negative int or None"):
        vec.reset(seed=seed)
    vec.reset(seed=np.int64(3))


def test_torch_ncx2_tail_equals_scipy():
    torch = pytest.importorskip("torch")
    from scipy import stats

    from fdia_env.stealth.torch_ops import ncx2_sf, ncx2_sf_series

    lam = np.concatenate([[0.0, 1e-12], np.geomspace(1e-8, 7e3, 300)])
    for dof in (1, 2, 21, 186):
        x = float(stats.chi2.isf(0.05, dof))
        want = stats.ncx2.sf(x, dof, lam)
        got = ncx2_sf_series(x, dof, torch.as_tensor(lam)).numpy()  # the other devices' series
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
        x_all = torch.full((lam.size,), x, dtype=torch.float64)
        on_cpu = ncx2_sf(x_all, dof, torch.as_tensor(lam))  # scipy's own figures
        assert on_cpu.dtype == torch.float64
        np.testing.assert_array_equal(on_cpu.numpy(), np.clip(want, 0.0, 1.0))


def test_defender_is_refused_by_the_native_vector_env(est):
    with pytest.raises(ValueError, match="plays the attacker alone"):
        _vec(est, 2, defender="threshold")


def _stacked(final, ended):
    """The ended members' rows of ``final_obs`` (numpy: an object array; torch: a tensor)."""
    rows = np.flatnonzero(_np(ended))
    return np.stack(list(final[rows])) if isinstance(final, np.ndarray) else _np(final)[rows]


@pytest.mark.parametrize(
    ("gym_id", "kwargs"),
    [
        (GYM_ID, {"budget": 3, "action": "free", "a_max": 0.05, "horizon": 4}),
        ("fdia_env/StealthDynamic-v0", {"action": "linear", "horizon": 4}),
    ],
)
def test_a_reset_mid_episode_equals_a_fresh_env(est, gym_id, kwargs):
    kwargs = kwargs | ({"scenario": est} if gym_id == GYM_ID else {})
    make = {"num_envs": 2, "vectorization_mode": "vector_entry_point", **kwargs}
    used, fresh = gym.make_vec(gym_id, **make), gym.make_vec(gym_id, **make)
    space = used.unwrapped.single_action_space
    acts = np.random.default_rng(5).uniform(-0.5, 0.5, (4, 2, *space.shape)).astype(np.float32)
    used.reset(seed=1)
    for a in acts[:2]:
        used.step(a)
    _assert_same_outputs(used.reset(seed=7), fresh.reset(seed=7))
    for a in acts[2:]:
        _assert_same_outputs(used.step(a), fresh.step(a))


def _assert_same_outputs(got, want):
    """Two envs' ``reset`` or ``step`` outputs are equal, the infos key by key."""
    for g, w in zip(got[:-1], want[:-1], strict=True):
        np.testing.assert_array_equal(g, w)
    assert set(got[-1]) == set(want[-1])
    for key, value in want[-1].items():
        np.testing.assert_array_equal(got[-1][key], value, err_msg=key)


@pytest.mark.parametrize(
    ("gym_id", "module"),
    [(GYM_ID, stealth_attack_v0), ("fdia_env/StealthDynamic-v0", stealth_dynamic_v0)],
)
def test_max_cycles_truncates_as_the_single_env_then_the_member_resets(est, gym_id, module):
    kwargs = {"horizon": 5, "max_cycles": 2, "dynamics": "expected"}
    kwargs |= {"scenario": est} if gym_id == GYM_ID else {}
    vec = gym.make_vec(gym_id, num_envs=3, vectorization_mode="vector_entry_point", **kwargs)
    single = module.parallel_env(**kwargs)
    vec.reset(seed=0)
    single.reset(seed=0)
    zero = np.zeros((3, *vec.unwrapped.single_action_space.shape), dtype=np.float32)
    flags = []
    for _ in range(3):  # two steps, then the next-step reset
        _, _, term, trunc, _ = vec.step(zero)
        flags.append((term.tolist(), trunc.tolist()))
    _, _, sterm, strunc, _ = single.step({"attacker": zero[0]})
    assert (sterm["attacker"], strunc["attacker"]) == (False, False)
    _, _, sterm, strunc, _ = single.step({"attacker": zero[0]})
    assert (sterm["attacker"], strunc["attacker"]) == (False, True)
    none, every = [False] * 3, [True] * 3
    assert flags == [(none, none), (none, every), (none, none)]  # the third: the reset step


@pytest.mark.parametrize("backend", ["numpy", "torch"])
@pytest.mark.parametrize(
    ("gym_id", "kwargs"),
    [
        (GYM_ID, {"budget": 5, "action": "free", "horizon": 2, "dynamics": "expected"}),
        ("fdia_env/StealthDynamic-v0", {"horizon": 3, "dynamics": "expected"}),
    ],
)
def test_same_step_autoreset_equals_next_step_and_a_manual_reset(est, gym_id, kwargs, backend):
    if backend == "torch":
        pytest.importorskip("torch")
    kwargs = kwargs | ({"scenario": est} if gym_id == GYM_ID else {})
    make = {"num_envs": 6, "vectorization_mode": "vector_entry_point", "backend": backend}
    same = gym.make_vec(gym_id, autoreset_mode=gym.vector.AutoresetMode.SAME_STEP, **make, **kwargs)
    ref = gym.make_vec(gym_id, **make, **kwargs)  # NEXT_STEP, reset by hand at each episode end
    assert same.metadata["autoreset_mode"] == gym.vector.AutoresetMode.SAME_STEP
    same.reset(seed=0)
    ref.reset(seed=0)
    space = same.unwrapped.single_action_space
    acts = np.random.default_rng(2).uniform(-0.3, 0.3, (7, 6, *space.shape)).astype(np.float32)
    ends = 0
    for a in acts:  # two whole episodes and part of a third
        a = a if backend == "numpy" else _tensor(a)
        obs, rew, term, trunc, info = same.step(a)
        robs, rrew, rterm, rtrunc, rinfo = ref.step(a)
        for got, want in zip((rew, term, trunc), (rrew, rterm, rtrunc), strict=True):
            np.testing.assert_array_equal(_np(got), _np(want))
        if not _np(rterm).any():
            np.testing.assert_array_equal(_np(obs), _np(robs))
            assert "final_obs" not in info
            continue
        ends += 1
        assert _np(rterm).all()  # expected dynamics, one horizon: every member ends together
        np.testing.assert_array_equal(_stacked(info["final_obs"], info["_final_obs"]), _np(robs))
        np.testing.assert_array_equal(_np(info["_final_info"]), _np(rterm))
        for key, want in rinfo.items():
            np.testing.assert_array_equal(_np(info["final_info"][key]), _np(want), err_msg=key)
        robs, rinfo = ref.reset()  # the manual reset the same-step mode does itself
        np.testing.assert_array_equal(_np(obs), _np(robs))
        assert _np(obs)[:, 0].tolist() == [1.0] * 6
        for key, want in rinfo.items():
            np.testing.assert_array_equal(_np(info[key]), _np(want), err_msg=key)
    assert ends == len(acts) // kwargs["horizon"]


@pytest.mark.parametrize("backend", ["numpy", "torch"])
def test_same_step_autoreset_restarts_only_the_members_that_ended(est, backend):
    if backend == "torch":
        pytest.importorskip("torch")
    vec = _vec(
        est,
        512,
        budget=3,
        action="free",
        a_max=0.05,
        horizon=4,
        on_detect="end",
        backend=backend,
        autoreset_mode="SameStep",
    )
    vec.reset(seed=1)
    a = np.full((512, est.m), 0.4, dtype=np.float32)
    a = a if backend == "numpy" else _tensor(a)
    k = np.zeros(512, dtype=np.int64)  # each member's step within its episode
    partial = 0
    for _ in range(9):
        obs, rew, term, trunc, info = vec.step(a)
        ended, k = _np(term) | _np(trunc), k + 1
        final = _np(info["final_info"]["detected"]) if ended.any() else np.zeros(512, bool)
        np.testing.assert_array_equal(ended, final | (k >= 4))  # an alarm or the horizon
        assert not _np(rew)[~ended & _np(info["detected"])].any()  # live members: no alarm
        if ended.any():
            last = _stacked(info["final_obs"], info["_final_obs"])
            np.testing.assert_allclose(last[:, 0], (4 - k[ended]) / 4)
            assert (_np(info["final_info"]["step"])[ended] == k[ended]).all()
        partial += 0 < ended.sum() < 512
        k[ended] = 0
        np.testing.assert_array_equal(_np(info["step"]), k)
        np.testing.assert_allclose(_np(obs)[:, 0], (4 - k) / 4)
        assert _np(obs)[ended, 1:].tolist() == [[0.0, 0.0]] * int(ended.sum())
    assert partial >= 3  # members ended at different steps (alarms) and restarted alone


def test_autoreset_mode_disabled_is_a_value_error_naming_it(est):
    with pytest.raises(ValueError, match="autoreset_mode must be"):
        _vec(est, 2, autoreset_mode=gym.vector.AutoresetMode.DISABLED)


@pytest.mark.parametrize("env_id", [GYM_ID, "fdia_env/StealthDynamic-v0"])
def test_train_py_torch_ppo_trains_on_the_stealth_envs(tmp_path, env_id):
    # before: train.py knew no stealth env, and their vector envs refused SAME_STEP autoreset
    pytest.importorskip("torch")
    import json

    import train

    args = ["attacker", "--env", env_id, "--algo", "torch-ppo", "--num-envs", "8"]
    args += ["--total-timesteps", "200", "--eval-freq", "0", "--final-eval-episodes", "3"]
    result = train.main([*args, "--no-progress-bar", "--runs-root", str(tmp_path)])
    assert result.timesteps == 288  # 3 iterations of 8 members x 12 steps
    scores = json.loads((result.run_dir / "scores.json").read_text())
    assert (result.run_dir / "model.json").is_file()
    learned = scores["evaluations"]["learned (torch-ppo)"]
    assert learned["env_id"] == env_id and learned["n_episodes"] == 3
    assert np.isfinite(learned["mean"]) and learned["mean"] >= 0.0  # damage or 0 when caught
    assert learned["reference"] is None  # train.py has no reference for the stealth envs
