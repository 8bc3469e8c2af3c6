"""Regression tests for defects found under hostile and clumsy input.

Each test is the reproduction of one defect: it failed before the fix and passes after.
"""

import numpy as np
import pytest

from baselines.covariance import det_optimal, kkt_residuals, water_filling

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
