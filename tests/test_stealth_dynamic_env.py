"""The dynamic stealthy-attack env (stealth_dynamic_v0): the Kalman filter under a windowed χ²
detector, against the Mo–Sinopoli attack and Guo et al.'s optimal linear attack.

The env's PettingZoo/Gymnasium conformance and the clients run from the table of environments
(tests/test_envs_api.py, tests/test_env_conformance.py, tests/test_clients.py, tests/test_grid.py).
"""

import gymnasium as gym
import numpy as np
import pytest
from scipy import stats

from baselines.stealth.dynamic import attack_effect, kalman_model, mo_sinopoli
from baselines.stealth.linear import attack_value, optimal_linear_attack
from fdia_env.stealth import stealth_dynamic_v0
from fdia_env.stealth.dynamic_model import chi2_mix_sf
from fdia_env.stealth.dynamic_policy import ScheduledPolicy, bias_actions, linear_action
from fdia_env.systems import LinearSystem, Sensor

GYM_ID = "fdia_env/StealthDynamic-v0"


def stable_system() -> LinearSystem:
    """A stable two-state system with two scalar sensors (Guo et al.'s setting: A stable)."""
    sensors = (
        Sensor(H=np.array([[1.0, 0.0]]), R=np.array([[0.5]]), name="s1"),
        Sensor(H=np.array([[1.0, 1.0]]), R=np.array([[1.0]]), name="s2"),
    )
    return LinearSystem(
        F=np.array([[0.9, 0.2], [0.0, 0.7]]), Q=np.diag([0.3, 0.2]), sensors=sensors, name="st"
    )


# --- Mo & Sinopoli: an unbounded stealthy attack -------------------------------------------
def mo_sinopoli_setup(scale, **kwargs):
    env = stealth_dynamic_v0.parallel_env(a_max=1e6, **kwargs)  # ch4-position, all 3 sensors
    s, rows = env.model.system, env.model.rows
    attack = mo_sinopoli(s.F, s.H, s.Q, s.R, rows)
    assert attack.vulnerable and attack.eigenvalue == 1.0  # the position mode, seen on all 3
    return env, attack


def test_mo_sinopoli_attack_grows_the_error_without_bound_at_bounded_detection():
    horizon, scale = 800, 2e-3
    env, attack = mo_sinopoli_setup(scale, dynamics="expected", horizon=horizon)
    model = env.model
    inj = attack.attack(horizon, scale)
    actions = bias_actions(model, inj)
    env.reset(seed=0)
    phi, p = [], []
    for k in range(horizon):
        info = env.step({"attacker": actions[k]})[4]
        phi.append(info["attacker"]["phi"])
        p.append(info["attacker"]["detection_probability"])
    phi, p = np.array(phi), np.array(p)
    # the baseline's own error change, played through the env: phi = tr P_f + |Δe|²
    de, _ = attack_effect(attack.model, inj)
    np.testing.assert_allclose(phi, model.clean + np.sum(de**2, axis=1), rtol=1e-9)
    # |λ| = 1: Δe grows by scale · v every n = 2 steps, so |Δe|² grows like k²
    excess = phi - model.clean
    assert excess[-1] == pytest.approx((scale * horizon / 2) ** 2, rel=0.01)
    assert excess[-1] > 50 * model.clean  # 0.64 against tr P_f = 0.0124
    assert excess[399] == pytest.approx(excess[-1] / 4, rel=0.02)
    # the innovation's change is the reach phase's, periodic and bounded: p stays near α
    assert p.max() < 0.0515 and p.min() > 0.05
    np.testing.assert_allclose(p[10:], np.tile(p[10:12], (horizon - 10) // 2), rtol=1e-9)


def test_mo_sinopoli_attack_in_sampled_dynamics_alarms_at_the_exact_rate():
    """Sampling check in the native vector env: alarm rate = the exact p ≈ α, error grows."""
    B, steps, scale = 400, 200, 2e-3
    env, attack = mo_sinopoli_setup(scale)
    model = env.model
    venv = gym.make_vec(
        GYM_ID, num_envs=B, vectorization_mode="vector_entry_point", a_max=1e6, horizon=steps
    )
    venv.reset(seed=1)
    inj = bias_actions(model, attack.attack(steps, scale))
    alarms, p, errors = [], [], []
    for k in range(steps):
        _, _, _, _, info = venv.step(np.repeat(inj[k][None], B, axis=0).astype(np.float32))
        alarms.append(info["detected"])
        p.append(info["detection_probability"])
        errors.append(info["error"])
    alarms, p = np.array(alarms[4:]), np.array(p[4:])  # the window full (w = 5)
    # overlapping windows: about B · steps / w independent draws; 4.5 standard errors
    se = np.sqrt(0.05 * 0.95 / (B * (steps - 4) / 5))
    assert abs(alarms.mean() - p.mean()) < 4.5 * se
    assert 0.05 < p.mean() < 0.0515
    # the realised squared error: its mean over members is phi (tr P_f + |Δe|²)
    de, _ = attack_effect(attack.model, attack.attack(steps, scale))
    for k in (49, steps - 1):
        want = model.clean + np.sum(de[k] ** 2)
        mean, sem = np.mean(errors[k]), np.std(errors[k]) / np.sqrt(B)
        assert abs(mean - want) < 4.5 * sem, (k, mean, want)
    assert np.mean(errors[-1]) > 3 * np.mean(errors[49])


def test_on_the_grid_the_minimum_meter_attack_meters_admit_an_unbounded_stealthy_attack():
    """grid-ieee14 (random walk, A = I): the 3 meters of bus 7's undetectable static attack."""
    from baselines.stealth import minimum_meter_attack

    meters = np.flatnonzero(minimum_meter_attack("ieee14", method="mincut").a).tolist()
    assert meters == [6, 7, 32]
    steps = 520  # 40 reach phases of n = 13 steps
    env = stealth_dynamic_v0.parallel_env(
        "grid-ieee14", sensors=meters, dynamics="expected", horizon=steps, a_max=1e6
    )
    model, s = env.model, env.model.system
    attack = mo_sinopoli(s.F, s.H, s.Q, s.R, model.rows)
    assert attack.vulnerable and not mo_sinopoli(s.F, s.H, s.Q, s.R, model.rows[:2]).vulnerable
    actions = bias_actions(model, attack.attack(steps, 1.645e-4))  # window non-centrality ≤ 0.05
    env.reset(seed=0)
    phi, p = [], []
    for k in range(steps):
        info = env.step({"attacker": actions[k]})[4]["attacker"]
        phi.append(info["phi"])
        p.append(info["detection_probability"])
    excess = np.array(phi) - model.clean
    assert excess[-1] > 3 * model.clean  # the trace 4.4 times the clean one, and growing
    assert excess[-1] / excess[steps // 2 - 1] == pytest.approx(4.0, rel=0.03)  # like k²
    assert 0.05 < max(p[5:]) < 0.0504


def test_a_sensor_set_the_test_rejects_gets_no_unbounded_attack_from_the_same_play():
    # the position mode is seen by all three sensors: attacking two of them is not enough
    env = stealth_dynamic_v0.parallel_env(sensors=[0, 1])
    s = env.model.system
    assert not mo_sinopoli(s.F, s.H, s.Q, s.R, env.model.rows).vulnerable
    assert env.action_space("attacker").shape == (2,)


# --- Guo et al.: the KL-optimal linear attack --------------------------------------------
@pytest.mark.parametrize("delta", [0.0, 0.5])
def test_guo_linear_attack_in_the_env_gives_the_closed_form_error_covariance(delta):
    system = stable_system()
    env = stealth_dynamic_v0.parallel_env(
        system, action="linear", dynamics="expected", horizon=150, window=1
    )
    attack = optimal_linear_attack(system.F, system.H, system.Q, system.R, delta)
    act = linear_action(env.model, attack.T)
    env.reset(seed=0)
    for _ in range(150):  # D converges like 0.81^k (F's spectral radius 0.9, squared)
        _, rewards, _, _, infos = env.step({"attacker": act})
    info = infos["attacker"]
    assert info["phi"] == pytest.approx(attack.value, rel=1e-10)
    assert env.model.clean == pytest.approx(attack.clean, rel=1e-12)
    assert info["kl"] == pytest.approx(delta, abs=1e-9)
    p = info["detection_probability"]
    if delta == 0.0:
        assert attack.value > 2 * attack.clean  # the sign flip more than doubles the error
        assert p == 0.05 and rewards["attacker"] == pytest.approx(0.95 * attack.value)
    else:
        # z̃ ~ N(0, Σ̃) with Σ^{-1/2} Σ̃ Σ^{-1/2} = T̂ T̂': its eigenvalues weight χ²₁ variables
        St = attack.T @ env.model.Pz @ attack.T.T
        mu = np.linalg.eigvals(np.linalg.solve(env.model.Pz, St)).real
        want = chi2_mix_sf(mu, stats.chi2.isf(0.05, 2))
        assert p == pytest.approx(want, rel=1e-12) and p > 0.05


def test_guo_attack_sampled_in_the_vector_env_realises_its_error_and_alarm_rate():
    system = stable_system()
    B, steps = 2000, 40
    attack = optimal_linear_attack(system.F, system.H, system.Q, system.R, 0.0)
    kwargs = {"action": "linear", "horizon": steps}
    env = stealth_dynamic_v0.parallel_env(system, dynamics="expected", **kwargs)
    np.testing.assert_allclose(attack.T, -np.eye(2), atol=1e-12)  # strict stealth: T = −I
    act = linear_action(env.model, -np.eye(2)).astype(np.float32)  # the action −I/2, exact
    env.reset(seed=0)
    for _ in range(steps):
        phi = env.step({"attacker": act})[4]["attacker"]["phi"]
    venv = gym.make_vec(
        GYM_ID, num_envs=B, vectorization_mode="vector_entry_point", scenario=system, **kwargs
    )
    venv.reset(seed=2)
    alarms = []
    for _ in range(steps):
        _, _, _, _, info = venv.step(np.repeat(act[None], B, axis=0))
        alarms.append(info["detected"])
    assert np.all(info["detection_probability"] == 0.05)  # strictly stealthy: z̃ ~ z
    se = np.sqrt(0.05 * 0.95 / (B * steps / 5))
    assert abs(np.mean(alarms[4:]) - 0.05) < 4.5 * se
    mean, sem = info["error"].mean(), info["error"].std() / np.sqrt(B)
    assert abs(mean - phi) < 4.5 * sem and phi == pytest.approx(attack.value, rel=1e-3)


def test_chi2_mixture_tail_matches_closed_forms_and_sampling():
    assert chi2_mix_sf([2.0, 2.0], 3.0) == pytest.approx(stats.chi2.sf(1.5, 2), rel=1e-12)
    assert chi2_mix_sf([1.0, 1e-9], 3.84) == pytest.approx(stats.chi2.sf(3.84, 1), rel=1e-6)
    lam, x = np.array([0.01, 5.0, 0.3, 0.3, 1.0]), 12.0
    draws = np.random.default_rng(0).standard_normal((400_000, lam.size)) ** 2 @ lam
    se = np.sqrt(0.15 * 0.85 / draws.size)
    assert abs(chi2_mix_sf(lam, x) - np.mean(draws > x)) < 4.5 * se


def test_baseline_attacks_as_policies_reproduce_their_values_through_the_gymnasium_view():
    # Mo & Sinopoli, open loop: the view's phi is the baseline's tr P_f + |Δe|² of what it played
    env, attack = mo_sinopoli_setup(2e-3)
    model = env.model
    policy = ScheduledPolicy(bias_actions(model, attack.attack(200, 2e-3)))
    view = gym.make(GYM_ID, dynamics="expected", a_max=1e6, horizon=200)
    obs, _ = view.reset(seed=0)
    done = False
    while not done:
        obs, _, term, trunc, info = view.step(policy.predict(obs)[0])
        done = term or trunc
    played = np.zeros((200, model.m))
    played[:, model.rows] = policy.actions.astype(np.float64) * model.a_max * model.sigma
    de, _ = attack_effect(attack.model, played)
    assert info["step"] == 200 and info["phi"] == pytest.approx(model.clean + de[-1] @ de[-1])
    assert info["phi"] == pytest.approx(model.clean + (2e-3 * 200 / 2) ** 2, rel=0.01)
    # Guo et al. at δ = 0.5: the closed form's value of the (float32) T the view played
    system = stable_system()
    best = optimal_linear_attack(system.F, system.H, system.Q, system.R, 0.5)
    kwargs = {"action": "linear", "dynamics": "expected", "horizon": 120, "window": 1}
    view = gym.make(GYM_ID, scenario=system, **kwargs)
    model = view.unwrapped.parallel.model
    policy = ScheduledPolicy(np.repeat(linear_action(model, best.T)[None], 120, axis=0))
    obs, _ = view.reset(seed=0)
    for _ in range(120):
        obs, reward, _, _, info = view.step(policy.predict(obs)[0])
    T = np.eye(2) + model.t_max * policy.actions[0, :, :2].astype(np.float64)
    value, kl = attack_value(kalman_model(system.F, system.H, system.Q, system.R), T, 0 * T)
    assert info["phi"] == pytest.approx(value, rel=1e-10) and info["kl"] == pytest.approx(kl)
    assert value == pytest.approx(best.value, rel=1e-6)
    assert reward == pytest.approx((1 - info["detection_probability"]) * value)


def test_policy_helpers_refuse_attacks_outside_the_action_range():
    env = stealth_dynamic_v0.parallel_env()  # a_max = 5, t_max = 4
    model = env.model
    with pytest.raises(ValueError, match="a_max"):
        bias_actions(model, np.full((2, 3), 100.0))
    with pytest.raises(ValueError, match="injections must be a finite"):
        bias_actions(model, np.full((2, 4), 0.1))
    with pytest.raises(ValueError, match="t_max"):
        linear_action(model, -9.0 * np.eye(3))
    with pytest.raises(ValueError, match="T must be"):
        linear_action(model, np.eye(2))
    with pytest.raises(ValueError, match="actions must lie"):
        ScheduledPolicy([[2.0]])


# --- the env's own conventions ------------------------------------------------------------
def test_no_attack_alarms_at_alpha_and_pays_the_clean_error():
    env = stealth_dynamic_v0.parallel_env(dynamics="expected", horizon=7)
    _, infos = env.reset(seed=0)
    assert infos["attacker"]["phi"] == env.model.clean
    for k in range(1, 8):
        obs, rewards, terms, _, infos = env.step({"attacker": np.zeros(3, dtype=np.float32)})
        info = infos["attacker"]
        assert info["detection_probability"] == 0.05 and info["step"] == k
        assert info["statistic"] == 3 * min(k, 5)  # E[g]: 3 rows × the innovations in the window
        assert info["threshold"] == pytest.approx(stats.chi2.isf(0.05, 3 * min(k, 5)))
        assert rewards["attacker"] == pytest.approx(0.95 * env.model.clean)
    assert terms["attacker"] and obs["attacker"][0] == 0.0


def test_a_protected_sensor_gets_no_injection_and_the_defender_sets_the_rate():
    env = stealth_dynamic_v0.parallel_env(dynamics="expected", protected=["z2"])
    env.reset(seed=0)
    info = env.step({"attacker": np.array([0.0, 1.0, 0.0], dtype=np.float32)})[4]["attacker"]
    assert info["phi"] == env.model.clean and info["kl"] == 0.0
    env = stealth_dynamic_v0.parallel_env(dynamics="expected", defender="threshold")
    env.reset(seed=0)
    bias = np.array([0.5, 0.5, 0.5], dtype=np.float32)
    _, rewards, _, _, infos = env.step({"attacker": bias, "defender": 4})  # α = 0.2
    assert infos["defender"]["alpha"] == 0.2
    assert rewards["defender"] == pytest.approx(-rewards["attacker"] - 0.2)
    p_loose = infos["attacker"]["detection_probability"]
    env.reset(seed=0)
    _, _, _, _, infos = env.step({"attacker": bias, "defender": 0})  # α = 0.001
    assert 0.0 < infos["attacker"]["detection_probability"] < p_loose


@pytest.mark.parametrize("action", ["bias", "linear"])
def test_the_protect_defender_guards_its_budget_of_sensors_each_step(action):
    env = stealth_dynamic_v0.parallel_env(
        dynamics="expected", defender="protect", protect_budget=2, action=action
    )
    assert env.action_space("defender") == gym.spaces.MultiBinary(3)
    attack = 0.5 * np.ones(env.action_space("attacker").shape, dtype=np.float32)
    env.reset(seed=0)
    _, rewards, _, _, infos = env.step({"attacker": attack, "defender": np.array([1, 1, 1])})
    np.testing.assert_array_equal(infos["defender"]["protected"], [1, 1, 0])  # budget 2
    assert rewards["defender"] == pytest.approx(-rewards["attacker"] - 0.05)
    # the same step against a fixed protection of sensors 0 and 1: the same error
    fixed = stealth_dynamic_v0.parallel_env(dynamics="expected", protected=[0, 1], action=action)
    fixed.reset(seed=0)
    _, want, _, _, fixed_infos = fixed.step({"attacker": attack})
    assert rewards["attacker"] == pytest.approx(want["attacker"], rel=1e-12)
    assert infos["attacker"]["phi"] > env.model.clean  # sensor 2 is still attacked
    env.reset(seed=0)
    _, _, _, _, infos = env.step({"attacker": attack, "defender": np.zeros(3, dtype=np.int8)})
    assert infos["attacker"]["phi"] > fixed_infos["attacker"]["phi"]  # nothing guarded: worse
    view = gym.make(GYM_ID, defender="protect", dynamics="expected", action=action)
    view.reset(seed=0)
    assert view.step(attack)[4]["protected"].tolist() == [0, 0, 0]  # the default opponent


@pytest.mark.parametrize("action", ["bias", "linear"])
def test_native_vector_env_matches_single_envs_in_expected_dynamics(action):
    kwargs = {"dynamics": "expected", "horizon": 3, "action": action}
    venv = gym.make_vec(GYM_ID, num_envs=3, vectorization_mode="vector_entry_point", **kwargs)
    singles = [gym.make(GYM_ID, **kwargs) for _ in range(3)]
    venv.reset(seed=0)
    for e in singles:
        e.reset(seed=0)
    space = singles[0].action_space
    space.seed(0)
    for step in range(5):  # across the end of the first episode (NEXT_STEP autoreset)
        acts = np.stack([0.3 * space.sample() for _ in range(3)])
        obs, rew, term, trunc, info = venv.step(acts)
        for i, e in enumerate(singles):
            if step == 3:  # the autoreset step
                assert rew[i] == 0.0 and info["step"][i] == 0
                e.reset(seed=0)
                continue
            o, r, t, tr, inf = e.step(acts[i])
            np.testing.assert_allclose(obs[i], o, rtol=1e-6)
            assert rew[i] == pytest.approx(r, rel=1e-12) and term[i] == t and trunc[i] == tr
            for key in ("phi", "detection_probability", "statistic", "kl", "step"):
                assert info[key][i] == pytest.approx(inf[key], rel=1e-12), key


def test_sampled_episode_ends_at_the_first_alarm_with_on_detect_end():
    env = stealth_dynamic_v0.parallel_env(on_detect="end", horizon=50)
    env.reset(seed=0)
    full = np.ones(3, dtype=np.float32)  # 5 innovation standard deviations on every sensor
    _, rewards, terms, _, infos = env.step({"attacker": full})
    assert infos["attacker"]["detected"] and terms["attacker"] and rewards["attacker"] == 0.0
    assert env.agents == []


@pytest.mark.filterwarnings("ignore::UserWarning")  # PettingZoo's reset options, which we name
@pytest.mark.parametrize(
    "kwargs",
    [{"defender": "threshold"}, {"defender": "protect", "action": "linear"}],
    ids=["threshold", "protect-linear"],
)
def test_pettingzoo_and_gymnasium_conformance_of_the_defender_variants(kwargs):
    from gymnasium.utils.env_checker import check_env
    from pettingzoo.test import api_test, parallel_api_test, parallel_seed_test, seed_test

    parallel_api_test(stealth_dynamic_v0.parallel_env(**kwargs), num_cycles=40)
    parallel_seed_test(lambda: stealth_dynamic_v0.parallel_env(**kwargs))
    api_test(stealth_dynamic_v0.env(**kwargs), num_cycles=20)
    seed_test(lambda: stealth_dynamic_v0.env(**kwargs), num_cycles=20)
    for agent_id in (GYM_ID, "fdia_env/StealthDynamicDefender-v0"):
        check_env(gym.make(agent_id, **kwargs).unwrapped, skip_render_check=True)


def test_bad_input_is_a_value_error_naming_the_parameter():
    make = stealth_dynamic_v0.parallel_env
    for kwargs, name in [
        ({"sensors": [7]}, "sensors"),
        ({"sensors": []}, "sensors"),
        ({"protected": ["nope"]}, "protected"),
        ({"window": 0}, "window"),
        ({"action": "shift"}, "action"),
        ({"alpha": 1.0}, "alpha"),
        ({"alpha": 0.0}, "alpha"),
        ({"a_max": -1.0}, "a_max"),
        ({"t_max": float("inf")}, "t_max"),
        ({"penalty": float("nan")}, "penalty"),
        ({"defender": "sensors"}, "defender"),
        ({"defender": "protect", "protect_budget": 4}, "protect_budget"),
        ({"alphas": [0.1, 1.5]}, "alphas"),
        ({"dynamics": "mean"}, "dynamics"),
        ({"horizon": 0}, "horizon"),
    ]:
        with pytest.raises(ValueError, match=name):
            make(**kwargs)
    env = make()
    env.reset(seed=0)
    with pytest.raises(ValueError, match="attacker"):
        env.step({"attacker": np.array([np.nan, 0.0, 0.0], dtype=np.float32)})
    with pytest.raises(ValueError, match="backend must be one of"):
        gym.make_vec(GYM_ID, num_envs=2, vectorization_mode="vector_entry_point", backend="jax")


# --- the torch backend of the native vector env (bias attack) -------------------------------
def _np(x):
    return x.detach().cpu().numpy() if hasattr(x, "detach") else np.asarray(x)


def _compare(out, tout):
    for want, got in zip(out[:4], tout[:4], strict=True):
        np.testing.assert_allclose(_np(got), want, rtol=0, atol=1e-10)
    assert set(tout[4]) == set(out[4])
    for key, want in out[4].items():
        np.testing.assert_allclose(_np(tout[4][key]), want, rtol=1e-10, atol=1e-10, err_msg=key)


@pytest.mark.parametrize("dynamics", ["expected", "sampled"])
@pytest.mark.parametrize("action", ["bias", "linear"])
def test_torch_backend_equals_numpy_on_the_same_draws(dynamics, action, monkeypatch):
    torch = pytest.importorskip("torch")
    from fdia_env.backend import NUMPY
    from fdia_env.stealth.dynamic_model import DynamicModel

    kwargs = {"dynamics": dynamics, "horizon": 3, "on_detect": "end", "a_max": 3.0}
    kwargs |= {"action": action}
    shape = (3,) if action == "bias" else (3, 4)  # (T, b) on the 3 attacked rows
    runs = []
    for backend in ("numpy", "torch"):
        draws = np.random.default_rng(7)  # the same noise, in the same order, for both

        def normal(xp, rng, shape, draws=draws):
            x = draws.standard_normal(shape)
            return x if xp is NUMPY else xp.asarray(x)

        monkeypatch.setattr(DynamicModel, "_normal", staticmethod(normal))
        venv = gym.make_vec(
            GYM_ID, num_envs=16, vectorization_mode="vector_entry_point", backend=backend, **kwargs
        )
        outs = [venv.reset(seed=0)]
        acts = np.random.default_rng(1).uniform(-1, 1, (6, 16, *shape)).astype(np.float32)
        for a in acts:  # across the ends of episodes (horizon, alarms) and their autoresets
            outs.append(venv.step(a if backend == "numpy" else torch.as_tensor(a)))
        runs.append(outs)
    (obs, _), (tobs, _) = runs[0][0], runs[1][0]
    np.testing.assert_array_equal(_np(tobs), obs)
    for out, tout in zip(runs[0][1:], runs[1][1:], strict=True):
        _compare(out, tout)
    p = np.concatenate([o[4]["detection_probability"] for o in runs[0][1:]])
    assert ((p > 0.05 + 1e-6) & (p < 1 - 1e-6)).sum() > 10  # the tails were exercised
    if action == "linear":  # the covariance of the attack's effect grew: phi above the clean
        phi = np.concatenate([o[4]["phi"] for o in runs[0][1:]])
        assert (phi > runs[0][0][1]["phi"][0] + 1e-6).sum() > 10
    if dynamics == "sampled":
        assert any(o[4]["detected"].any() for o in runs[0][1:])


def test_torch_backend_draws_its_own_noise_and_refuses_numpy_actions():
    torch = pytest.importorskip("torch")
    venv = gym.make_vec(
        GYM_ID, num_envs=4000, vectorization_mode="vector_entry_point", backend="torch"
    )
    venv.reset(seed=3)
    with pytest.raises(TypeError, match=r"attacker actions must be a torch\.Tensor"):
        venv.step(np.zeros((4000, 3), dtype=np.float32))
    _, rewards, _, _, infos = venv.step(torch.zeros((4000, 3)))
    rate = float(infos["detected"].double().mean())  # no attack: the detector's α
    assert abs(rate - 0.05) < 4 * np.sqrt(0.05 * 0.95 / 4000)
    assert torch.all(rewards[~infos["detected"]] > 0)


def test_sensors_and_protected_take_positions_or_names_with_one_check():
    """The dynamic env and the static model name sensors/meters through one check."""
    env = stealth_dynamic_v0.parallel_env(dynamics="expected", sensors=["z2", 0, 0], protected=1)
    np.testing.assert_array_equal(env.sensors, [0, 1])
    np.testing.assert_array_equal(env.protected, [1])
    with pytest.raises(ValueError, match=r"protected holds an unknown sensor 'nope'"):
        stealth_dynamic_v0.parallel_env(protected=["nope"])
    with pytest.raises(ValueError, match=r"sensors must hold sensor positions \(0\.\.2\)"):
        stealth_dynamic_v0.parallel_env(sensors=[1.5])
    with pytest.raises(ValueError, match="protected must be a collection of sensors"):
        stealth_dynamic_v0.parallel_env(protected=2.5)
