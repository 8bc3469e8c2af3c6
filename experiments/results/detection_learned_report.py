"""Tables and plots of :mod:`experiments.results.detection_learned` (Markdown and PNG)."""

from __future__ import annotations

import math
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


def format_tables(res: dict[str, Any]) -> str:
    """The four tables as Markdown."""
    out = ["**1a. Defender's best threshold against the preset attack** (exact, 1-D search)", ""]
    header = ["setting", "criterion", "τ*", "τ*'s reward", "env's reward at τ*", "OBDD α"]
    header += ["OBDD's reward", "OBDD's score", "random thresholds' score"]
    rows = [
        [
            _setting(r),
            r["criterion"],
            f"{r['best_threshold']:.4g}",
            f"{r['best_value']:.6g}",
            f"{r['env_value']:.6g}",
            f"{r['obdd_threshold']:.4g}",
            f"{r['obdd_value']:.6g}",
            f"{r['obdd_score']:.1%}",
            f"{r['random_score']:.1%}",
        ]
        for r in res["defender_refs"]
    ]
    out.append(table(header, rows))
    out += [
        "",
        "**1b. Attacker's best response (p, Σ) to each fixed detector** "
        "(exact, multi-start search; preset: p1 = 0.85, c2-maximising Σ)",
        "",
    ]
    header = ["setting", "criterion", "detector", "τ", "preset attack", "best response"]
    header += ["env's reward", "p*", "Σ*", "gain"]
    rows = []
    for r in res["attacker_refs"]:
        sigma = np.round(np.asarray(r["br_sigma"]), 1).tolist()
        note = " (always discards: constant)" if r["constant"] else ""
        rows.append(
            [
                _setting(r),
                r["criterion"],
                f"{r['detector']}{note}",
                f"{r['threshold']:.4g}",
                f"{r['preset_value']:.6g}",
                f"{r['br_value']:.6g}",
                f"{r['env_value']:.6g}",
                f"{r['br_probability']:g}",
                sigma,
                f"×{r['br_gain']:.3f}",
            ]
        )
    out.append(table(header, rows))
    out += ["", "**2. Learned attacker (SAC, MSE criterion) against each fixed detector**", ""]
    header = ["setting", "detector", "steps", "learned reward", "learned p", "best response"]
    header += ["learned's score", "random attacks' score", "preset's score"]
    rows = [
        [
            _setting(r),
            r["detector"],
            r["steps"],
            _pm(r["learned"]),
            _pm(r["learned_p"], ".3f"),
            f"{r['br_value']:.5g}",
            _pm(r["learned_score"], ".1%"),
            f"{r['random_score']:.1%}",
            f"{r['preset_value'] / r['br_value']:.1%}",
        ]
        for r in res["learned_attackers"]
    ]
    out.append(table(header, rows))
    out += ["", "**3. Learned defender (SAC, MSE criterion) against the preset attack**", ""]
    header = ["setting", "steps", "learned reward", "τ*'s reward", "learned's score"]
    header += ["OBDD α's score", "random thresholds' score"]
    rows = [
        [
            _setting(r),
            r["steps"],
            _pm(r["learned"]),
            f"{r['best_value']:.6g}",
            _pm(r["learned_score"], ".2%"),
            f"{r['obdd_score']:.2%}",
            f"{r['random_score']:.1%}",
        ]
        for r in res["learned_defenders"]
    ]
    out.append(table(header, rows))
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
