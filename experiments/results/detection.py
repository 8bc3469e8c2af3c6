"""``detection``: where the detection game separates a good defender from a poor one.

The detection game's defender at the Bayes-cost criterion, where OBDD's threshold α is the optimum
(docs/math.md §3), over attack powers a² and both chapter-3 scenarios: the score of random
thresholds (the uniform policy over the defender's action box, evaluated by
:func:`agents.evaluate.evaluate` in expected dynamics) against OBDD's optimal Bayes cost. Settings
where random play scores at most 80 % separate policies; the literature's default setting does not.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import gymnasium as gym

import fdia_env  # noqa: F401 - registers the Gymnasium ids
from agents.evaluate import evaluate
from experiments.markdown import table
from experiments.results.common import write_rows

SCENARIOS = ("ch3-static", "ch3-tracking")
POWERS = (0.01, 0.1, 1.0, 10.0, 100.0, 1e3, 1e4)
SEPARATING = 0.8  # random play at or below this score separates policies


def detection_separation(
    scenarios: Sequence[str] = SCENARIOS,
    powers: Sequence[float] = POWERS,
    episodes: int = 200,
    seed: int = 0,
) -> list[dict]:
    """Random thresholds' score against OBDD's Bayes cost for every (scenario, power).

    Args:
        scenarios: Chapter-3 presets.
        powers: Attack powers a².
        episodes: Episodes of random play per setting.
        seed: Seed of the random policy.

    Returns:
        One row per setting: scenario, power, random play's mean return and 95 % CI half-width,
        OBDD's (negated) Bayes cost, the score and whether the setting separates policies.

    Raises:
        ValueError: For ``episodes < 1`` (naming it), or an unknown scenario or a bad power
            (the env names the parameter).
    """
    if isinstance(episodes, bool) or not isinstance(episodes, int) or episodes < 1:
        raise ValueError(f"episodes must be an integer >= 1, got {episodes!r}")
    rows = []
    for scenario in scenarios:
        for power in powers:
            env = gym.make(
                "fdia_env/DetectionDefender-v0",
                scenario=scenario,
                power=power,
                criterion="bayes_cost",
            )
            result = evaluate("random", env, episodes, seed=seed)
            rows.append(
                {
                    "scenario": scenario,
                    "power": float(power),
                    "random_mean": result.mean,
                    "random_ci95": result.ci95,
                    "obdd": result.reference,
                    "score": result.score,
                    "separates": result.score <= SEPARATING,
                }
            )
            env.close()
    return rows


def format_detection(rows: list[dict]) -> str:
    """The rows as a Markdown table."""
    header = [
        "scenario",
        "a²",
        "random thresholds (return ± 95 % CI)",
        "OBDD α (−Bayes cost)",
        "random's score",
        "separates (≤ 80 %)",
    ]
    return table(
        header,
        [
            [
                r["scenario"],
                f"{r['power']:g}",
                f"{r['random_mean']:.4g} ± {r['random_ci95']:.2g}",
                f"{r['obdd']:.4g}",
                f"{r['score']:.1%}",
                "yes" if r["separates"] else "no",
            ]
            for r in rows
        ],
    )


def run(quick: bool = False, seed: int = 0, out: Path | None = None) -> str:
    """The ``detection`` table (Markdown); ``quick``: one scenario, three powers, 50 episodes."""
    if quick:
        rows = detection_separation(("ch3-static",), (0.01, 10.0, 1e3), episodes=50, seed=seed)
    else:
        rows = detection_separation(seed=seed)
    if out is not None:
        write_rows(out / "detection.json", rows)
    return format_detection(rows)
