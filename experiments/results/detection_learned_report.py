"""Tables and plots of :mod:`experiments.results.detection_learned` (Markdown and PNG)."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from experiments.markdown import table
from experiments.results.common import mean_ci95

GAME_SETTING = ("ch3-static", 1000.0)  # learned against learned


def _pm(pair: tuple[float, float], fmt: str = ".4g") -> str:
    mean, half = pair
    if math.isnan(half):
        return f"{mean:{fmt}}"
    return f"{mean:{fmt}} ± {half:.1%}" if fmt.endswith("%") else f"{mean:{fmt}} ± {half:.2g}"


def _setting(row: dict[str, Any]) -> str:
    return f"{row['scenario']} a²={row['power']:g}"


Column = tuple[str, str | Callable[[dict[str, Any]], Any]]
"""A table column: its header and its cell, a format of the record's fields or a function of it."""


def _columns_table(records: list[dict[str, Any]], columns: Sequence[Column]) -> str:
    """``records`` as a Markdown table with ``columns``, one row each."""
    rows = [[c.format(**r) if isinstance(c, str) else c(r) for _, c in columns] for r in records]
    return table([header for header, _ in columns], rows)


def _detector(row: dict[str, Any]) -> str:
    """The fixed detector, noted where its best response is constant."""
    return row["detector"] + (" (always discards: constant)" if row["constant"] else "")


def _mean_pm(key: str, fmt: str = ".4g") -> Callable[[dict[str, Any]], str]:
    """The cell of a (mean, 95 % half-width) field: ``mean ± half`` (:func:`_pm`)."""
    return lambda r: _pm(r[key], fmt)


DEFENDER_REFS: tuple[Column, ...] = (
    ("setting", _setting),
    ("criterion", "{criterion}"),
    ("τ*", "{best_threshold:.4g}"),
    ("τ*'s reward", "{best_value:.6g}"),
    ("env's reward at τ*", "{env_value:.6g}"),
    ("OBDD α", "{obdd_threshold:.4g}"),
    ("OBDD's reward", "{obdd_value:.6g}"),
    ("OBDD's score", "{obdd_score:.1%}"),
    ("random thresholds' score", "{random_score:.1%}"),
)
"""Table 1a: the defender's best threshold against the preset attack."""

ATTACKER_REFS: tuple[Column, ...] = (
    ("setting", _setting),
    ("criterion", "{criterion}"),
    ("detector", _detector),
    ("τ", "{threshold:.4g}"),
    ("preset attack", "{preset_value:.6g}"),
    ("best response", "{br_value:.6g}"),
    ("env's reward", "{env_value:.6g}"),
    ("p*", "{br_probability:g}"),
    ("Σ*", lambda r: np.round(np.asarray(r["br_sigma"]), 1).tolist()),
    ("gain", "×{br_gain:.3f}"),
)
"""Table 1b: the attacker's best response to each fixed detector."""

LEARNED_ATTACKERS: tuple[Column, ...] = (
    ("setting", _setting),
    ("detector", "{detector}"),
    ("steps", "{steps}"),
    ("learned reward", _mean_pm("learned")),
    ("learned p", _mean_pm("learned_p", ".3f")),
    ("best response", "{br_value:.5g}"),
    ("learned's score", _mean_pm("learned_score", ".1%")),
    ("random attacks' score", "{random_score:.1%}"),
    ("preset's score", lambda r: f"{r['preset_value'] / r['br_value']:.1%}"),
)
"""Table 2: the learned attacker against each fixed detector."""

LEARNED_DEFENDERS: tuple[Column, ...] = (
    ("setting", _setting),
    ("steps", "{steps}"),
    ("learned reward", _mean_pm("learned")),
    ("τ*'s reward", "{best_value:.6g}"),
    ("learned's score", _mean_pm("learned_score", ".2%")),
    ("OBDD α's score", "{obdd_score:.2%}"),
    ("random thresholds' score", "{random_score:.1%}"),
)
"""Table 3: the learned defender against the preset attack."""


def format_tables(res: dict[str, Any]) -> str:
    """The four tables as Markdown."""
    out = ["**1a. Defender's best threshold against the preset attack** (exact, 1-D search)", ""]
    out.append(_columns_table(res["defender_refs"], DEFENDER_REFS))
    out += [
        "",
        "**1b. Attacker's best response (p, Σ) to each fixed detector** "
        "(exact, multi-start search; preset: p1 = 0.85, c2-maximising Σ)",
        "",
    ]
    out.append(_columns_table(res["attacker_refs"], ATTACKER_REFS))
    out += ["", "**2. Learned attacker (SAC, MSE criterion) against each fixed detector**", ""]
    out.append(_columns_table(res["learned_attackers"], LEARNED_ATTACKERS))
    out += ["", "**3. Learned defender (SAC, MSE criterion) against the preset attack**", ""]
    out.append(_columns_table(res["learned_defenders"], LEARNED_DEFENDERS))
    if res["rounds"]:
        out += [
            "",
            "**4. Learned against learned** "
            f"({GAME_SETTING[0]} a²={GAME_SETTING[1]:g}, MSE; alternating SAC best "
            "responses from the learned defender of table 3)",
            "",
            _rounds_table(res["rounds"]),
        ]
        mm = res.get("minimax")
        obdd_worst = res["obdd_worst_case"]
        line = f"OBDD α's worst case over all attacks: {obdd_worst:.6g}"
        if mm is not None:
            line += (
                f"; minimax threshold (grid of {len(mm['grid'])} actions): τ = "
                f"{mm['threshold']:.4g}, worst case {mm['value']:.6g}"
            )
        out += ["", line + "."]
    return "\n".join(out)


def _rounds_table(records: list[dict[str, Any]]) -> str:
    """Table 4: each round's learned side against the other, mean ± 95 % CI over seeds."""
    header = ["round", "side", "payoff against the other", "its exact best response's", "score"]
    header += ["counterpart against the same opponent", "worst case over all attacks"]
    rows = []
    for k, side in sorted({(r["round"], r["side"]) for r in records}, key=_order):
        rs = [r for r in records if r["round"] == k and r["side"] == side]
        if k == 0:
            worst = _pm(mean_ci95([r["worst_case"] for r in rs]))
            rows.append([0, "defender (table 3)", "", "", "", "", worst])
            continue
        cols = [_pm(mean_ci95([r[c] for r in rs])) for c in ("payoff", "best_response")]
        score = _pm(mean_ci95([r["score"] for r in rs]), ".1%")
        if side == "attacker":
            other = f"preset attack: {_pm(mean_ci95([r['preset_payoff'] for r in rs]))}"
            worst = ""
        else:
            other = f"OBDD α: {_pm(mean_ci95([r['obdd_payoff'] for r in rs]))}"
            worst = _pm(mean_ci95([r["worst_case"] for r in rs]))
        rows.append([k, side, cols[0], cols[1], score, other, worst])
    return table(header, rows)


def _order(key: tuple[int, str]) -> tuple[int, int]:
    return key[0], 0 if key[1] == "attacker" else 1


def _ratio_plot(
    rows: list[dict[str, Any]],
    ratio: Any,
    label: Any,
    reference: str,
    ylabel: str,
    title: str,
    path: Path,
    legend_size: int,
) -> Path:
    """Learning curves of ``ratio(row, point)`` (mean over seeds) with the reference at 1."""
    import matplotlib.pyplot as plt

    from agents.plots import save_figure

    fig, ax = plt.subplots(figsize=(7, 4))
    for r in rows:
        steps = [c["timesteps"] for c in r["curves"][0]]
        mean = np.mean([[ratio(r, c) for c in cur] for cur in r["curves"]], 0)
        ax.plot(steps, mean, marker="o", ms=3, label=label(r))
    ax.axhline(1.0, color="k", ls="--", label=reference)
    ax.set(xlabel="environment steps", ylabel=ylabel, title=title)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=legend_size, loc="lower right")
    save_figure(fig, path)
    return path


def plot(res: dict[str, Any], out: Path) -> list[Path]:
    """Learning curves (score against the exact reference line) and the threshold curve."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from agents.plots import save_figure

    out.mkdir(parents=True, exist_ok=True)
    paths = []
    paths.append(
        _ratio_plot(
            res["learned_attackers"],
            lambda r, c: c["reward"] / r["br_value"],
            lambda r: f"{_setting(r)} {r['detector']}",
            "numerical best response = 1",
            "reward / best response (mean over seeds)",
            "Learned attacker (SAC) against fixed detectors, MSE",
            out / "results_detection_learned_attacker.png",
            legend_size=6,
        )
    )
    paths.append(
        _ratio_plot(
            res["learned_defenders"],
            lambda r, c: r["best_value"] / c["reward"],
            lambda r: f"{_setting(r)} (OBDD: {r['obdd_score']:.1%})",
            "τ*_MSE (exact optimum) = 1",
            "optimal cost / learned cost (mean over seeds)",
            "Learned defender (SAC) against the preset attack, MSE",
            out / "results_detection_learned_defender.png",
            legend_size=7,
        )
    )

    fig, ax = plt.subplots(figsize=(7, 4))
    for r in res["defender_refs"]:
        if (r["scenario"], r["power"]) != GAME_SETTING:
            continue
        ax.plot(r["curve"]["action"], r["curve"]["value"], label=f"criterion {r['criterion']}")
        color = ax.lines[-1].get_color()
        ax.axvline(r["best_action"], ls=":", color=color, label=f"best τ ({r['criterion']})")
    for r in res["learned_defenders"]:
        if (r["scenario"], r["power"]) == GAME_SETTING:
            ax.plot(
                r["actions"],
                r["learned"][0] * np.ones(len(r["actions"])),
                "kx",
                label="learned defenders (MSE)",
            )
    ax.set(
        xlabel="defender action a (τ = (1 + a) / (1 − a))",
        ylabel="defender reward",
        title=f"Threshold vs the preset attack, {GAME_SETTING[0]} a²={GAME_SETTING[1]:g}",
    )
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    paths.append(save_figure(fig, out / "results_detection_learned_threshold.png"))
    return paths
