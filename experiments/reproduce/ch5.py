"""Chapter 5: the sensor-selection game (``python -m experiments reproduce ch5``)."""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from baselines.game import (
    exploitability,
    payoff_matrix,
    solve_bayesian,
    solve_double_oracle,
    solve_zero_sum,
    strategy_bounds,
)
from experiments.reproduce.common import Section, table
from fdia_env.attacks.subsets import subset_name, subsets

# --- chapter 5 ------------------------------------------------------------------------------

# docs/references.md §5: the literature's independent-attack payoff as printed (rows defender
# subset, columns attacked subset, order z1, z2, z3, z1z2, z1z3, z2z3, z1z2z3). Row z1z3 prints
# 3.8 in columns z2 and z2z3, where the value is 3.748 (docs/references.md §5, erratum).
CH5_LITERATURE_L = np.array(
    [
        [25.4, 4.7, 4.7, 25.4, 25.4, 4.7, 25.4],
        [7.2, 23.5, 7.2, 7.2, 7.2, 23.5, 7.2],
        [10.0, 10.0, 23.6, 10.0, 10.0, 10.0, 10.0],
        [13.5, 6.6, 3.4, 13.5, 13.5, 6.6, 13.5],
        [16.4, 3.8, 5.4, 16.4, 16.4, 3.8, 16.4],
        [5.0, 12.4, 8.0, 5.0, 5.0, 12.4, 5.0],
        [10.2, 5.2, 3.9, 10.2, 10.2, 5.2, 10.2],
    ]
)
CH5_ERRATA = {(4, 1): 3.748, (4, 5): 3.748}
"""The print's misprints: ``(row, column)`` of :data:`CH5_LITERATURE_L` → the value of the
literature's own model (docs/references.md §5, erratum)."""
CH5_CORRECTED_L = CH5_LITERATURE_L.copy()
for (_row, _col), _value in CH5_ERRATA.items():
    CH5_CORRECTED_L[_row, _col] = round(_value, 1)
CH5_CORRECTED_L.setflags(write=False)
"""The literature's table with :data:`CH5_ERRATA` applied, at its one decimal (what the
payoff reproduces exactly after rounding)."""
CH5_LITERATURE_DEFENDER = (0.0, 0.0, 0.0, 0.0, 0.0, 0.40, 0.60)
CH5_LITERATURE_VALUE = 8.106
CH5_PRIORS = (0.5, 0.5)  # incomplete-information example: independent / dependent attacker
CH5_ALLOCATION_LABELS = {"independent": "independent (Prop. 2)", "dependent": "dependent (Prop. 3)"}


def ch5_matrix_table(L: np.ndarray, names: Sequence[str], digits: int) -> str:
    """A payoff matrix as a markdown table, rows D and columns A named by subset."""
    rows = [[names[r], *[f"{v:.{digits}f}" for v in L[r]]] for r in range(len(names))]
    return table(["D \\ A", *names], rows)


def ch5_mix(p: np.ndarray, names: Sequence[str], digits: int = 4) -> str:
    """The support of a mixed strategy: ``z2z3 0.4003, z1z2z3 0.5997``."""
    return ", ".join(f"{names[j]} {p[j]:.{digits}f}" for j in np.flatnonzero(p > 1e-12))


def ch5_identical_columns(L: np.ndarray) -> list[list[int]]:
    """Groups of identical columns of L (strategies the attacker cannot tell apart)."""
    groups: dict[bytes, list[int]] = {}
    for j in range(L.shape[1]):
        groups.setdefault(L[:, j].tobytes(), []).append(j)
    return list(groups.values())


def ch5_payoffs(matrices: dict[str, np.ndarray], names: Sequence[str]) -> str:
    """Both payoff matrices, the independent one beside the literature's print."""
    ours = matrices["independent"]
    differ = np.argwhere(np.round(ours, 1) != CH5_LITERATURE_L)
    diff_text = "; ".join(
        f"D = {names[r]}, A = {names[c]}: literature {CH5_LITERATURE_L[r, c]:.1f}, "
        f"this {ours[r, c]:.4f}"
        for r, c in differ
    )
    return "\n\n".join(
        [
            "### Payoff matrices, ch5-game (σ_w = 3, 4, 5, σ_v = 0.5, power a² = 100)",
            "`L[D, A] = tr(P_D + W_D Σ_{A∩D} W_D')` with the filter of subset D in steady state "
            "at the attack time (`baselines.game.payoff_matrix`). Rows: the defender's subset "
            "D; columns: the attacked subset A.",
            "**Independent attack** (Prop. 2: all power on the "
            "smallest-σ_w sensor of A), this implementation:",
            ch5_matrix_table(ours, names, 3),
            "Literature (as printed, 1 decimal):",
            ch5_matrix_table(CH5_LITERATURE_L, names, 1),
            f"Entries that differ at the literature's 1-decimal print: {len(differ)}"
            + (
                f" ({diff_text}); erratum ({{ref}}`references §5 <references-5>`): the value is "
                "3.748."
                if len(differ)
                else "."
            ),
            "**Dependent attack** (Prop. 3: correlation 1 over A, "
            "σ_b,i = c_i a / ||c||, c_i ∝ 1/σ_i²), this implementation:",
            ch5_matrix_table(matrices["dependent"], names, 3),
            "The literature's printed dependent matrix is not reproduced: per {ref}`references "
            "§5 <references-5>` it "
            "mixes this rule with an unnormalised one in its single-sensor rows. Columns z1, z2, "
            "z3 equal the independent matrix's (one attacked sensor takes all the power under "
            "either rule).",
        ]
    )


def ch5_equilibria(matrices: dict[str, np.ndarray], names: Sequence[str]) -> tuple[str, dict]:
    """Equilibrium, value, uniqueness and exploitability of both complete-information games."""
    parts = ["### Equilibria (LP with its dual, scipy HiGHS: `baselines.game.solve_zero_sum`)"]
    solutions = {}
    rows = []
    for allocation, L in matrices.items():
        x, y, value = solve_zero_sum(L)
        solutions[allocation] = (x, y, value)
        e = exploitability(L, x, y, value)
        x_low, x_high = strategy_bounds(L, "defender")
        groups = ch5_identical_columns(L)
        y_low, y_high = strategy_bounds(L, "attacker", groups=groups)
        x_unique = np.abs(x_high - x_low).max() <= 1e-6
        group_text = "; ".join(
            f"{{{', '.join(names[j] for j in g)}}} "
            + (
                f"{y_low[k]:.4f}"
                if y_high[k] - y_low[k] <= 1e-6
                else f"[{y_low[k]:.4f}, {y_high[k]:.4f}]"
            )
            for k, g in enumerate(groups)
            if y_high[k] > 1e-6
        )
        rows.append(
            [
                CH5_ALLOCATION_LABELS[allocation],
                ch5_mix(x, names),
                "yes" if x_unique else "no",
                ch5_mix(y, names),
                group_text,
                f"{value:.6f}",
                f"{e.nash_conv:.1e}",
            ]
        )
    parts.append(
        table(
            [
                "attack",
                "defender x (support)",
                "x unique",
                "attacker y (one equilibrium)",
                "attacker totals over identical columns, all equilibria",
                "value",
                "NashConv",
            ],
            rows,
        )
    )
    x, y, value = solutions["independent"]
    lit_x = np.array(CH5_LITERATURE_DEFENDER)
    same_x = np.array_equal(np.round(x, 2), lit_x)
    parts += [
        "Uniqueness is checked by minimising and maximising every coordinate (or group total) "
        "over the whole equilibrium polytope (`baselines.game.strategy_bounds`); NashConv is "
        "`max_j (L'x)_j − min_i (L y)_i` of the returned pair.",
        "Against the literature (independent attack): defender "
        f"({', '.join(f'{v:.2f}' for v in x)}) vs ({', '.join(f'{v:.2f}' for v in lit_x)}): "
        f"**{'same' if same_x else 'DIFFERENT'}**; value {value:.6f} vs {CH5_LITERATURE_VALUE}: "
        f"**{'same' if round(value, 3) == CH5_LITERATURE_VALUE else 'DIFFERENT'}** at the "
        "printed precision. The attacker's equilibrium is not unique (columns z1, z1z2, z1z3, "
        "z1z2z3 are identical, and so are z2, z2z3); only the group totals are determined. The "
        "literature's printed attacker strategy sums to 1.10, is not a probability vector and "
        "is not reproduced.",
    ]
    return "\n\n".join(parts), solutions


def ch5_incomplete(matrices: dict[str, np.ndarray], solutions: dict, names: Sequence[str]) -> str:
    """The incomplete-information game with priors over the two attack types."""
    Ls = [matrices["independent"], matrices["dependent"]]
    p = np.array(CH5_PRIORS)
    models = {m: solve_bayesian(Ls, p, attacker=m) for m in ("uninformed", "informed")}
    mean = p[0] * Ls[0] + p[1] * Ls[1]
    candidates = {
        "equilibrium of the independent game": solutions["independent"][0],
        "equilibrium of the dependent game": solutions["dependent"][0],
        "uninformed-attacker Bayesian equilibrium": models["uninformed"].x,
        "informed-attacker Bayesian equilibrium": models["informed"].x,
    }
    rows = []
    for label, x in candidates.items():
        worst = [float((x @ L).max()) for L in Ls]
        rows.append(
            [
                label,
                ch5_mix(x, names),
                f"{worst[0]:.4f}",
                f"{worst[1]:.4f}",
                f"{float((x @ mean).max()):.4f}",
                f"{float(p @ worst):.4f}",
            ]
        )
    u, i = models["uninformed"], models["informed"]
    return "\n\n".join(
        [
            f"### Incomplete information: attacker independent or dependent with priors "
            f"{CH5_PRIORS[0]} / {CH5_PRIORS[1]}",
            "{ref}`math §5 <math-5>`: the defender's LP uses `L̄ = Σ_s p_s L_s` "
            "(`solve_bayesian(..., "
            'attacker="uninformed")`): the attacker picks its subset without regard to its '
            'type, which nature then draws. `attacker="informed"` is the Harsanyi game in '
            "which each type knows itself and best-responds on its own matrix "
            "(`min Σ_s p_s b_s s.t. L_s' x ≤ b_s 1`).",
            f"Uninformed attacker: defender {ch5_mix(u.x, names)}; attacker "
            f"{ch5_mix(u.y[0], names)}; value {u.value:.6f} (against the independent type "
            f"{u.type_values[0]:.4f}, the dependent type {u.type_values[1]:.4f}).",
            f"Informed attacker: defender {ch5_mix(i.x, names)}; independent type "
            f"{ch5_mix(i.y[0], names)}, dependent type {ch5_mix(i.y[1], names)}; value "
            f"{i.value:.6f}.",
            "What each defender strategy concedes to a best-responding attacker (lower is "
            "better; the equilibrium of a model is best in that model's column):",
            table(
                [
                    "defender strategy",
                    "support",
                    "vs independent type",
                    "vs dependent type",
                    "uninformed model, max_j (L̄'x)_j",
                    "informed model, Σ_s p_s max_j (L_s'x)_j",
                ],
                rows,
            ),
        ]
    )


def ch5_double_oracle(sizes: Sequence[int], lp_max: int) -> str:
    """Double oracle on larger games (tracking, σ_w evenly over [1, 5]), with the full LP check."""
    from fdia_env.systems import tracking_system  # local: leaves the shared import block as is

    rows = []
    for M in sizes:
        system = tracking_system(0.5, list(np.linspace(1.0, 5.0, M)))
        for allocation in ("independent", "dependent"):
            t0 = time.perf_counter()
            r = solve_double_oracle(system, 100.0, allocation)
            seconds = time.perf_counter() - t0
            check = "–"
            if M <= lp_max:
                v = solve_zero_sum(payoff_matrix(system, 100.0, allocation))[2]
                check = f"{abs(v - r.value):.1e}"
            rows.append(
                [
                    M,
                    f"{2**M - 1:,}",
                    allocation,
                    f"{seconds:.3f}",
                    r.iterations,
                    f"{r.restricted_size[0]} × {r.restricted_size[1]}",
                    f"{len(r.defender)} / {len(r.attacker)}",
                    f"{r.value:.10f}",
                    f"{r.gap:.1e}",
                    check,
                ]
            )
    return "\n\n".join(
        [
            "### Larger games: double oracle (`baselines.game.solve_double_oracle`)",
            "Tracking systems with M position sensors, σ_w evenly spread over [1, 5], σ_v = 0.5, "
            "power 100. The double oracle never builds the (2^M − 1)² matrix: best responses over "
            "all subsets come from the factorised payoff, and `gap` = (attacker's best response "
            "to x) − (defender's best response to y) certifies the value. Time includes the "
            "steady states of all subsets. \\|Δ\\| full LP compares with the LP on the whole "
            f"matrix where it is built (M ≤ {lp_max}). Timings of every M: `benchmarks/game.py`.",
            table(
                [
                    "M",
                    "strategies",
                    "attack",
                    "time (s)",
                    "iterations",
                    "restricted game",
                    "support x / y",
                    "value",
                    "gap",
                    "\\|Δ\\| full LP",
                ],
                rows,
            ),
        ]
    )


def ch5_heatmap(
    matrices: dict[str, np.ndarray], solutions: dict, names: Sequence[str]
) -> Callable[[Path], None]:
    """Both payoff matrices as annotated heatmaps, equilibrium probabilities in the labels."""

    def plot(path: Path) -> None:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        from agents.plots import save_figure

        fig, axes = plt.subplots(1, 2, figsize=(12, 5.2))
        for ax, (allocation, L) in zip(axes, matrices.items(), strict=True):
            x, y, value = solutions[allocation]
            im = ax.imshow(L, cmap="viridis")
            for r in range(L.shape[0]):
                for c in range(L.shape[1]):
                    dark = L[r, c] < 0.6 * L.max()
                    ax.text(
                        c,
                        r,
                        f"{L[r, c]:.1f}",
                        ha="center",
                        va="center",
                        fontsize=8,
                        color="white" if dark else "black",
                    )
            ax.set_xticks(
                range(len(names)),
                [f"{n}\n{p:.2f}" if p > 1e-9 else n for n, p in zip(names, y, strict=True)],
                fontsize=8,
            )
            ax.set_yticks(
                range(len(names)),
                [f"{n} {p:.2f}" if p > 1e-9 else n for n, p in zip(names, x, strict=True)],
                fontsize=8,
            )
            ax.set_xlabel("attacked subset A (probability in the equilibrium found)")
            ax.set_ylabel("defender subset D (equilibrium probability)")
            ax.set_title(f"{CH5_ALLOCATION_LABELS[allocation]}, value {value:.3f}")
            fig.colorbar(im, ax=ax, shrink=0.8, label="tr(P + W Σ W')")
        fig.suptitle("ch5-game payoff L[D, A] (defender minimises, attacker maximises)")
        save_figure(fig, path)

    return plot


def chapter5(args: argparse.Namespace) -> Section:
    """Chapter 5: the sensor-selection game."""
    quick = args.quick
    names = [subset_name(s) for s in subsets(3)]
    matrices = {a: payoff_matrix("ch5-game", allocation=a) for a in ("independent", "dependent")}
    eq_text, solutions = ch5_equilibria(matrices, names)
    body = "\n\n".join(
        [
            "The sensor-selection game ({ref}`math §5 <math-5>`; solvers in `baselines/game`). "
            "Subsets are "
            "written z1z3 (sensors 1 and 3); both players have the 7 non-empty subsets of the 3 "
            "sensors, the defender minimises, the attacker maximises.",
            ch5_payoffs(matrices, names),
            eq_text,
            ch5_incomplete(matrices, solutions, names),
            ch5_double_oracle((4, 8) if quick else (4, 8, 10, 12, 16), lp_max=8 if quick else 10),
            "![ch5 payoff heatmaps](figures/ch5_payoff_heatmap.png)",
        ]
    )
    return Section(
        "Chapter 5: sensor-selection game",
        body,
        {"ch5_payoff_heatmap.png": ch5_heatmap(matrices, solutions, names)},
    )
