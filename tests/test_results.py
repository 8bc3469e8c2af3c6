"""experiments.results: the re-runnable result tables of the learned-vs-analytic comparison."""

import json
import math

import pytest

from experiments import results
from experiments.results import detection
from experiments.results.common import mean_ci95


def test_detection_quick_table_separates_only_at_high_power(capsys, tmp_path):
    assert results.main(["detection", "--quick", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    table = [line for line in out.splitlines() if line.startswith("|")]
    assert len(table) == 5  # header, rule, three settings
    assert len(json.loads((tmp_path / "detection.json").read_text())) == 3
    rows = detection.detection_separation(("ch3-static",), (0.01, 10.0), episodes=50, seed=0)
    weak, strong = rows
    # a² = 0.01: every threshold has OBDD's cost (the attack is too weak to matter)
    assert weak["score"] == pytest.approx(1.0, abs=1e-9) and not weak["separates"]
    # a² = 10: random thresholds pay about twice OBDD's Bayes cost (52 % over 200 episodes);
    # the bound 0.8 leaves more than 3 CI half-widths of room at 50 episodes
    assert strong["obdd"] == pytest.approx(-14.7708, rel=1e-4)
    assert strong["score"] <= detection.SEPARATING and strong["separates"]
    assert strong["random_mean"] + strong["random_ci95"] < strong["obdd"]


def test_detection_separation_names_a_bad_episode_count():
    with pytest.raises(ValueError, match="episodes must be an integer >= 1"):
        detection.detection_separation(episodes=0)


def test_unknown_table_is_named():
    with pytest.raises(ValueError, match="table must be one of"):
        results.run_table("nope")


def test_mean_ci95_is_the_student_t_interval():
    mean, half = mean_ci95([1.0, 2.0, 3.0])
    # t(0.975, 2) = 4.302653; s = 1; half = 4.302653 / sqrt(3)
    assert mean == 2.0 and half == pytest.approx(4.302653 / math.sqrt(3), rel=1e-6)
    assert math.isnan(mean_ci95([5.0])[1])
    with pytest.raises(ValueError, match="finite"):
        mean_ci95([1.0, float("nan")])
    with pytest.raises(ValueError, match="non-empty"):
        mean_ci95([])
