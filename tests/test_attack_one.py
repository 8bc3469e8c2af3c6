"""The single env's attack models are their batched code on the batch of one (backend ONE)."""

from __future__ import annotations

import numpy as np
import pytest
from gymnasium import spaces

from fdia_env.attacks import CovarianceAttack, SparseAttack
from fdia_env.attacks.probabilistic import ProbabilisticAttack
from fdia_env.backend import NUMPY, ONE
from fdia_env.episode import EpisodeSpec
from fdia_env.scenarios import resolve


def test_one_backend_drops_the_batch_axis():
    table = np.array([[1, 2], [3, 4]], dtype=np.int8)
    assert ONE.full(1, 3, dtype=ONE.int64) == 3 and type(ONE.full(1, 3, dtype=ONE.int64)) is int
    assert ONE.zeros((1, 3), dtype=ONE.int8).shape == (3,)
    row = ONE.take(table, 1, axis=0)
    row[0] = 9  # a new row: the table is unchanged
    assert table[1].tolist() == [3, 4]
    assert ONE.take(np.array([5, 7]), 1) == 7 and type(ONE.take(np.array([5, 7]), 1)) is int
    assert ONE.sum(np.array([True, False, True]), 1) == 2  # axis 1 of (B, M) = axis 0 of (M,)
    assert ONE.cumsum(np.array([1, 1, 1]), 1).tolist() == [1, 2, 3]
    assert ONE.col(2.5) == [2.5] and NUMPY.col(np.array([1, 2])).shape == (2, 1)
    assert ONE.where(True, 1, 2) == 1 and ONE.minimum(3, 2) == 2
    assert ONE.flatnonzero(True).tolist() == [0] and ONE.flatnonzero(False).tolist() == []
    assert type(ONE.copy(np.float64(1.5))) is float


def _bound(model, scenario="ch4-position", horizon=4):
    model.bind(resolve(scenario).system, EpisodeSpec(horizon=horizon))
    return model


def _random_action(space, rng):
    if isinstance(space, spaces.Discrete):
        return int(rng.integers(0, space.n))
    if isinstance(space, spaces.MultiBinary):
        return rng.integers(0, 2, space.shape).astype(np.int8)
    return rng.uniform(-1.0, 1.0, space.shape).astype(np.float32)


MODELS = [
    ("ch4-position", lambda: SparseAttack(3)),
    ("ch4-position", lambda: SparseAttack(2, action="single")),
    ("ch4-position", lambda: SparseAttack(2, action="multibinary")),
    ("ch4-position", lambda: SparseAttack(1, illegal_action="noop")),
    ("ch2-position", lambda: CovarianceAttack(3000.0)),
    ("ch2-position", lambda: CovarianceAttack(3000.0, power_mode="budget")),
    ("ch2-position", lambda: CovarianceAttack(3000.0, structure="diagonal")),
    ("ch3-static", lambda: ProbabilisticAttack(100.0)),
]


@pytest.mark.parametrize(("scenario", "make"), MODELS)
def test_single_calls_equal_member_zero_of_the_numpy_batch(scenario, make):
    """Each single-env call equals member 0 of the numpy batch given the same actions."""
    single, batch = _bound(make(), scenario), _bound(make(), scenario)
    rng = np.random.default_rng(0)
    B = 3
    single.reset()
    batch.xp = NUMPY
    batch.batch_reset(B)
    assert single.xp is ONE
    for _ in range(4):
        assert single.features() == batch.batch_features()[0].tolist()
        mask, masks = single.action_mask(), batch.batch_action_mask()
        assert (mask is None) == (masks is None)
        if mask is not None:
            assert mask.dtype == np.int8 and np.array_equal(mask, masks[0])
        actions = [_random_action(single.action_space, rng) for _ in range(B)]
        effect = single.apply(actions[0])
        bits, sigma = batch.batch_apply(np.stack([np.asarray(a) for a in actions]))
        assert effect.attacked == int(bits[0])
        if sigma is None:
            assert effect.sigma is None
        else:
            np.testing.assert_allclose(effect.sigma, sigma[0], rtol=1e-12, atol=1e-12)
        probability = batch.batch_probability()
        assert effect.probability == (1.0 if probability is None else float(probability[0]))
        info, infos = single.info(), batch.batch_info()
        assert info.keys() == infos.keys()
        for key, value in info.items():
            if isinstance(value, np.ndarray):
                assert value.shape == infos[key].shape[1:] and np.array_equal(value, infos[key][0])
            else:
                assert type(value) in (int, float) and value == infos[key][0].item()


def test_single_apply_checks_the_action_and_changes_nothing_on_error():
    attack = _bound(SparseAttack(2, illegal_action="error"))
    attack.reset()
    with pytest.raises(ValueError, match=r"attacker action must be an integer in \[0, 8\)"):
        attack.apply(8)
    with pytest.raises(ValueError, match=r"attacker action must .*Discrete\(8\).*'big'"):
        attack.apply("big")
    assert attack.remaining == 2
    attack.apply(3)  # sensors 1 and 2: the whole budget
    with pytest.raises(ValueError, match="is illegal: it attacks 1 sensors with 0 of the budget"):
        attack.apply(4)
    assert attack.remaining == 0 and attack.info()["budget_left"] == 0


def test_covariance_action_to_sigma_uses_the_power_left_without_spending_it():
    attack = _bound(CovarianceAttack(3000.0, power_mode="budget"), "ch2-position")
    attack.reset()
    half = np.zeros(attack.action_space.shape, dtype=np.float32)  # spend half of what is left
    sigma, spent = attack.action_to_sigma(half)
    assert spent == 1500.0 and attack.remaining == 3000.0
    np.testing.assert_allclose(np.trace(attack.weight @ sigma), 1500.0, rtol=1e-12)
    effect = attack.apply(half)
    np.testing.assert_allclose(effect.sigma, sigma, rtol=1e-12)
    assert attack.remaining == 1500.0 and attack.info() == {"power": 1500.0, "power_left": 1500.0}


PAIRS = [
    ("sensor_game_v0", {}),
    ("sensor_game_v0", {"attacker_model": "informed", "types": ("independent", "dependent")}),
    ("detection_game_v0", {}),
    (
        "fdia_v0",
        {
            "scenario": "ch2-position",
            "attack": "covariance",
            "defense": "unaware",
            "attack_kwargs": {"power": 3000.0},
            "horizon": 4,
        },
    ),
    ("fdia_v0", {"attack": "sparse", "defense": "perfect_detection"}),
]


@pytest.mark.parametrize(("module", "kwargs"), PAIRS, ids=lambda x: str(x))
def test_single_pair_equals_member_zero_of_the_numpy_batch(module, kwargs):
    """Attack and defense together: the filter input, features and infos of member 0."""
    import importlib

    make = importlib.import_module(f"fdia_env.{module}").parallel_env
    if kwargs.get("types"):
        from fdia_env.attacks.typed import TypedSubsetAttack

        kwargs = {}
        env_s, env_b = make(), make()
        for env in (env_s, env_b):
            env.attack = TypedSubsetAttack(100.0, ("independent", "dependent"), (0.25, 0.75))
            env.attack.bind(env.system, env.spec)
    else:
        env_s, env_b = make(**kwargs), make(**kwargs)
    (att, dfn), (batt, bdfn) = (env_s.attack, env_s.defense), (env_b.attack, env_b.defense)
    B, rng = 3, np.random.default_rng(1)
    att.reset(), dfn.reset()
    batt.xp = bdfn.xp = NUMPY
    batt.batch_reset(B), bdfn.batch_reset(B)
    seeds = [np.random.default_rng(s) for s in range(B)]
    att.draw_nature(np.random.default_rng(0), {})
    batt.batch_draw_nature(seeds, None, {})
    assert att.private_info().keys() == batt.batch_private_info().keys()
    for _ in range(3):
        assert att.features() == batt.batch_features()[0].tolist()
        assert dfn.features() == bdfn.batch_features()[0].tolist()
        a = [_random_action(att.action_space, rng) for _ in range(B)]
        d = [None] * B
        if dfn.action_space is not None:
            d = [_random_action(dfn.action_space, rng) for _ in range(B)]
        effect = att.apply(a[0])
        fi = dfn.apply(d[0], effect)
        bits, sigma = batt.batch_apply(np.stack([np.asarray(x) for x in a]))
        actions = None if d[0] is None else np.stack([np.asarray(x) for x in d])
        used, leak, present, steady = bdfn.batch_apply(actions, bits, sigma)
        assert fi.used == int(used[0]) and fi.steady == bool(steady)
        if present is None or not present[0]:
            assert fi.leaked_sigma is None
        else:
            np.testing.assert_allclose(fi.leaked_sigma, leak[0], rtol=1e-12, atol=1e-12)
        rule = bdfn.batch_detection()
        assert (fi.detection is None) == (rule is None)
        if rule is not None:
            assert fi.detection.threshold == rule.member(0).threshold
            assert np.array_equal(fi.detection.assumed_sigma, rule.assumed_sigma)
            assert fi.attack_probability == float(batt.batch_probability()[0])
        att.observe_opponent(dfn), dfn.observe_opponent(att)
        batt.batch_observe_opponent(bdfn), bdfn.batch_observe_opponent(batt)
        assert att.info().keys() == batt.batch_info().keys()


def test_a_model_that_writes_a_single_env_call_is_refused():
    from fdia_env.defenses.base import DefenseModel

    with pytest.raises(
        TypeError, match=r"defines \['apply'\]: a model implements only its batched"
    ):

        class Twin(SparseAttack):
            def apply(self, action):
                return super().apply(action)

    with pytest.raises(TypeError, match=r"defines \['reset'\]"):

        class Legacy(DefenseModel):
            def reset(self):
                pass
