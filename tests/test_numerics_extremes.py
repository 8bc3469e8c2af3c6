"""Rewards and infos at the extremes of every accepted parameter (exact, finite, or refused)."""

import gymnasium as gym
import numpy as np
import pytest

from baselines.covariance import det_optimal
from fdia_env import covariance_attack_v0
from fdia_env.stealth import stealth_attack_v0

torch = pytest.importorskip("torch")

COV_ID = "fdia_env/CovarianceAttack-v0"


def _covariance_rewards(power: float, actions: list[np.ndarray], backend: str) -> np.ndarray:
    """The logdet rewards of ``actions`` (one member each) in ch2-position at ``power``."""
    kw = {"scenario": "ch2-position", "power": power, "objective": "logdet"}
    if backend == "single":
        out = []
        for a in actions:
            env = covariance_attack_v0.parallel_env(**kw)
            env.reset(seed=0)
            out.append(env.step({"attacker": a})[1]["attacker"])
        return np.array(out)
    env = gym.make_vec(
        COV_ID,
        num_envs=len(actions),
        vectorization_mode="vector_entry_point",
        backend=backend,
        **kw,
    )
    env.reset(seed=0)
    batch = np.stack(actions).astype(np.float32)
    if backend == "torch":
        batch = torch.as_tensor(batch)
    reward = env.step(batch)[1]
    return np.asarray(reward.numpy() if backend == "torch" else reward, dtype=np.float64)


@pytest.mark.parametrize("backend", ["single", "numpy", "torch"])
@pytest.mark.parametrize("power", [3e3, 1e10, 1e20, 1e30, 1e100, 1e300])
def test_logdet_covariance_rewards_are_exact_and_never_beat_the_certified_optimum(power, backend):
    """det_optimal's policy earns its value; no action (all ones, random) earns more.

    Summing P and a rank-one W Σ W' of 1e20 loses P's small eigenvalue (log det −inf, or
    above the optimum at 1e30 and on torch).
    """
    best = det_optimal("ch2-position", power)
    env = covariance_attack_v0.parallel_env(scenario="ch2-position", power=power)
    optimal = env.attack.sigma_to_action(best.sigma)
    rng = np.random.default_rng(0)
    others = [np.ones(3), -np.ones(3), np.array([1.0, -1.0, 1.0])]
    others += [rng.uniform(-1, 1, 3) for _ in range(5)]
    others += [np.array([1.0, 0.75, 0.0]) * s for s in (1.0, 1.0 - 1e-7, 1.0 + 1e-7)]
    others = [np.clip(a, -1, 1).astype(np.float32) for a in others]
    rewards = _covariance_rewards(power, [optimal, *others], backend)
    assert np.isfinite(rewards).all()
    np.testing.assert_allclose(rewards[0], best.value, rtol=1e-13)
    assert (rewards[1:] <= best.value * (1 + 1e-13)).all(), (rewards, best.value)


# --- the non-central χ² tail far out ------------------------------------------------------------

mpmath = pytest.importorskip("mpmath")


def _mp_ncx2_miss(x: float, dof: int, lam: float) -> "mpmath.mpf":
    """``P[χ²_dof(λ) ≤ x]`` to 40 digits by its Poisson mixture (moderate λ)."""
    with mpmath.workdps(40):
        mu, y, a = mpmath.mpf(lam) / 2, mpmath.mpf(x) / 2, mpmath.mpf(dof) / 2
        # past j ≈ 3 sqrt(μ y) + 3 y each term is below a ninth of the last (P(a + j, y) falls
        # as y^j / j!), past μ + 40 sqrt(μ) the Poisson weights are nothing
        mu_f, y_f = lam / 2, x / 2
        top = int(min(mu_f + 40 * np.sqrt(mu_f), 3 * np.sqrt(mu_f * y_f) + 3 * y_f + dof) + 200)
        return mpmath.fsum(
            mpmath.exp(j * mpmath.log(mu) - mu - mpmath.loggamma(j + 1) if j else -mu)
            * mpmath.gammainc(a + j, 0, y, regularized=True)
            for j in range(top)
        )


def _mp_ncx2_miss_bound(x: float, dof: int, lam: float) -> "mpmath.mpf":
    """An upper bound of ``P[χ²_dof(λ) ≤ x]`` at any λ (40 digits).

    ``P(a + j, y) ≤ y^{a+j} / Γ(a + j + 1) ≤ y^a / Γ(a + 1) · y^j / j!`` in the Poisson
    mixture gives ``e^{−μ} y^a / Γ(a + 1) · I₀(2 sqrt(μ y))``.
    """
    with mpmath.workdps(40):
        mu, y, a = mpmath.mpf(lam) / 2, mpmath.mpf(x) / 2, mpmath.mpf(dof) / 2
        return (
            mpmath.exp(-mu)
            * y**a
            / mpmath.gamma(a + 1)
            * mpmath.besseli(0, 2 * mpmath.sqrt(mu * y))
        )


@pytest.mark.parametrize(("x", "dof"), [(12.591587243743977, 6), (55.75847927888702, 40)])
def test_ncx2_tail_matches_mpmath_up_to_its_far_tail(x, dof):
    """scipy's range to 1e-14, and 1.0 exactly past it, where scipy gives NaN (λ ≥ ~1e19)."""
    from fdia_env.stealth.tails import ncx2_sf

    moderate = [0.0, 1.0, 40.0, 400.0, 3000.0, 12000.0]
    got = ncx2_sf(x, dof, np.array(moderate))
    want = [float(1 - _mp_ncx2_miss(x, dof, lam)) for lam in moderate]
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-14)
    huge = [1e19, 3.3e19, 1e30, 1e300, np.inf]
    got = ncx2_sf(x, dof, np.array(huge))
    assert got.tolist() == [1.0] * len(huge)
    for lam in huge[:-1]:  # the miss probability is far below a double's last digit at 1.0
        assert _mp_ncx2_miss_bound(x, dof, lam) < mpmath.mpf(2) ** -60
    got_t = torch_ncx2(x, dof, moderate + huge)
    np.testing.assert_allclose(got_t, want + [1.0] * len(huge), rtol=0, atol=1e-14)


def torch_ncx2(x: float, dof: int, lams: list[float]) -> np.ndarray:
    """The torch backend's tail on the CPU (scipy) and by its series (the other devices)."""
    from fdia_env.stealth.torch_ops import ncx2_sf, ncx2_sf_series

    lam = torch.tensor(lams, dtype=torch.float64)
    cpu = ncx2_sf(x, dof, lam).numpy()
    series = ncx2_sf_series(x, dof, lam[lam < 1e5])
    np.testing.assert_allclose(series.numpy(), cpu[: len(series)], rtol=0, atol=1e-13)
    return cpu


def _mp_mixture_cdf_small(weights: list[float], x: float) -> float:
    """``P[Σ w_i χ²₁ <= x]`` for x far below every weight (40 digits, relative error (x/w)²).

    The Laplace transform ``Π (1 + 2 w_i t)^{−1/2} = (2t)^{−m/2} Π w_i^{−1/2} (1 − Σ 1/(4 w_i t)
    + O(t⁻²))`` inverts term by term to ``Π w_i^{−1/2} 2^{−m/2} (x^{m/2} / Γ(m/2 + 1) −
    Σ 1/(4 w_i) x^{m/2+1} / Γ(m/2 + 2))``.
    """
    with mpmath.workdps(40):
        w = [mpmath.mpf(v) for v in weights]
        y, h = mpmath.mpf(x), mpmath.mpf(len(w)) / 2
        lead = y**h / mpmath.gamma(h + 1) - sum(1 / (4 * v) for v in w) * y ** (h + 1) / (
            mpmath.gamma(h + 2)
        )
        return float(lead / (mpmath.sqrt(mpmath.fprod(w)) * 2**h))


def test_linear_attack_detection_probability_is_exact_when_the_weights_dwarf_the_threshold():
    """The linear attack's weighted χ²₁ tail: Imhof's integral in float gave 0.677 for ~1.

    Weights 1e9 to 1e10 times the threshold put it far in the lower tail; the answer is then
    1 − 4.86e-14 (and 1.0 exactly for weights of 1e200).
    """
    from fdia_env.detection.gchisq import gchisq_cdf
    from fdia_env.stealth.dynamic_model import chi2_mix_sf

    weights = [1e10, 3e9, 2e9]
    lower = _mp_mixture_cdf_small(weights, 12.6)
    assert abs(chi2_mix_sf(weights, 12.6) - (1.0 - lower)) < 2e-16
    assert float(gchisq_cdf(12.6, weights)) == pytest.approx(lower, rel=1e-12)
    assert chi2_mix_sf([1e200, 1.0, 2.0], 12.6) == 1.0
    assert chi2_mix_sf([1e10, 3e9, 1.0], 12.6) > 0.9999716779076895  # P[1e10 χ²₁ > 12.6]


STEALTH_DYNAMIC_ID = "fdia_env/StealthDynamic-v0"


@pytest.mark.parametrize("backend", ["single", "numpy", "torch"])
@pytest.mark.parametrize(
    ("a_max", "dynamics"), [(3e9, "expected"), (1e10, "sampled"), (1e15, "expected")]
)
def test_stealth_dynamic_detection_probability_is_one_past_scipys_range(a_max, dynamics, backend):
    """A bias of 3e9 innovation deviations is detected with probability 1.0 (scipy: NaN)."""
    from fdia_env.stealth import stealth_dynamic_v0

    kw = {"a_max": a_max, "dynamics": dynamics, "horizon": 3}
    if backend == "single":
        env = stealth_dynamic_v0.parallel_env(**kw)
        env.reset(seed=0)
        steps = []
        for _ in range(3):
            act = np.ones(env.action_space("attacker").shape, np.float32)
            _, rew, _, _, info = env.step({"attacker": act})
            steps.append((rew["attacker"], info["attacker"]["detection_probability"]))
        rewards, p = (np.array(v, dtype=np.float64) for v in zip(*steps, strict=True))
    else:
        env = gym.make_vec(
            STEALTH_DYNAMIC_ID,
            num_envs=2,
            vectorization_mode="vector_entry_point",
            backend=backend,
            **kw,
        )
        env.reset(seed=0)
        rewards, p = [], []
        for _ in range(3):
            act = np.ones((2, *env.single_action_space.shape), np.float32)
            _, rew, _, _, info = env.step(torch.as_tensor(act) if backend == "torch" else act)
            rewards.append(np.asarray(rew.numpy() if backend == "torch" else rew))
            q = info["detection_probability"]
            p.append(np.asarray(q.numpy() if backend == "torch" else q))
        rewards, p = np.array(rewards, dtype=np.float64), np.array(p)
    assert (p == 1.0).all(), p
    assert np.isfinite(rewards).all()
    if dynamics == "expected":  # (1 − p) · phi + p · 0 with p = 1: nothing
        assert (rewards == 0.0).all(), rewards


# --- stealthy injections of any size; scales refused past float64's reach ----------------------

STEALTH_ID = "fdia_env/StealthAttack-v0"


def _stealth_statistics(magnitude: float, backend: str, test: str) -> tuple[np.ndarray, np.ndarray]:
    """(statistic, detected) of 6 sampled steps of the all-ones shift (an undetectable a = H c)."""
    kw = {"magnitude": magnitude, "test": test, "horizon": 6}
    if backend == "single":
        env = stealth_attack_v0.parallel_env(**kw)
        env.reset(seed=3)
        out = []
        for _ in range(6):
            act = np.ones(env.action_space("attacker").shape, np.int8)
            info = env.step({"attacker": act})[4]["attacker"]
            out.append((info["statistic"], info["detected"]))
        stat, det = zip(*out, strict=True)
        return np.array(stat), np.array(det)
    env = gym.make_vec(
        STEALTH_ID, num_envs=2, vectorization_mode="vector_entry_point", backend=backend, **kw
    )
    env.reset(seed=3)
    stat, det = [], []
    for _ in range(6):
        act = np.ones((2, *env.single_action_space.shape), np.int8)
        info = env.step(torch.as_tensor(act) if backend == "torch" else act)[4]
        stat.append(
            np.asarray(info["statistic"].numpy() if backend == "torch" else info["statistic"])
        )
        d = info["detected"]
        det.append(np.asarray(d.numpy() if backend == "torch" else d))
    return np.array(stat), np.array(det)


@pytest.mark.parametrize("test", ["chi2", "lnr"])
@pytest.mark.parametrize("backend", ["single", "numpy", "torch"])
def test_an_undetectable_shift_is_undetectable_at_every_magnitude(backend, test):
    """a = H c leaves the residual unchanged: the same statistic and alarms at 0.05 and 1e100.

    The residual of e + a carried a's rounding, |a| · 1e-16: from a magnitude of ~1e12 it raised
    the alarm on its own (always at 1e13).
    """
    want_stat, want_det = _stealth_statistics(0.05, backend, test)
    for magnitude in (1e13, 1e40, 1e100):
        stat, det = _stealth_statistics(magnitude, backend, test)
        np.testing.assert_allclose(stat, want_stat, rtol=1e-12)
        np.testing.assert_array_equal(det, want_det)


@pytest.mark.parametrize(
    ("module", "name", "kwargs"),
    [
        ("stealth_attack_v0", "magnitude", {}),
        ("stealth_attack_v0", "a_max", {"action": "free"}),
        ("stealth_dynamic_v0", "a_max", {}),
        ("stealth_dynamic_v0", "b_max", {"action": "linear"}),
    ],
)
def test_scales_past_float64s_reach_are_refused_by_name(module, name, kwargs):
    """1e300 overflowed the squared statistic and phi to inf; 1e100 is the largest accepted."""
    from fdia_env.stealth import stealth_attack_v0, stealth_dynamic_v0

    make = {"stealth_attack_v0": stealth_attack_v0, "stealth_dynamic_v0": stealth_dynamic_v0}
    build = make[module].parallel_env
    with pytest.raises(
        ValueError, match=rf"{name} must satisfy 0 < {name} <= 1e\+100, got 1e\+300"
    ):
        build(**kwargs, **{name: 1e300})
    env = build(**kwargs, **{name: 1e100}, horizon=2)
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    for _ in range(2):
        space = env.action_space("attacker")
        act = np.ones(space.shape, space.dtype) if rng.random() < 0.5 else space.sample()
        _, rewards, _, _, infos = env.step({"attacker": act})
        assert np.isfinite(rewards["attacker"])
        assert all(
            np.isfinite(v).all()
            for v in infos["attacker"].values()
            if np.asarray(v).dtype.kind == "f"
        ), infos


def test_linear_gain_spread_past_float64s_reach_is_refused_by_name():
    """t_max = 1e8 rounded the innovation law's small eigenvalues to 0: a KL of +inf."""
    from fdia_env.stealth import stealth_dynamic_v0

    with pytest.raises(ValueError, match=r"t_max must satisfy 0 < t_max <= 1e\+06, got 1e\+08"):
        stealth_dynamic_v0.parallel_env(action="linear", t_max=1e8)


# --- every scale parameter over its whole accepted range ----------------------------------------

from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

from fdia_env import detection_game_v0, sensor_game_v0  # noqa: E402
from fdia_env.stealth import stealth_dynamic_v0  # noqa: E402

LOG_UNIFORM = st.floats(-300.0, 300.0).map(lambda e: 10.0**e)  # 1e-300 .. 1e300
RATE = st.floats(-300.0, -1e-12).map(lambda e: 10.0**e)  # a probability in (0, 1)

CASES = {  # module, the env's gym id of the native vector env (None: none), kwargs strategies
    "covariance_attack_v0": (
        covariance_attack_v0,
        COV_ID,
        {
            "scenario": st.sampled_from(["ch2-position", "ch2-pv-2", "ch4-position"]),
            "power": LOG_UNIFORM,
            "objective": st.sampled_from(["trace", "logdet"]),
            "structure": st.sampled_from(["full", "diagonal"]),
            "power_mode": st.sampled_from(["per_step", "budget"]),
            "horizon": st.integers(1, 3),
        },
    ),
    "detection_game_v0": (
        detection_game_v0,
        "fdia_env/DetectionDefender-v0",
        {
            "scenario": st.sampled_from(["ch3-static", "ch3-tracking"]),
            "power": LOG_UNIFORM,
            "statistic": st.sampled_from(["quadratic", "chi2"]),
            "on_detect": st.sampled_from(["discard", "incorporate"]),
            "criterion": st.sampled_from(["mse", "bayes_cost"]),
            "dynamics": st.sampled_from(["expected", "sampled"]),
        },
    ),
    "sensor_game_v0": (sensor_game_v0, "fdia_env/SensorGameAttacker-v0", {"power": LOG_UNIFORM}),
    "stealth_attack_v0": (
        stealth_attack_v0,
        "fdia_env/StealthAttack-v0",
        {
            "scenario": st.just("grid-ieee14"),
            "action": st.sampled_from(["shift", "box_shift", "free"]),
            "magnitude": LOG_UNIFORM,
            "a_max": LOG_UNIFORM,
            "alpha": RATE,
            "penalty": LOG_UNIFORM,
            "on_detect": st.sampled_from(["zero", "penalty"]),
            "dynamics": st.sampled_from(["sampled", "expected"]),
        },
    ),
    "stealth_dynamic_v0": (
        stealth_dynamic_v0,
        STEALTH_DYNAMIC_ID,
        {
            "action": st.sampled_from(["bias", "linear"]),
            "a_max": LOG_UNIFORM,
            "t_max": LOG_UNIFORM,
            "b_max": LOG_UNIFORM,
            "alpha": RATE,
            "penalty": LOG_UNIFORM,
            "on_detect": st.sampled_from(["zero", "penalty"]),
            "dynamics": st.sampled_from(["sampled", "expected"]),
            "horizon": st.integers(1, 4),
        },
    ),
}


def assert_finite_tree(value, where: str) -> None:
    """Every float in ``value`` (dicts, sequences, arrays, tensors) is finite."""
    if isinstance(value, dict):
        for key, item in value.items():
            if key != "threshold" or np.asarray(item).dtype.kind != "f":
                assert_finite_tree(item, f"{where}[{key!r}]")
            else:  # the detector's τ: +inf exactly where its action is 1 (never detects)
                assert not np.isnan(np.asarray(item, dtype=np.float64)).any(), where
        return
    if isinstance(value, (list, tuple)):
        for i, item in enumerate(value):
            assert_finite_tree(item, f"{where}[{i}]")
        return
    if isinstance(value, torch.Tensor):
        value = value.cpu().numpy()
    arr = np.asarray(value)
    if arr.dtype.kind in "fc":
        assert np.isfinite(arr).all(), f"{where} = {value!r}"


def _actions(space, rng: np.random.Generator, k: int) -> np.ndarray:
    """Step k's action: the space's corners first (all high, all low), then random draws."""
    if isinstance(space, gym.spaces.Box):
        if k < 2:
            return np.full(space.shape, space.high if k == 0 else space.low, dtype=space.dtype)
        return rng.uniform(space.low, space.high).astype(space.dtype)
    if isinstance(space, gym.spaces.MultiBinary):
        return (
            np.full(space.shape, 1 - k % 2, dtype=space.dtype)
            if k < 2
            else (rng.integers(0, 2, space.shape).astype(space.dtype))
        )
    if isinstance(space, gym.spaces.Discrete):
        return np.int64(space.start + (space.n - 1 if k == 0 else rng.integers(space.n)))
    return space.sample()


def _refused(exc: ValueError, kwargs: dict) -> None:
    """A refusal names one of the parameters given."""
    assert any(name in str(exc) for name in kwargs), (str(exc), kwargs)


def _run_parallel(module, kwargs: dict, seed: int) -> None:
    try:
        env = module.parallel_env(**kwargs)
    except ValueError as exc:
        _refused(exc, kwargs)
        return
    rng = np.random.default_rng(seed)
    _, infos = env.reset(seed=seed)
    assert_finite_tree(infos, "reset info")
    for k in range(4):
        actions = {a: _actions(env.action_space(a), rng, k) for a in env.agents}
        _, rewards, term, trunc, infos = env.step(actions)
        assert_finite_tree(rewards, f"step {k} reward")
        assert_finite_tree(infos, f"step {k} info")
        if any(term.values()) or any(trunc.values()) or not env.agents:
            _, infos = env.reset(seed=seed + k + 1)


def _run_vector(env_id: str, kwargs: dict, seed: int, backend: str) -> None:
    try:
        env = gym.make_vec(
            env_id, num_envs=3, vectorization_mode="vector_entry_point", backend=backend, **kwargs
        )
    except ValueError as exc:
        _refused(exc, kwargs)
        return
    rng = np.random.default_rng(seed)
    _, infos = env.reset(seed=seed)
    assert_finite_tree(infos, "reset info")
    space = env.single_action_space
    for k in range(3):
        batch = np.stack([_actions(space, rng, k + j) for j in range(3)])
        if backend == "torch":
            batch = torch.as_tensor(batch)
        _, rewards, _, _, infos = env.step(batch)
        assert_finite_tree(rewards, f"step {k} reward")
        assert_finite_tree(infos, f"step {k} info")


@pytest.mark.filterwarnings("ignore")
@pytest.mark.parametrize("name", list(CASES))
@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data(), seed=st.integers(0, 2**16))
def test_extreme_parameters_give_a_named_error_or_finite_rewards_and_infos(name, data, seed):
    """Log-uniform scales over 1e-300..1e300 in every env: refused by name, or all finite."""
    module, _, strategies = CASES[name]
    kwargs = data.draw(st.fixed_dictionaries(strategies), label="kwargs")
    _run_parallel(module, kwargs, seed)


@pytest.mark.filterwarnings("ignore")
@pytest.mark.parametrize("backend", ["numpy", "torch"])
@pytest.mark.parametrize("name", list(CASES))
@settings(max_examples=5, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data(), seed=st.integers(0, 2**16))
def test_extreme_parameters_in_native_vector_envs(name, backend, data, seed):
    """The same on the native vector env's numpy and torch backends."""
    _, env_id, strategies = CASES[name]
    kwargs = data.draw(st.fixed_dictionaries(strategies), label="kwargs")
    if (
        name == "detection_game_v0"
        and kwargs["dynamics"] == "expected"
        and (kwargs["scenario"] == "ch3-tracking")
    ):
        kwargs["horizon"] = 1
    _run_vector(env_id, kwargs, seed, backend)


@pytest.mark.parametrize("k", [-990, 0, 33, 66, 500, 990])
def test_two_state_log_det_of_a_sum_matches_mpmath(k):
    """logdet_sum2 (the engine's 2-state log det of P + B) against an exact determinant (mpmath).

    B is exactly rank one in float64 (integer vectors times 2^k) or a multiple of I; the sum
    P + B in float64 loses P's part across B's null direction from 2^50 on.
    """
    from fdia_env.kalman.linalg import logdet_sum2

    rng = np.random.default_rng(1)
    A = rng.standard_normal((6, 2, 2))
    P = A @ A.swapaxes(1, 2) + 0.1 * np.eye(2)
    v = np.array([[3.0, 1.0], [1.0, -2.0], [0.0, 0.0], [5.0, 4.0], [1.0, 0.0], [2.0, 7.0]])
    S = np.einsum("bi,bj->bij", v, v) * 2.0**k
    S[2] = 2.0**k * np.eye(2)
    S[1] += 2.0 ** (k - 10) * np.eye(2)
    want = []
    with mpmath.workprec(2400):  # P + B and its determinant exactly (entries up to 2^993)
        for p, s in zip(P, S, strict=True):
            m = [[mpmath.mpf(p[i, j]) + mpmath.mpf(s[i, j]) for j in range(2)] for i in range(2)]
            want.append(float(mpmath.log(m[0][0] * m[1][1] - m[0][1] * m[1][0])))
    got = logdet_sum2(P, S)
    np.testing.assert_allclose(got, want, rtol=1e-14, atol=1e-13)
    got_t = logdet_sum2(torch.as_tensor(P), torch.as_tensor(S)).numpy()
    np.testing.assert_allclose(got_t, want, rtol=1e-14, atol=1e-13)


@pytest.mark.parametrize("power", [1e-300, 1.0, 1e300])
def test_the_detection_threshold_is_infinite_only_at_the_never_detect_action(power):
    from fdia_env import detection_game_v0

    for a, infinite in ((1.0, True), (np.nextafter(np.float32(1), np.float32(0)), False)):
        env = detection_game_v0.parallel_env(scenario="ch3-static", power=power)
        env.reset(seed=0)
        attack = np.zeros(env.action_space("attacker").shape, dtype=np.float32)
        defend = np.array([a], dtype=np.float32)
        _, rewards, _, _, infos = env.step({"attacker": attack, "defender": defend})
        assert np.isinf(infos["defender"]["threshold"]) == infinite
        assert all(np.isfinite(r) for r in rewards.values())
