"""The training figures: labels, legend and the written PNG."""

from __future__ import annotations

import pytest

from agents import plots


@pytest.fixture
def captured(monkeypatch):
    """The figures the plots save, with their text read before they are closed."""
    seen: list[dict] = []
    real = plots.save_figure

    def spy(fig, path, dpi=120):
        ax = fig.axes[0]
        seen.append(
            {
                "labels": (ax.get_xlabel(), ax.get_ylabel(), ax.get_title()),
                "legend": [t.get_text() for t in ax.get_legend().get_texts()],
                "grid": any(line.get_visible() for line in ax.get_xgridlines()),
            }
        )
        return real(fig, path, dpi)

    monkeypatch.setattr(plots, "save_figure", spy)
    return seen


def test_learning_curve_labels_and_reference(tmp_path, captured):
    history = [
        {"timesteps": 10, "mean": 1.0, "ci95": 0.5},
        {"timesteps": 20, "mean": 2.0, "ci95": 0.1},
    ]
    path = plots.learning_curve(tmp_path / "c.png", history, 2.5, "EXS", "toy")
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    (fig,) = captured
    assert fig["labels"] == ("environment steps", "episode return", "toy")
    assert fig["legend"] == ["learned policy (evaluation)", "95% CI", "EXS = 2.5"]
    assert fig["grid"]


def test_exploitability_curve_labels_and_lines(tmp_path, captured):
    history = [
        {"iteration": i, "nash_conv": 1.0 / i, "defender": 0.5, "attacker": 0.2} for i in (1, 2)
    ]
    plots.exploitability_curve(tmp_path / "e.png", history, 3.0, "game")
    (fig,) = captured
    assert fig["labels"] == ("iteration", "exploitability (payoff units)", "game")
    assert fig["legend"][:3] == ["NashConv", "defender exploitability", "attacker exploitability"]
    assert fig["legend"][3:] == ["equilibrium (LP) = 0", "1% of the value 3"]
    assert (tmp_path / "e.png").is_file()
