"""``stealth_attack_v0``: the static stealthy attacker's environment and its Gymnasium view."""

from __future__ import annotations

import importlib

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env
from pettingzoo.test import api_test, parallel_api_test, parallel_seed_test, seed_test
from stable_baselines3.common.env_checker import check_env as sb3_check_env

from baselines.stealth import budgeted_attack, security_index
from fdia_env.registration import GYM_IDS
from fdia_env.stealth import DEFENDER_GYM_ID, GYM_ID, static_estimation, stealth_attack_v0

ALPHA = 0.05


@pytest.fixture(scope="module")
def est():
    return static_estimation("ieee14")


@pytest.mark.parametrize("dynamics", ["expected", "sampled"])
@pytest.mark.parametrize("action", ["shift", "box_shift", "free"])
def test_pettingzoo_api_and_seed(est, dynamics, action):
    make = lambda: stealth_attack_v0.parallel_env(  # noqa: E731
        scenario=est, dynamics=dynamics, action=action, horizon=3
    )
    parallel_api_test(make(), num_cycles=50)
    parallel_seed_test(make)


@pytest.mark.filterwarnings("ignore::UserWarning")
def test_aec_api_and_seed(est):
    api_test(stealth_attack_v0.env(scenario=est, horizon=3), num_cycles=30)
    seed_test(lambda: stealth_attack_v0.env(scenario=est, horizon=3), num_cycles=20)


@pytest.mark.parametrize("dynamics", ["expected", "sampled"])
def test_gymnasium_and_sb3_checkers(dynamics):
    gym_check_env(gym.make(GYM_ID, dynamics=dynamics).unwrapped, skip_render_check=False)
    sb3_check_env(gym.make(GYM_ID, dynamics=dynamics), warn=True)


def test_infos_keep_their_keys_and_shapes(est):
    env = stealth_attack_v0.parallel_env(scenario=est, horizon=4, dynamics="sampled")
    _, infos = env.reset(seed=0)
    sig = {k: type(v).__name__ for k, v in infos["attacker"].items()}
    assert {"phi", "step", "detected", "detection_probability"} <= set(sig)
    env.action_space("attacker").seed(0)
    while env.agents:
        _, _, _, _, infos = env.step({"attacker": env.action_space("attacker").sample()})
        assert {k: type(v).__name__ for k, v in infos["attacker"].items()} == sig
        assert infos["attacker"]["attacked"].shape == (est.m,)


def test_security_index_policy_scores_its_exact_value(est):
    # the min-cut attack on the radial bus (3 meters) fits a budget of 3: undetectable, so the
    # expected reward is the shift times the probability of no false alarm
    policy = security_index(est, method="mincut").policy()
    env = stealth_attack_v0.parallel_env(scenario=est, budget=3, dynamics="expected")
    obs, _ = env.reset(seed=0)
    _, rewards, terms, _, infos = env.step({"attacker": policy.predict(obs["attacker"])[0]})
    assert rewards["attacker"] == pytest.approx((1 - ALPHA) * 0.05, rel=1e-12)
    assert infos["attacker"]["meters_used"] == 3
    assert infos["attacker"]["detection_probability"] == ALPHA
    assert terms["attacker"]


def test_over_budget_shift_is_trimmed_and_detected(est):
    # state 0 needs 5 meters: with 3, two of its meters keep their true readings
    bits = np.zeros(est.n, dtype=np.int8)
    bits[0] = 1
    env = stealth_attack_v0.parallel_env(scenario=est, budget=3, dynamics="expected")
    env.reset(seed=0)
    _, rewards, _, _, infos = env.step({"attacker": bits})
    p = infos["attacker"]["detection_probability"]
    assert infos["attacker"]["meters_used"] == 3
    assert p > 0.99
    assert rewards["attacker"] == pytest.approx((1 - p) * infos["attacker"]["phi"])


def test_budgeted_attack_policy_reaches_the_milp_value(est):
    best = budgeted_attack(est, budget=3, a_max=0.5, target=6)
    env = stealth_attack_v0.parallel_env(
        scenario=est, budget=3, action="free", a_max=0.5, dynamics="expected"
    )
    obs, _ = env.reset(seed=0)
    action = best.policy(a_max=0.5).predict(obs["attacker"])[0]
    _, rewards, _, _, infos = env.step({"attacker": action})
    assert infos["attacker"]["phi"] == pytest.approx(best.value, rel=1e-6)
    assert rewards["attacker"] == pytest.approx((1 - ALPHA) * best.value, rel=1e-6)


@pytest.mark.parametrize("a_max", [0.05, 0.5])
def test_box_shift_optimum_over_every_action_is_the_milp_optimum(est, a_max):
    """IEEE 14, budget 3: the best of all 8,191 box shifts pays (1 − α) · the MILP's shift.

    At a_max = 0.05 pu the detectable (trimmed) shifts pay something (each over 1 % of the
    optimum, the mean 11 %), at 0.5 pu almost nothing: neither beats the MILP's attack.
    """
    from fdia_env.stealth.vector import StealthVectorEnv

    milp = budgeted_attack(est, budget=3, a_max=a_max, target=6)  # bus 7, certified
    assert milp.proved and milp.value == pytest.approx(0.088075 * a_max / 0.5, rel=1e-6)
    kwargs = {"budget": 3, "action": "box_shift", "a_max": a_max, "dynamics": "expected"}
    bits = ((np.arange(1, 2**est.n)[:, None] >> np.arange(est.n)) & 1).astype(np.int8)
    vec = StealthVectorEnv(bits.shape[0], scenario=est, **kwargs)
    vec.reset(seed=0)
    _, rewards, _, _, infos = vec.step(bits)
    best = int(np.argmax(rewards))
    assert rewards[best] == pytest.approx((1 - ALPHA) * milp.value, rel=1e-12)
    assert infos["phi"][best] == pytest.approx(milp.value, rel=1e-12)
    assert infos["meters_used"][best] == 3
    dense = np.mean(rewards > 0.01 * rewards[best])
    assert dense == 1.0 if a_max == 0.05 else dense < 0.001
    # the fixed-magnitude shift of the same state pays the smaller (1 − α) · magnitude
    env = stealth_attack_v0.parallel_env(scenario=est, **(kwargs | {"action": "shift"}))
    env.reset(seed=0)
    _, rewards, _, _, _ = env.step({"attacker": bits[best]})
    assert rewards["attacker"] == pytest.approx((1 - ALPHA) * 0.05, rel=1e-12)


def test_box_shift_scales_the_largest_injection_to_a_max(est):
    env = stealth_attack_v0.parallel_env(scenario=est, budget=est.m, action="box_shift", a_max=0.3)
    bits = np.zeros(est.n, dtype=np.int8)
    bits[[2, 5]] = 1
    a = env.injection(bits)
    assert np.max(np.abs(a)) == pytest.approx(0.3, rel=1e-14)
    c = est.K @ a
    np.testing.assert_allclose(c, c[2] * bits, atol=1e-14)  # K H c = c: the shift is s · bits
    assert not env.injection(np.zeros(est.n, dtype=np.int8)).any()  # no bit: no injection


def test_sampled_detection_matches_the_exact_probability(est):
    # a single-meter injection: the sampled alarm rate over many snapshots is the exact p
    a = np.zeros(est.m)
    a[0] = 0.06
    p = float(est.detection_probability(a))
    env = stealth_attack_v0.parallel_env(
        scenario=est, budget=1, action="free", a_max=0.06, horizon=4000, dynamics="sampled"
    )
    env.reset(seed=3)
    action = (a / 0.06).astype(np.float32)
    alarms = 0
    while env.agents:
        _, rewards, _, _, infos = env.step({"attacker": action})
        alarms += infos["attacker"]["detected"]
        assert rewards["attacker"] == (
            0.0 if infos["attacker"]["detected"] else infos["attacker"]["phi"]
        )
    assert abs(alarms / 4000 - p) < 4 * np.sqrt(p * (1 - p) / 4000)


def test_on_detect_end_and_penalty(est):
    loud = np.ones(est.m, dtype=np.float32)
    env = stealth_attack_v0.parallel_env(
        scenario=est, budget=est.m, action="free", horizon=5, on_detect="end"
    )
    env.reset(seed=0)
    _, rewards, terms, _, infos = env.step({"attacker": loud})
    assert infos["attacker"]["detected"] and terms["attacker"] and rewards["attacker"] == 0.0
    assert env.agents == []
    env = stealth_attack_v0.parallel_env(
        scenario=est, budget=est.m, action="free", on_detect="penalty", penalty=2.0
    )
    env.reset(seed=0)
    _, rewards, _, _, _ = env.step({"attacker": loud})
    assert rewards["attacker"] == -2.0


def test_protected_meters_get_no_injection(est):
    env = stealth_attack_v0.parallel_env(
        scenario=est, budget=est.m, action="free", protected=["inj6", 7], dynamics="expected"
    )
    env.reset(seed=0)
    _, _, _, _, infos = env.step({"attacker": np.ones(est.m, dtype=np.float32)})
    attacked = infos["attacker"]["attacked"]
    assert attacked[6] == attacked[7] == 0
    assert attacked.sum() == est.m - 2


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"budget": 35}, "budget must be <= 34"),
        ({"alpha": 1.5}, "alpha must be a false-alarm rate in"),
        ({"protected": ["line99@0"]}, "protected holds an unknown meter"),
        ({"action": "sparse"}, "action must be one of"),
        ({"test": "lnr", "dynamics": "expected"}, "test='lnr' needs dynamics='sampled'"),
        ({"on_detect": "stop"}, "on_detect must be one of"),
        ({"penalty": -1.0}, "penalty must be a finite number >= 0"),
        ({"scenario": [[1.0, 2.0], [2.0, 4.0], [3.0, 6.0]]}, "H must have full column rank"),
    ],
)
def test_bad_options_name_the_parameter(kwargs, match):
    with pytest.raises(ValueError, match=match):
        stealth_attack_v0.parallel_env(**{"scenario": "grid-ieee14", **kwargs})


def test_non_finite_action_is_refused(est):
    env = stealth_attack_v0.parallel_env(scenario=est, action="free")
    env.reset(seed=0)
    bad = np.zeros(est.m, dtype=np.float32)
    bad[0] = np.nan
    with pytest.raises(ValueError, match="attacker"):
        env.step({"attacker": bad})


def test_agents_evaluate_scores_policies_against_the_milp_optimum(est):
    from agents.evaluate import evaluate

    best = budgeted_attack(est, budget=3, a_max=0.5, target=6)
    kwargs = {"scenario": est, "budget": 3, "action": "free", "a_max": 0.5, "dynamics": "expected"}
    reference = (1 - ALPHA) * best.value
    scored = evaluate(best.policy(a_max=0.5), GYM_ID, n_episodes=2, reference=reference, **kwargs)
    assert scored.score == pytest.approx(1.0, rel=1e-9)
    random = evaluate("random", GYM_ID, n_episodes=10, reference=reference, **kwargs)
    assert random.score < 0.01  # random injections on 3 meters are detected


def test_alpha_rethresholds_a_given_estimation_keeping_its_noise():
    own = static_estimation("ieee14", sigma=0.05)
    env = stealth_attack_v0.parallel_env(scenario=own, alpha=0.01)
    assert env.estimation.alpha == 0.01
    np.testing.assert_array_equal(env.estimation.R, own.R)
    assert env.estimation.threshold == pytest.approx(38.93217268351607)  # chi2(21) upper 1 %
    assert stealth_attack_v0.parallel_env(scenario=own).estimation is own


@pytest.mark.parametrize("dynamics", ["expected", "sampled"])
def test_threshold_defender_passes_the_pettingzoo_api(est, dynamics):
    make = lambda: stealth_attack_v0.parallel_env(  # noqa: E731
        scenario=est, dynamics=dynamics, horizon=3, defender="threshold"
    )
    parallel_api_test(make(), num_cycles=50)
    parallel_seed_test(make)


@pytest.mark.filterwarnings("ignore::UserWarning")
def test_threshold_defender_aec_and_gymnasium_views(est):
    api_test(stealth_attack_v0.env(scenario=est, horizon=3, defender="threshold"), num_cycles=30)
    gym_check_env(gym.make(DEFENDER_GYM_ID).unwrapped, skip_render_check=False)
    sb3_check_env(gym.make(DEFENDER_GYM_ID), warn=True)
    sb3_check_env(gym.make(GYM_ID, defender="threshold"), warn=True)


def test_threshold_defender_rewards(est):
    # the undetectable 3-meter attack is only seen by false alarms: the attacker gets
    # (1 − α) · shift, the defender minus that minus the cost of its false-alarm rate
    def game(**kwargs):
        return stealth_attack_v0.parallel_env(
            scenario=est,
            budget=3,
            dynamics="expected",
            defender="threshold",
            alphas=[0.01, 0.2],
            **kwargs,
        )

    bits = np.zeros(est.n, dtype=np.int8)
    bits[6] = 1
    env = game(false_alarm_cost=0.5)
    for choice, alpha in enumerate((0.01, 0.2)):
        env.reset(seed=0)
        _, rewards, _, _, infos = env.step({"attacker": bits, "defender": choice})
        assert rewards["attacker"] == pytest.approx((1 - alpha) * 0.05, rel=1e-12)
        assert rewards["defender"] == pytest.approx(-(1 - alpha) * 0.05 - 0.5 * alpha, rel=1e-12)
        assert infos["defender"]["alpha"] == alpha
    # a detectable attack (a small shift of state 0 on 3 of its 5 meters): a lower
    # false-alarm rate lets more of it through
    bits[:] = 0
    bits[0] = 1
    env = game(magnitude=0.004)
    seen = []
    for choice in (0, 1):
        env.reset(seed=0)
        _, rewards, _, _, infos = env.step({"attacker": bits, "defender": choice})
        seen.append(infos["attacker"]["detection_probability"])
    assert 0.05 < seen[0] < seen[1] < 0.99


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"defender": "protect"}, "defender must be one of"),
        ({"defender": "threshold", "alphas": [0.0, 0.1]}, "alphas must be a non-empty list"),
        ({"defender": "threshold", "alphas": []}, "alphas must be a non-empty list"),
        ({"false_alarm_cost": -1.0}, "false_alarm_cost must be a finite number >= 0"),
        ({"false_alarm_cost": 10**400}, "false_alarm_cost must be a finite number >= 0"),
        ({"penalty": -(10**30)}, "penalty must be a finite number >= 0"),
    ],
)
def test_bad_defender_options_name_the_parameter(est, kwargs, match):
    with pytest.raises(ValueError, match=match):
        stealth_attack_v0.parallel_env(scenario=est, **kwargs)


def test_costs_given_as_python_ints_beyond_int64_are_taken_as_floats(est):
    env = stealth_attack_v0.parallel_env(scenario=est, penalty=10**30, false_alarm_cost=2**70)
    assert (env.penalty, env.false_alarm_cost) == (1e30, float(2**70))


def test_every_id_is_made_after_only_import_fdia_env_in_a_fresh_process():
    # both views of the stealth env come from the table of environments: a fresh interpreter
    # that imports fdia_env alone (not fdia_env.stealth) makes every registered id
    import subprocess
    import sys

    code = (
        "import sys, gymnasium as gym, fdia_env\n"
        "from fdia_env.registration import GYM_IDS\n"
        "assert 'fdia_env.stealth' not in sys.modules\n"
        "ids = sorted(i for i in gym.registry if i.startswith('fdia_env/'))\n"
        "assert ids == sorted(GYM_IDS), (ids, sorted(GYM_IDS))\n"
        "for i in ids:\n"
        "    env = gym.make(i)\n"
        "    env.reset(seed=0)\n"
        "    env.close()\n"
        "print(' '.join(ids))\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=200, check=False
    )
    assert done.returncode == 0, done.stderr[-2000:]
    made = done.stdout.split()
    assert GYM_ID in made and DEFENDER_GYM_ID in made and set(made) == set(GYM_IDS)


def test_the_defender_view_is_in_the_table_without_a_native_vector_env():
    from fdia_env.registration import ENVS, vector_ids

    entry = ENVS["stealth_attack_v0"]
    assert GYM_IDS[DEFENDER_GYM_ID] == ("fdia_env.stealth.stealth_attack_v0", "defender")
    assert entry.has_vector("attacker") and not entry.has_vector("defender")
    assert GYM_ID in vector_ids() and DEFENDER_GYM_ID not in vector_ids()
    spec = gym.spec(DEFENDER_GYM_ID)
    assert spec.vector_entry_point is None and spec.kwargs["defender"] == "threshold"
    venv = gym.make_vec(DEFENDER_GYM_ID, num_envs=2)  # copies in SyncVectorEnv
    obs, _ = venv.reset(seed=0)
    assert isinstance(venv, gym.vector.SyncVectorEnv) and obs.shape == (2, 3)
    _, reward, *_ = venv.step(np.array([0, 4]))
    assert reward.shape == (2,) and np.all(np.isfinite(reward))
    venv.close()
    with pytest.raises(gym.error.Error, match="vector entry point"):
        gym.make_vec(DEFENDER_GYM_ID, num_envs=2, vectorization_mode="vector_entry_point")
    # the view built from (module, agent) alone is the defender's (the table's fixed options)
    from fdia_env.envs.single_agent import make_single_agent

    view = make_single_agent(*GYM_IDS[DEFENDER_GYM_ID])
    assert view.agent == "defender" and view.action_space == gym.spaces.Discrete(5)


class _ShiftBus7:
    """Shift bus 7 (radial, 3 meters): undetectable, damage 0.05 rad; batched for (B, d)."""

    def predict(self, observation, state=None, episode_start=None, deterministic=True):
        bits = np.zeros(13, dtype=np.int8)
        bits[6] = 1
        obs = np.asarray(observation)
        return (np.tile(bits, (obs.shape[0], 1)) if obs.ndim == 2 else bits), state


def test_evaluate_with_num_envs_runs_the_stealth_env_on_its_native_vector_env():
    from agents.evaluate import evaluate

    kwargs = {"budget": 3, "dynamics": "expected", "horizon": 2}
    batched = evaluate(_ShiftBus7(), GYM_ID, 5, seed=1, num_envs=2, **kwargs)  # 2, 2 and 1
    one_by_one = evaluate(_ShiftBus7(), GYM_ID, 5, seed=1, **kwargs)
    # expected payoff per snapshot: (1 − α) · 0.05 (only the test's false alarms catch it)
    np.testing.assert_allclose(batched.returns, np.full(5, 2 * (1 - ALPHA) * 0.05), rtol=1e-12)
    np.testing.assert_array_equal(batched.returns, one_by_one.returns)
    sampled = evaluate(_ShiftBus7(), GYM_ID, 400, seed=0, num_envs=64, budget=3)
    assert set(np.round(sampled.returns, 12)) == {0.0, 0.05}  # paid unless a false alarm
    assert abs(np.mean(sampled.returns == 0.0) - ALPHA) < 0.04  # 400 draws: ~3.5 σ
    assert evaluate("random", GYM_ID, 6, seed=0, num_envs=4).returns.shape == (6,)


def test_evaluate_with_num_envs_refuses_views_without_a_native_vector_env_by_name():
    from agents.evaluate import evaluate

    with pytest.raises(ValueError, match=r"num_envs=4: fdia_env/StealthDefender-v0 has no native"):
        evaluate("random", DEFENDER_GYM_ID, 4, num_envs=4)
    with pytest.raises(ValueError, match=r"num_envs=2: .* plays 'attacker' alone"):
        evaluate("random", GYM_ID, 4, num_envs=2, defender="threshold")
    direct = stealth_attack_v0.parallel_env(budget=3)
    from fdia_env.envs.single_agent import SingleAgentEnv

    with pytest.raises(ValueError, match=r"num_envs=2: .* made by gymnasium.make"):
        evaluate("random", SingleAgentEnv(direct), 4, num_envs=2)
    assert evaluate("random", DEFENDER_GYM_ID, 3, seed=0).returns.shape == (3,)  # one by one


@pytest.mark.parametrize("env_id", [GYM_ID, DEFENDER_GYM_ID])
@pytest.mark.parametrize("backend", ["numpy", "torch"])
def test_fdia_torchrl_env_refuses_the_stealth_ids_with_its_own_error(env_id, backend):
    pytest.importorskip("torchrl")
    from fdia_env.torchrl import FdiaTorchRLEnv

    # before: the attacker's id gave the stealth vector env's autoreset/backend complaint and
    # the defender's id Gymnasium's "doesn't have a vector entry point defined"
    with pytest.raises(ValueError, match=r"no native vector env of the Kalman-filter engine.*"):
        FdiaTorchRLEnv(env_id, num_envs=2, backend=backend)


def test_parallel_env_takes_the_options_of_the_env_class():
    import inspect

    from agents.training import env_option_names
    from fdia_env.stealth.env import StealthAttackEnv

    cls = inspect.signature(StealthAttackEnv).parameters
    assert inspect.signature(stealth_attack_v0.parallel_env).parameters == cls
    assert env_option_names(GYM_ID) == tuple(n for n in cls if n != "render_mode")
    env = stealth_attack_v0.parallel_env("grid-ieee14", budget=2, alphas=[0.01, 0.1])
    assert env.budget == 2 and env.alphas == (0.01, 0.1)
    with pytest.raises(TypeError, match="budgett"):
        stealth_attack_v0.parallel_env(budgett=2)


@pytest.mark.parametrize("name", ["stealth_attack_v0", "stealth_dynamic_v0"])
def test_rgb_array_frame_of_both_stealth_envs(name):
    module = importlib.import_module(f"fdia_env.stealth.{name}")
    env = module.parallel_env(render_mode="rgb_array")
    env.reset(seed=0)
    env.step({a: env.action_space(a).sample() for a in env.agents})
    frame = env.render()
    assert frame.shape == (256, 640, 3) and frame.dtype == np.uint8
    assert frame.min() < 100 < 250 <= frame.max()  # a plot: dark marks on a white page
