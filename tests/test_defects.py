"""Regression tests for defects found under hostile and clumsy input.

Each test is the reproduction of one defect: it failed before the fix and passes after.
"""

import numpy as np
import pytest

from baselines.covariance import det_optimal, kkt_residuals, water_filling
from fdia_env.systems import position_sensor, pv_sensor, tracking_system

# --- water-filling at tiny powers and with negative gains -------------------------------------


@pytest.mark.parametrize("power", [1e-300, 1e-20, 1e-12])
def test_det_optimal_at_a_tiny_power_spends_exactly_that_power(power):
    # a level a² + 1/ξ₁ rounds to 1/ξ₁: no direction was active and water_filling raised
    # IndexError
    result = det_optimal("ch2-position", power=power)
    s = result.info["s"]
    assert s.sum() == pytest.approx(power, rel=1e-12)
    assert np.count_nonzero(s) == 1  # all power on the largest gain
    assert kkt_residuals(result).worst < 1e-9


@pytest.mark.parametrize("power", [1e-20, 1e-300])
def test_water_filling_at_a_tiny_power_fills_the_largest_gain_only(power):
    s, level = water_filling(np.array([0.25, 1.0, 0.5]), power)
    assert s.tolist() == [0.0, power, 0.0]
    assert level == 1.0  # 1/ξ_max; a² is below its resolution


@pytest.mark.parametrize("xi", [[1.0, -0.5], [-1e-17, 2.0], [-1.0]])
def test_water_filling_refuses_negative_gains_by_name(xi):
    with pytest.raises(ValueError, match="xi must be non-negative"):
        water_filling(np.array(xi), 1.0)


# --- AEC: a bad action is refused on its own turn; the env is never stuck ----------------------

AEC_GAMES = ["sensor_game_v0", "detection_game_v0"]


def _aec(name: str, **kwargs):
    import importlib

    env = importlib.import_module(f"fdia_env.{name}").env(**kwargs)
    for agent in env.possible_agents:
        env.action_space(agent).seed(0)  # the samples below are reproducible
    return env


@pytest.mark.parametrize("name", AEC_GAMES)
@pytest.mark.parametrize("bad", [-1, None, "0", 1.5, [0, 0]])
def test_aec_bad_attacker_action_is_refused_on_the_attackers_turn(name, bad):
    env = _aec(name)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="attacker action"):
        env.step(bad)
    assert env.agent_selection == "attacker"  # nothing stored, nothing advanced
    env.step(env.action_space("attacker").sample())
    assert env.agent_selection == "defender"
    env.step(env.action_space("defender").sample())  # the round completes
    assert env.agent_selection == "attacker"
    assert np.isfinite(env.rewards["attacker"])


@pytest.mark.parametrize("name", AEC_GAMES)
def test_aec_bad_defender_action_names_the_defender(name):
    env = _aec(name)
    env.reset(seed=0)
    env.step(env.action_space("attacker").sample())
    with pytest.raises(ValueError, match="defender action"):
        env.step(-1)
    assert env.agent_selection == "defender"
    env.step(env.action_space("defender").sample())
    assert env.agent_selection == "attacker"


def test_aec_round_refused_by_a_game_rule_restarts_from_the_first_agent():
    # an over-budget attack with illegal_action="error" passes the space check and is refused
    # by the parallel step on the defender's turn: the round restarts instead of refusing
    # every later defender action
    env = _aec(
        "fdia_v0",
        attack_kwargs={"illegal_action": "error", "budget": 1},
        defense="sensor_selection",
    )
    env.reset(seed=0)
    env.step(0b011)  # two sensors, budget 1
    with pytest.raises(ValueError, match="illegal") as info:
        env.step(0)
    assert "acts again" in "".join(getattr(info.value, "__notes__", []))
    assert env.agent_selection == "attacker"
    env.step(0b001)
    env.step(0)
    assert env.agent_selection == "attacker"
    assert env.unwrapped.sim.k == 1  # exactly one window step was taken


@pytest.mark.parametrize("name", [*AEC_GAMES, "fdia_v0"])
def test_aec_step_after_the_episode_or_before_reset_raises_runtime_error(name):
    env = _aec(name)
    with pytest.raises(RuntimeError, match="before reset"):
        env.step(0)
    env.reset(seed=0)
    for agent in env.agent_iter():
        _, _, terminated, truncated, _ = env.last()
        env.step(None if terminated or truncated else env.action_space(agent).sample())
    with pytest.raises(RuntimeError, match="after the episode ended"):
        env.step(env.action_space("attacker").sample())
    env.reset(seed=1)  # still usable
    assert env.agent_selection == "attacker"


# --- silent coercions: actions and options are what Gymnasium's spaces accept ----------------


def _single(env_id: str, **kwargs):
    import gymnasium as gym

    import fdia_env  # noqa: F401 - registers the ids

    env = gym.make(env_id, **kwargs)
    env.reset(seed=0)
    return env


def _vector(env_id: str, num_envs: int = 2, **kwargs):
    import gymnasium as gym

    import fdia_env  # noqa: F401 - registers the ids

    venv = gym.make_vec(
        env_id, num_envs=num_envs, vectorization_mode="vector_entry_point", **kwargs
    )
    venv.reset(seed=0)
    return venv


@pytest.mark.parametrize("env_id", ["fdia_env/SparseAttack-v0", "fdia_env/SensorGameAttacker-v0"])
@pytest.mark.parametrize("action", [np.array([1]), np.array([[1]]), np.array([1.0]), 1.0])
def test_single_env_discrete_action_is_an_integer_not_a_shape_1_array_or_float(env_id, action):
    env = _single(env_id)
    assert not env.action_space.contains(action)  # Gymnasium's own rule
    with pytest.raises(ValueError, match="attacker action must be an integer"):
        env.step(action)
    env.step(np.int64(1))  # still usable; numpy integers and 0-d integer arrays are fine
    env.reset(seed=1)
    env.step(np.array(0))


@pytest.mark.parametrize("actions", [np.array([1.0, 0.0]), np.array([1.0, 0.0], np.float32)])
def test_vector_env_refuses_float_discrete_actions_as_the_single_env_does(actions):
    venv = _vector("fdia_env/SparseAttack-v0")
    with pytest.raises(ValueError, match="attacker actions must be integers"):
        venv.step(actions)
    venv.step(actions.astype(np.int64))  # still usable


@pytest.mark.parametrize("env_id", ["fdia_env/SparseAttack-v0", "fdia_env/CovarianceAttack-v0"])
def test_one_player_envs_refuse_an_opponent_instead_of_ignoring_it(env_id):
    import gymnasium as gym

    from fdia_env.envs.opponents import FixedMix

    for make in (gym.make, lambda i, **kw: gym.make_vec(i, num_envs=2, **kw)):
        with pytest.raises(ValueError, match="opponent must be None: this env has a single"):
            make(env_id, opponent=FixedMix.uniform(3))


@pytest.mark.parametrize("k", [4, 99])
def test_sensor_game_max_subset_size_above_m_is_refused(k):
    from fdia_env import sensor_game_v0

    with pytest.raises(ValueError, match=r"max_subset_size must be in \[1, M = 3\]"):
        sensor_game_v0.parallel_env(max_subset_size=k)
    full = sensor_game_v0.parallel_env(max_subset_size=3)  # k = M: every subset, as None
    assert full.action_space("attacker") == sensor_game_v0.parallel_env().action_space("attacker")


# --- MultiBinary accepts 0/1 of any numeric dtype, single and vector envs ----------------------

MB_ACTIONS = [
    np.array([1.0, 0.0, 1.0]),  # float64, as stable-baselines3's PPO and A2C emit
    np.array([1.0, 0.0, 1.0], dtype=np.float32),
    np.array([1, 0, 1], dtype=np.uint8),
    np.array([True, False, True]),
]


@pytest.mark.parametrize("action", MB_ACTIONS, ids=lambda a: str(a.dtype))
def test_multibinary_single_env_accepts_0_1_of_any_numeric_dtype(action):
    env = _single("fdia_env/SparseAttack-v0", action="multibinary")
    assert env.action_space.contains(action)
    _, _, _, _, info = env.step(action)
    assert info["attacked"].tolist() == [1, 0, 1]
    with pytest.raises(ValueError, match="0/1 array"):
        env.step(np.array([0.5, 0.0, 0.0]))


@pytest.mark.parametrize("action", MB_ACTIONS, ids=lambda a: str(a.dtype))
def test_multibinary_vector_env_accepts_0_1_of_any_numeric_dtype(action):
    venv = _vector("fdia_env/SparseAttack-v0", action="multibinary")
    batch = np.stack([action, np.zeros_like(action)])
    _, _, _, _, info = venv.step(batch)
    assert info["attacked"].tolist() == [[1, 0, 1], [0, 0, 0]]
    with pytest.raises(ValueError, match="0/1"):
        venv.step(np.full((2, 3), 0.5))


@pytest.mark.parametrize("dtype", ["float32", "float64", "int64", "bool"])
def test_multibinary_torch_vector_env_accepts_0_1_of_any_real_dtype(dtype):
    torch = pytest.importorskip("torch")
    venv = _vector("fdia_env/SparseAttack-v0", action="multibinary", backend="torch")
    batch = torch.tensor([[1, 0, 1], [0, 1, 0]]).to(getattr(torch, dtype))
    _, _, _, _, info = venv.step(batch)
    assert info["attacked"].tolist() == [[1, 0, 1], [0, 1, 0]]
    with pytest.raises(ValueError, match="must be 0/1"):
        venv.step(torch.full((2, 3), 0.5))


# --- the detection game at every power up to 1e300, on the tracking scenario too ---------------

STRONG = [10.0**e for e in (30, 32, 36, 40, 46, 58, 100, 150, 226, 294)]  # singular Pzz1 before


@pytest.mark.parametrize("power", STRONG)
def test_detection_game_tracking_steps_and_obdd_threshold_at_strong_power(power):
    import math

    from baselines.detection import obdd, tracking_problem
    from fdia_env import detection_game_v0

    env = detection_game_v0.parallel_env(scenario="ch3-tracking", power=power)
    env.reset(seed=0)  # raised LinAlgError: Singular matrix
    attack = detection_game_v0.default_opponent(env, "defender").predict(None)[0]  # rank one
    _, rewards, *_ = env.step(
        {"attacker": attack, "defender": env.action_space("defender").sample()}
    )
    assert math.isfinite(rewards["attacker"]) and rewards["attacker"] > 0.0
    assert math.isfinite(obdd(tracking_problem("ch3-tracking", power=power)).threshold)  # was −inf


@pytest.mark.parametrize(
    ("statistic", "on_detect", "limit"),
    [
        ("chi2", "discard", 3.38159464),
        ("quadratic", "discard", 3.53468809),
        ("chi2", "incorporate", 3.34874956),
        ("quadratic", "incorporate", 3.50118564),
    ],
)
def test_tracking_exact_error_reaches_its_strong_attack_limit(statistic, on_detect, limit):
    # against a rank-one attack the error tends to a limit as a² → ∞ (the attacked direction is
    # detected and dropped or down-weighted); it was 3.7e31 (quadratic, discard) and 1.9e281
    # (incorporate) at a² = 1e300, and LinAlgError between 1e30 and 1e41
    from baselines.detection import Detector, expected_mse, tracking_problem

    tau = 5.99 if statistic == "chi2" else 1.0
    values = [
        expected_mse(Detector("D", tracking_problem("ch3-tracking", a2), statistic, tau, on_detect))
        for a2 in (1e30, 1e40, 1e100, 1e150, 1e300)
    ]
    np.testing.assert_allclose(values, limit, rtol=1e-8)


def test_tracking_bayes_costs_are_right_at_strong_power():
    # OBDI's cost was −9.8e16 at 1e36 and 7.7e20 at 1e40; CSD's miss probability ~ a⁻¹ times
    # c2 ~ a² grows as a (it did not: 1.1e18, 9.0e8, 7.0e8 at 1e36, 1e40, 1e300)
    from baselines.detection import bayes_cost, csd, obdi, tracking_problem

    obdi_costs = [
        bayes_cost(obdi(tracking_problem("ch3-tracking", a2))).value for a2 in (1e36, 1e40, 1e300)
    ]
    np.testing.assert_allclose(obdi_costs, obdi_costs[0], rtol=1e-9)
    assert 0.0 < obdi_costs[0] < 10.0
    csd_costs = [
        bayes_cost(csd(tracking_problem("ch3-tracking", a2))).value for a2 in (1e36, 1e40, 1e300)
    ]
    assert csd_costs[1] / csd_costs[0] == pytest.approx(1e2, rel=1e-6)
    assert csd_costs[2] / csd_costs[0] == pytest.approx(1e132, rel=1e-6)


@pytest.mark.parametrize("power", [1e-20, 1.0, 1e40, 1e300])
def test_spd_inv_sum_matches_a_high_precision_reference_for_a_rank_one_sum(power):
    mp = pytest.importorskip("mpmath")
    from fdia_env.kalman import spd_inv_sum

    mp.mp.dps = 700
    rng = np.random.default_rng(3)
    M = rng.standard_normal((3, 3))
    P = M @ M.T + np.eye(3)
    v = rng.standard_normal(3)
    S = power * np.outer(v, v) / (v @ v)
    inverse, logdet = spd_inv_sum(P, S)
    # reference: the exact rank-one matrix power · u u' with the float unit vector u
    u = mp.matrix(list(v)) / mp.norm(mp.matrix(list(v)))
    exact = mp.matrix(P.tolist()) + mp.mpf(power) * (u * u.T)
    ref = exact**-1
    ref_np = np.array(ref.tolist(), dtype=float)
    assert np.linalg.norm(inverse - ref_np) <= 1e-12 * np.linalg.norm(ref_np)
    assert logdet == pytest.approx(float(mp.log(mp.det(exact))), rel=1e-12, abs=1e-12)


# --- extreme noise scales: clear errors instead of OverflowError, steady states at any scale ----


@pytest.mark.parametrize(
    ("make", "name"),
    [
        (
            lambda: tracking_system(1e200, [3.0]),
            "sigma_v",
        ),
        (
            lambda: tracking_system(1.0, [1e200]),
            "sigma_w",
        ),
        (
            lambda: tracking_system(1e100, [3.0], T=1e60),
            "sigma_v",
        ),
        (
            lambda: tracking_system(1e-170, [3.0]),
            "sigma_v",
        ),
        (lambda: pv_sensor(1e200, 1.0), "sigma_p"),
        (lambda: position_sensor(1e-200), "sigma"),
    ],
)
def test_noise_whose_variance_leaves_float64_is_refused_by_name(make, name):
    # tracking_system(1e200, [3.0]) raised a bare OverflowError (sigma_v ** 2)
    with pytest.raises(ValueError, match=rf"{name}.* outside float64's normal range"):
        make()


@pytest.mark.parametrize("c", [1e-150, 1e-100, 1e100, 1e150])
def test_steady_state_scales_with_the_noise_at_any_absolute_scale(c):
    # P(cσ) = c² P(σ), W(cσ) = W(σ): σ_v = σ_w = 1e-150 "diverged" before (the DARE solver's
    # absolute tolerances, then a 2 × 2 determinant of 1e-600)
    from fdia_env.kalman import steady_state

    P_pred, P_post, W = steady_state(tracking_system(0.5 * c, [3.0 * c, 4.0 * c]))
    ref_pred, ref_post, ref_W = steady_state(tracking_system(0.5, [3.0, 4.0]))
    np.testing.assert_allclose(P_pred / c**2, ref_pred, rtol=1e-12)
    np.testing.assert_allclose(P_post / c**2, ref_post, rtol=1e-12)
    np.testing.assert_allclose(W, ref_W, rtol=1e-12)


def test_inv2_of_tiny_and_huge_matrices_is_the_scaled_inverse():
    from fdia_env.kalman import inv2

    a = np.array([[2.0, 1.0], [1.0, 3.0]])
    for c in (1e-200, 1e-160, 1e160, 1e200):
        np.testing.assert_allclose(inv2(a * c) * c, np.linalg.inv(a), rtol=1e-14)


def test_a_detectable_system_out_of_float64_reach_is_not_called_undetectable():
    # a position+velocity sensor at tracking index ~4e149 is detectable; the error asked "is
    # every unstable mode detectable?" instead of naming the scale gap
    from fdia_env.kalman import steady_state

    with pytest.raises(RuntimeError, match="detectable, but the process noise") as info:
        steady_state(tracking_system(1e150, sensors=[pv_sensor(3.0, 4.0)]))
    assert "is every unstable mode detectable" not in str(info.value)
    assert "3.73e+149" in str(info.value)


def _alpha_beta_reference(sigma_v, sigma_w, T):
    """The α-β filter of tracking index λ in 60-digit arithmetic (Kalata's textbook form)."""
    mp = pytest.importorskip("mpmath")
    mp.mp.dps = 400
    s2 = 1 / sum(1 / mp.mpf(w) ** 2 for w in sigma_w)
    lam = mp.mpf(sigma_v) * mp.mpf(T) ** 2 / mp.sqrt(s2)
    r = (4 + lam - mp.sqrt(8 * lam + lam**2)) / 4
    alpha = 1 - r**2
    beta = 2 * (2 - alpha) - 4 * mp.sqrt(1 - alpha)
    T = mp.mpf(T)
    P = [[alpha, beta / T], [beta / T, beta * (alpha - beta / 2) / ((1 - alpha) * T**2)]]
    return np.array([[float(s2 * v) for v in row] for row in P])


@pytest.mark.parametrize(
    ("sigma_v", "sigma_w", "T"),
    [
        (1e150, [3.0, 4.0], 1.0),  # "diverged … is every unstable mode detectable?"
        (1e9, [1.0], 1.0),  # the documented xfail of the property suite
        (1e-150, [3.0], 1.0),  # "did not converge" after ~10 s
        (1e-20, [3.0], 1.0),
        (1.0, [1e-17], 1.0),
        (1e-140, [1e-5, 2e-5], 1e-3),
    ],
)
def test_steady_state_at_extreme_tracking_indices_is_the_alpha_beta_filter(sigma_v, sigma_w, T):
    from fdia_env.kalman import steady_state

    P_pred, P_post, W = steady_state(tracking_system(sigma_v, sigma_w, T=T))
    np.testing.assert_allclose(P_post, _alpha_beta_reference(sigma_v, sigma_w, T), rtol=1e-12)
    assert np.all(np.isfinite(P_pred)) and np.all(np.isfinite(W))


@pytest.mark.parametrize("sensors", [np.array("x"), np.array(3.0), "xy"])
def test_linear_system_sensors_that_are_no_sequence_are_named(sensors):
    # a 0-d array raised a bare TypeError "iteration over a 0-d array"
    from fdia_env.systems import LinearSystem

    with pytest.raises(ValueError, match=r"LinearSystem\.sensors must be a sequence of Sensor"):
        LinearSystem(F=np.eye(1), Q=np.eye(1), sensors=sensors)


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"sigma_w": np.array("x")}, "sigma_w"),
        ({"sigma_w": np.array(3.0)}, "sigma_w"),
        ({"sigma_w": [3.0], "sensors": np.array("x")}, "sensors"),
    ],
)
def test_tracking_system_zero_d_arrays_are_named(kwargs, name):
    # tracking_system(1.0, sigma_w=np.array("x")) raised "iteration over a 0-d array"
    with pytest.raises(ValueError, match=rf"^{name} must be"):
        tracking_system(1.0, **kwargs)


def test_grid_steady_state_at_a_tiny_random_walk_variance():
    # grid_system(q=1e-300): "did not converge" after ~20 s; the steady state of a random walk
    # scales as √q, and P[k|k] J P[k|k−1] = Q is the DARE for F = I
    from fdia_env.kalman import steady_state
    from fdia_env.systems.grid import grid_system

    states = {}
    for q in (1e-300, 1e-200):
        system = grid_system("ieee14", q=q)
        P_pred, P_post, W = steady_state(system)
        J = system.J.sum(axis=0)
        assert np.abs(P_post @ J @ P_pred - system.Q).max() <= 1e-6 * q
        assert np.all(np.isfinite(W))
        states[q] = P_post
    np.testing.assert_allclose(states[1e-300], 1e-50 * states[1e-200], rtol=1e-6)


@pytest.mark.parametrize(
    ("scenario", "rank"), [("ch2-pv-2", 2), ("ch2-pv-1", 2), ("ch2-position", 1)]
)
def test_det_optimal_value_grows_as_rank_times_log_power_up_to_1e300(scenario, rank):
    # log det(P + W Σ W') of a rank-r Σ grows by r ln(10) per decade of power; ch2-pv-2 gave
    # 1572.97 at 1e250 and 1915.70 at 1e300 (rounding "eigenvalues" of 1e284 counted)
    values = [det_optimal(scenario, power=10.0**e).value for e in (200, 250, 300)]
    np.testing.assert_allclose(np.diff(values), rank * 50 * np.log(10.0), rtol=1e-9)


def test_a_stable_mode_without_process_noise_is_named_not_a_singular_matrix():
    # F = [[0.063]], Q = 0 (found by the property suite): numpy's "Singular matrix" from the
    # information form; the steady state is P = 0, which that form cannot represent
    from fdia_env.kalman import steady_state
    from fdia_env.systems import LinearSystem, Sensor

    system = LinearSystem(
        F=np.array([[0.06286511]]),
        Q=np.zeros((1, 1)),
        sensors=(Sensor(H=np.array([[0.12573022]]), R=np.array([[0.04156428]])),),
    )
    with pytest.raises(ValueError, match=r"Q gives no process noise to the stable mode"):
        steady_state(system)
