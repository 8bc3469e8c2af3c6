"""The stealth chapter of the reproduction report: its checks on small settings."""

from __future__ import annotations

import numpy as np
import pytest

from experiments.reproduce import cli
from experiments.reproduce.stealth import guo_rows, liu_row, mo_sinopoli_rows


def test_liu_claims_hold_on_ieee14():
    row = liu_row("ieee14", trials=6)
    assert (row["m"], row["n"], row["k"]) == (34, 13, 22)
    assert row["residual"] < 1e-12 and row["statistic"] < 1e-10 and row["estimate"] < 1e-12
    assert row["admit_k"] == 6  # every set of m − n + 1 meters admits an undetectable attack
    assert row["fewest"] == 3  # bus 7's radial attack


def test_mo_sinopoli_rows_grow_the_error_and_keep_the_alarm_rate():
    position, velocity, both = mo_sinopoli_rows(200)
    assert position["vulnerable"] and both["vulnerable"] and not velocity["vulnerable"]
    assert "error" not in velocity
    np.testing.assert_allclose(position["direction"], [1.0, 0.0], atol=1e-12)
    quarter, half, full = position["error"]
    assert full == pytest.approx(2 * half, rel=0.05) and half == pytest.approx(2 * quarter, rel=0.1)
    assert 0.05 < position["max_p"] < 0.055  # the exact windowed χ² alarm probability


def test_guo_strict_stealth_is_minus_identity_and_unbeaten():
    (strict, budget) = guo_rows((0.0, 0.5), starts=2, samples=50)
    assert strict["distance_to_minus_I"] < 1e-12 and strict["kl"] < 1e-12
    assert budget["kl"] == pytest.approx(0.5, rel=1e-9)
    assert budget["value"] > strict["value"] > strict["clean"]
    assert budget["sampled_feasible"] > 0
    assert budget["sampled_best"] <= budget["value"] * (1 + 1e-12)
    assert budget["local_best"] <= budget["value"] * (1 + 1e-6)


def test_the_chapter_is_on_the_command_line():
    assert "stealth" in cli.CHAPTERS
