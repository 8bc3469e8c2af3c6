"""The random system families' shared parts: numbered systems, scenarios and range checks."""

from __future__ import annotations

import numpy as np
import pytest

from fdia_env.envs.family import check_range
from fdia_env.envs.grid_family import GridFamily
from fdia_env.envs.system_family import TrackingFamily


def test_tracking_family_scenario_is_its_numbered_system_with_budget_and_horizon():
    family = TrackingFamily(budget=4, horizon=3)
    sc = family.scenario(5)
    assert (sc.name, sc.description) == ("tracking-family-5", "tracking family system 5")
    assert (sc.budget, sc.horizon) == (4, 3)
    np.testing.assert_array_equal(sc.system.R, family.system(5).R)


def test_grid_family_scenario_names_its_case():
    family = GridFamily(budget=2, horizon=1)
    sc = family.scenario(2)
    assert (sc.name, sc.description) == ("grid-family-2", "grid family (ieee14) system 2")
    assert (sc.budget, sc.horizon, sc.system.M) == (2, 1, 34)
    np.testing.assert_array_equal(sc.system.R, family.draw(np.random.default_rng(2)).R)
    assert not np.array_equal(sc.system.R, family.system(3).R)


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda: TrackingFamily(sigma_v=(0.0, 1.0)), r"sigma_v must .* 0 < low <= high"),
        (lambda: TrackingFamily(sigma_w=(-0.1, 1.0)), r"sigma_w must .* 0 <= low <= high"),
        (lambda: GridFamily(load_scale=(1.5, 0.5)), r"load_scale must .* 0 < low <= high"),
        (lambda: GridFamily(noise_scale=(float("nan"), 1.0)), r"noise_scale must"),
        (lambda: TrackingFamily().system(-1), r"seed must be"),
        (lambda: GridFamily().scenario(1.5), r"seed must be"),
    ],
)
def test_bad_ranges_and_seeds_are_refused_by_name(make, message):
    with pytest.raises(ValueError, match=message):
        make()


def test_check_range_returns_floats_and_allows_the_bound_only_when_closed():
    assert check_range("r", (0, 2), closed=True) == (0.0, 2.0)
    assert check_range("r", [1, 1]) == (1.0, 1.0)
    for bad in ((0, 2), (1,), (True, 2), ("a", 2), (2, 1), (1, float("inf"))):
        with pytest.raises(ValueError, match=r"^r must be a \(low, high\) pair"):
            check_range("r", bad)
