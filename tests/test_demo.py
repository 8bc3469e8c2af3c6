"""``make demo`` (agents/demo.py): its instance and the fast core of its table."""

from __future__ import annotations

import math

import pytest

from agents import demo
from baselines.sparse import branch_and_bound
from fdia_env import sparse_attack_v0
from fdia_env.envs.sequential import play_plan


@pytest.fixture(scope="module")
def instance() -> demo.Instance:
    return demo.instance()


def test_instance_is_one_where_sfs_is_clearly_suboptimal(instance):
    # EXS enumerates every set of c = 6 of the M·N = 20 pairs; branch and bound proves the same
    # optimum independently, and SFS stops at 82.9 % of it
    assert instance.optimum_sets == math.comb(20, 6) == 38_760
    bnb = branch_and_bound(instance.scenario, budget=6, horizon=2)
    assert bnb.proved_optimal
    assert bnb.value == pytest.approx(instance.optimum, rel=1e-12)
    assert instance.sfs / instance.optimum <= 0.90
    assert instance.sfs / instance.optimum == pytest.approx(0.8291, abs=1e-4)
    assert instance.optimum == pytest.approx(0.029276, rel=1e-4)


def test_optimum_replayed_in_the_sequential_env_returns_its_value(instance):
    env = sparse_attack_v0.parallel_env(
        scenario=instance.scenario, budget=6, horizon=2, action="sequential"
    )
    plan = [[] for _ in range(2)]
    for step, sensor in instance.optimum_attacks:
        plan[step].append(sensor + 1)
    assert play_plan(env, plan) == pytest.approx(instance.optimum, rel=1e-12)


def test_main_prints_the_table_with_a_tiny_budget(capsys):
    out = demo.main(["--steps", "256", "--random-episodes", "10"])
    text = capsys.readouterr().out
    for row in (
        "random play (10 episodes)",
        "SFS (greedy)",
        "learned (MaskablePPO, seed 0)",
        "optimum (EXS, certified)",
    ):
        assert row in text
    assert "82.9%" in text and "100.0%" in text
    assert out["sfs"] / out["optimum"] == pytest.approx(0.8291, abs=1e-4)
    # random masked play in the sequential format is far below SFS; no learner beats the optimum
    assert 0 < out["random"] < out["sfs"] < out["optimum"]
    assert out["worst"] == out["learned_0"] <= out["optimum"] * (1 + 1e-12)


def test_bad_options_are_refused_naming_the_option(capsys):
    with pytest.raises(SystemExit):
        demo.main(["--steps", "0"])
    assert "--steps must be at least 1" in capsys.readouterr().err


def test_the_demo_env_is_v0_time_major_without_the_out_of_date_notice(instance):
    import warnings

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        env = instance.make_env()
    with env:
        assert env.spec.id == "fdia_env/SparseAttack-v0"
        assert env.action_space.n == 11  # the time-major order: M + 1 = 10 sensors + stop
    assert not any("is out of date" in str(w.message) for w in caught)
