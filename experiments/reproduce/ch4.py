"""Chapter 4: sparse attacks under perfect detection (``python -m experiments reproduce ch4``)."""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path

import numpy as np

from baselines.sparse import SOLVERS, dp, sfs
from experiments.reproduce.common import Section, grid_table, pairs_text, table, timed
from fdia_env import scenarios

# --- chapter 4 ------------------------------------------------------------------------------

# docs/references.md §4: SFS pick order for ch4-position, N = 6 (rows sensors, columns K+1..).
CH4_LITERATURE_GRID = np.array(
    [
        [0, 0, 5, 3, 2, 1],
        [0, 0, 0, 0, 0, 4],
        [0, 0, 0, 0, 0, 0],
    ]
)
CH4_LITERATURE_VALUE = 0.0328
# Matlab run times (s) at sizes M·N = 18 / 30 / 60; None = "not feasible".
CH4_LITERATURE_TIMES = {
    "sfs": (0.025, 0.064, 0.249),
    "sbs": (0.045, 0.239, 1.982),
    "sfs_ss": (0.047, 0.128, 0.495),
    "dp": (0.015, 0.025, 0.049),
    "exs": (2.269, 79.383, None),
}


def solver_label(name: str) -> str:
    """A solver's name in the tables: its ``SOLVERS`` key upper-cased (``"sfs_ss"``: SFS-SS)."""
    return name.upper().replace("_", "-")


def literature_columns(name: str, column: int, seconds: float) -> tuple[str, str]:
    """The literature's time of solver ``name`` at size ``column`` and its ratio to ``seconds``.

    A solver the literature did not run (one added to ``SOLVERS`` since) reads
    ``"not in the literature"``; a size it could not run, ``"not feasible"``.
    """
    if name not in CH4_LITERATURE_TIMES:
        return "not in the literature", "–"
    lit = CH4_LITERATURE_TIMES[name][column]
    if lit is None:
        return "not feasible", "–"
    return f"{lit:.3f}", f"{lit / seconds:.1f}×"


def ch4_table1() -> str:
    """Table 1: SFS pick order for N = 6 beside the literature's."""
    result = sfs("ch4-position", budget=5, horizon=6)
    same = np.array_equal(result.grid(), CH4_LITERATURE_GRID)
    return "\n\n".join(
        [
            "### Table 1: SFS pick order, ch4-position, c = 5, N = 6",
            "This implementation (1 = first pick):",
            grid_table(result.grid()),
            "Literature:",
            grid_table(CH4_LITERATURE_GRID),
            f"Identical: **{'yes' if same else 'NO'}**. tr P[K+N|K+N] = {result.value:.10g}.",
        ]
    )


def ch4_table2(repeats: int, warmup: bool = True) -> str:
    """Table 2: value and run time of every solver at sizes 18 / 30 / 60."""
    rows = []
    for col, N in enumerate((6, 10, 20)):
        for name, solver in SOLVERS.items():
            result, seconds = timed(lambda s=solver, n=N: s("ch4-position", 5, n), repeats, warmup)
            lit_text, ratio = literature_columns(name, col, seconds)
            row = [3 * N, solver_label(name), f"{result.value:.10f}", f"{seconds:.4f}"]
            rows.append([*row, lit_text, ratio])
    return "\n\n".join(
        [
            "### Table 2: objective and run time per solver, ch4-position, c = 5",
            f"Times are the median of {repeats} call(s) of the whole solver (including the "
            f"steady-state solve){', after one warm-up call' if warmup else ''}; literature "
            "times are Matlab's.",
            table(
                [
                    "size M·N",
                    "solver",
                    "tr P[K+N\\|K+N]",
                    "time (s)",
                    "literature time (s)",
                    "speed-up",
                ],
                rows,
            ),
            f"Literature value for every solver and size: {CH4_LITERATURE_VALUE}.",
        ]
    )


def ch4_pv_cases() -> str:
    """The three position+velocity cases: SFS pick order (det objective) and EXS vs SFS."""
    parts = ["### Position+velocity sensors (ch4-pv-case1..3): det objective, c = 5, N = 6"]
    rows = []
    for case in (1, 2, 3):
        name = f"ch4-pv-case{case}"
        results = {s: f(name, 5, 6, "logdet") for s, f in SOLVERS.items()}
        parts += [
            f"**{name}** ({scenarios.get(name).description}): SFS pick order",
            grid_table(results["sfs"].grid()),
        ]
        best = results["exs"].value
        for s, r in results.items():
            optimal = r.value >= best - 1e-12 * abs(best)
            gap = "optimal" if optimal else f"{np.exp(r.value - best):.6f}"
            rows.append(
                [
                    case,
                    solver_label(s),
                    f"{np.exp(r.value):.6e}",
                    f"{r.value:.8f}",
                    gap,
                    pairs_text(r),
                ]
            )
    parts += [
        "Objective per solver (det P[K+N|K+N]; `det / EXS` is the ratio to the optimum):",
        table(["case", "solver", "det P", "log det P", "det / EXS", "attacked pairs"], rows),
    ]
    return "\n\n".join(parts)


def ch4_dp_vs_sfs(sigmas: np.ndarray, trials: int) -> tuple[str, Callable[[Path], None]]:
    """DP against SFS on random 10-sensor problems (ch4-random, c = 10, N = 6)."""
    counts = np.zeros((len(sigmas), 3), dtype=int)  # same, DP better, SFS better
    for row, sigma_v in enumerate(sigmas):
        for seed in range(trials):
            sc = scenarios.get("ch4-random", seed=seed, sigma_v=float(sigma_v))
            v_dp, v_sfs = dp(sc, 10, 6).value, sfs(sc, 10, 6).value
            tol = 1e-9 * max(abs(v_dp), abs(v_sfs))
            counts[row, 0 if abs(v_dp - v_sfs) <= tol else (1 if v_dp > v_sfs else 2)] += 1
    rows = [[f"{s:.4g}", *counts[i]] for i, s in enumerate(sigmas)]
    text = "\n\n".join(
        [
            "### DP against SFS, ch4-random (10 position sensors, σ_w ~ U(0, 1), c = 10, N = 6)",
            f"{trials} trials per σ_v, trial t uses seed t; values equal within 1e-9 (relative) "
            "count as the same.",
            table(["σ_v", "same", "DP better", "SFS better"], rows),
            f"Total over {len(sigmas) * trials} trials: same {counts[:, 0].sum()}, DP better "
            f"{counts[:, 1].sum()}, SFS better {counts[:, 2].sum()}.",
            "![DP against SFS](figures/ch4_dp_vs_sfs.png)",
        ]
    )

    def plot(path: Path) -> None:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        from agents.plots import save_figure

        fig, ax = plt.subplots(figsize=(6, 3.5))
        for col, label in enumerate(("same", "DP better", "SFS better")):
            ax.semilogx(sigmas, counts[:, col], marker="o", label=label)
        ax.set_xlabel("σ_v")
        ax.set_ylabel(f"trials (of {trials})")
        ax.set_title("DP vs SFS, 10 sensors, c = 10, N = 6")
        ax.legend()
        save_figure(fig, path)

    return text, plot


def chapter4(args: argparse.Namespace) -> Section:
    """Chapter 4: sparse attacks under perfect detection."""
    quick = args.quick
    sigmas = np.logspace(-2, 0, 3 if quick else 10)
    trials = 5 if quick else 100
    dp_text, plot = ch4_dp_vs_sfs(sigmas, trials)
    body = "\n\n".join(
        [
            "Sparse attacks under perfect detection ({ref}`math §4 <math-4>`; solvers in "
            "`baselines/sparse`). "
            "Pairs are written zi@K+k (sensor i attacked at time K+k).",
            ch4_table1(),
            ch4_table2(repeats=1 if quick else 5, warmup=not quick),
            ch4_pv_cases(),
            dp_text,
        ]
    )
    return Section("Chapter 4: sparse attacks", body, {"ch4_dp_vs_sfs.png": plot})
