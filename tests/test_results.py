"""agents.results: the re-runnable result tables of the learned-vs-analytic comparison."""

import pytest

from agents import results


def test_detection_quick_table_separates_only_at_high_power(capsys):
    assert results.main(["detection", "--quick"]) == 0
    table = capsys.readouterr().out
    assert table.count("\n") == 5  # header, rule, three settings
    rows = results.detection_separation(("ch3-static",), (0.01, 10.0), episodes=50, seed=0)
    weak, strong = rows
    # a² = 0.01: every threshold has OBDD's cost (the attack is too weak to matter)
    assert weak["score"] == pytest.approx(1.0, abs=1e-9) and not weak["separates"]
    # a² = 10: random thresholds pay about twice OBDD's Bayes cost (52 % over 200 episodes);
    # the bound 0.8 leaves more than 3 CI half-widths of room at 50 episodes
    assert strong["obdd"] == pytest.approx(-14.7708, rel=1e-4)
    assert strong["score"] <= results.SEPARATING and strong["separates"]
    assert strong["random_mean"] + strong["random_ci95"] < strong["obdd"]


def test_detection_separation_names_a_bad_episode_count():
    with pytest.raises(ValueError, match="episodes must be an integer >= 1"):
        results.detection_separation(episodes=0)
