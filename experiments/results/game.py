"""``game``: PSRO with learned best responses against the exact equilibrium of large sensor games.

The sensor-selection game (docs/math.md §5) at sizes where the strategies cannot be listed by hand:
``game-m10`` (10 position sensors, 1,023 strategies per player) and ``grid-ieee14`` (34 meters,
``max_subset_size`` k = 2: 596 defender and 595 attacker strategies). The exact equilibrium comes
from the double oracle (:func:`baselines.game.solve_double_oracle`, certified by its best-response
gap) and from the full LP on :func:`baselines.game.payoff_matrix` (:func:`~baselines.game.
solve_zero_sum`); the two values must agree. PSRO (:func:`agents.selfplay.run_selfplay`, SB3 PPO
best responses on the one-shot Gymnasium views) is scored after every iteration by its NashConv
on the exact matrix, ``max_A L(x, A) − min_D L(D, y)`` (the sum of the two players'
exploitabilities, docs/math.md §5), relative to the game value; the target is at most 1 %.
"""

from __future__ import annotations

import argparse
import json
import platform
import tempfile
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from agents.config import GameConfig, Hyperparameters, RunSettings
from agents.plots import exploitability_curve
from agents.selfplay import expected_rewards, game_algo, game_setup, run_selfplay
from baselines.game import exploitability, payoff_matrix, solve_double_oracle, solve_zero_sum
from experiments.markdown import table
from experiments.results.common import write_rows
from fdia_env._validation import check_int

GAMES = ("game-m10", "grid-ieee14")
TARGET = 0.01  # PSRO's relative NashConv target: 1 % of the game value


@dataclass(frozen=True)
class PsroSetting:
    """One PSRO run of the table.

    Attributes:
        scenario: A sensor-game preset of ``agents.registry`` (``ch5-game``, ``game-m10``,
            ``grid-ieee14``).
        iterations: PSRO iterations (each trains one attacker and one defender best response).
        steps: Environment steps per learned best response.
        algo: SB3 learner of the best responses (``PPO``, ``A2C``, ``DQN`` or
            ``MaskablePPO``); None: ``train.py``'s default for the scenario
            (:data:`agents.config.SCENARIO_DEFAULTS`: MaskablePPO in the sequential format on
            grid-ieee14, PPO on the subset format elsewhere).
    """

    scenario: str
    iterations: int
    steps: int
    algo: str | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.scenario, str):
            raise TypeError(f"scenario must be a preset name, got {type(self.scenario).__name__}")
        check_int("iterations", self.iterations, minimum=1)
        check_int("steps", self.steps, minimum=1)
        if self.algo not in (None, "PPO", "A2C", "DQN", "MaskablePPO"):
            raise ValueError(
                f"algo must be one of PPO, A2C, DQN, MaskablePPO (or None: train.py's default "
                f"for the scenario), got {self.algo!r}"
            )


FULL = (PsroSetting("game-m10", 10, 16384), PsroSetting("grid-ieee14", 24, 4096))
QUICK = (PsroSetting("game-m10", 3, 2048),)


def exact_equilibrium(scenario: str) -> dict[str, Any]:
    """The game's exact value by the double oracle and by the full LP, with their wall times.

    Returns:
        A dict with the payoff matrix ``L`` (defender rows), the LP value and support sizes, the
        double oracle's value, certified gap, iterations, restricted size and both wall times.

    Raises:
        ValueError: For a scenario the solvers do not know (they name it).
    """
    start = time.perf_counter()
    do = solve_double_oracle(scenario)
    do_seconds = time.perf_counter() - start
    start = time.perf_counter()
    L = payoff_matrix(scenario)
    x, y, value = solve_zero_sum(L)
    lp_seconds = time.perf_counter() - start
    return {
        "L": L,
        "lp_value": float(value),
        "lp_support": (int((x > 1e-9).sum()), int((y > 1e-9).sum())),
        "lp_seconds": lp_seconds,
        "do_value": do.value,
        "do_gap": do.gap,
        "do_iterations": do.iterations,
        "do_restricted_size": do.restricted_size,
        "do_seconds": do_seconds,
        "do_support": (len(do.defender), len(do.attacker)),
    }


def psro_against_exact(
    setting: PsroSetting, seed: int = 0, runs_root: Path | None = None
) -> dict[str, Any]:
    """Run PSRO on ``setting`` and score every iteration on the exact payoff matrix.

    Args:
        setting: Scenario, iterations, steps per best response and learner.
        seed: Seed of the PSRO run (best responses derive theirs from it).
        runs_root: Folder for the run folder (default: a temporary one, removed).

    Returns:
        One row: the exact references (:func:`exact_equilibrium`, without the matrix), the
        PSRO history (per iteration: NashConv, relative NashConv, each side's exploitability,
        the learned actions and their best-response gaps), the populations, the largest
        difference between the empirical meta-game and the exact matrix entries of the learned
        actions, the first iteration at or below :data:`TARGET` and the wall times.

    Raises:
        ValueError: For a bad seed or setting (naming the parameter).
        TypeError: For a setting that is not a :class:`PsroSetting`.
    """
    if not isinstance(setting, PsroSetting):
        raise TypeError(f"setting must be a PsroSetting, got {type(setting).__name__}")
    seed = check_int("seed", seed, minimum=0)
    exact = exact_equilibrium(setting.scenario)
    L = exact.pop("L")
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp) if runs_root is None else Path(runs_root)
        cfg = GameConfig(
            method="psro",
            env="sensor_game_v0",
            scenario=setting.scenario,
            algo=setting.algo,
            iterations=setting.iterations,
            steps_per_iteration=setting.steps,
            final_eval_episodes=1,
            run=RunSettings(seed=seed, runs_root=root, progress_bar=False, torch_threads=1),
            hp=Hyperparameters(),
        )
        start = time.perf_counter()
        result = run_selfplay(cfg, report=None)
        psro_seconds = time.perf_counter() - start
        state = json.loads((result.run_dir / "state.json").read_text())
    pops = result.populations
    meta = np.array(state["meta_payoff"], dtype=float)
    exact_meta = L[np.ix_(pops["defender"], pops["attacker"])]
    value = exact["lp_value"]
    history = []
    for rec in result.history:
        e = exploitability(L, rec["x"], rec["y"], value)  # re-scored here, independently
        history.append(
            {
                "iteration": rec["iteration"],
                "timesteps": rec["timesteps"],
                "train_seconds": rec["train_seconds"],
                "nash_conv": e.nash_conv,
                "relative_nash_conv": e.nash_conv / abs(value),
                "defender": e.defender,
                "attacker": e.attacker,
                "br_attacker": rec["br_attacker"],
                "br_defender": rec["br_defender"],
                "br_gap_attacker": rec["br_gap_attacker"],
                "br_gap_defender": rec["br_gap_defender"],
                "selfplay_nash_conv": rec["nash_conv"],
            }
        )
    reached = [h["iteration"] for h in history if h["relative_nash_conv"] <= TARGET]
    return {
        "scenario": setting.scenario,
        "algo": game_algo(cfg),
        "action": game_setup(cfg).env_kwargs.get("action", "subset"),
        "expected_rewards": expected_rewards(cfg, game_algo(cfg)),
        "iterations": setting.iterations,
        "steps_per_br": setting.steps,
        "seed": seed,
        "strategies": list(L.shape),
        **exact,
        "lp_do_relative_difference": abs(exact["lp_value"] - exact["do_value"]) / abs(value),
        "history": history,
        "populations": pops,
        "meta_max_abs_error": float(np.abs(meta - exact_meta).max()),
        "final_relative_nash_conv": history[-1]["relative_nash_conv"],
        "best_relative_nash_conv": min(h["relative_nash_conv"] for h in history),
        "first_iteration_at_target": reached[0] if reached else None,
        "psro_seconds": psro_seconds,
    }


def plot_row(row: dict[str, Any], path: Path) -> Path:
    """The exploitability per PSRO iteration, with 0 (the exact equilibrium) and 1 % lines."""
    title = (
        f"PSRO ({row['algo']}, {row['steps_per_br']} steps per BR) on {row['scenario']}, "
        f"v = {row['lp_value']:.4g}"
    )
    return exploitability_curve(path, row["history"], row["lp_value"], title)


EXACT_HEADER = (
    "game", "strategies (def × att)", "LP value", "DO value", "abs(LP − DO) / v",
    "DO iterations (support)", "DO wall", "LP wall",
)  # fmt: skip
PSRO_HEADER = (
    "game", "PSRO iterations × steps per BR", "NashConv / v: first", "best", "last",
    "first iteration ≤ 1 %", "meta-game vs exact entries", "PSRO wall",
)  # fmt: skip
ITERATION_HEADER = (
    "iteration", "NashConv / v", "defender expl. / v", "attacker expl. / v",
    "BR defender (gap / v)", "BR attacker (gap / v)", "wall",
)  # fmt: skip


def format_game(rows: list[dict[str, Any]]) -> str:
    """The rows as Markdown tables: the exact solvers, PSRO, then PSRO per iteration."""
    exact = [
        [
            r["scenario"],
            f"{r['strategies'][0]} × {r['strategies'][1]}",
            f"{r['lp_value']:.10g}",
            f"{r['do_value']:.10g}",
            f"{r['lp_do_relative_difference']:.1e}",
            f"{r['do_iterations']} ({r['do_support'][0]} + {r['do_support'][1]})",
            f"{r['do_seconds']:.2f} s",
            f"{r['lp_seconds']:.2f} s",
        ]
        for r in rows
    ]
    psro = [
        [
            r["scenario"],
            f"{r['iterations']} × {r['steps_per_br']} ({r['algo']}"
            f"{', expected rewards' if r.get('expected_rewards') else ''})",
            f"{r['history'][0]['relative_nash_conv']:.2%}",
            f"{r['best_relative_nash_conv']:.2%}",
            f"{r['final_relative_nash_conv']:.2%}",
            r["first_iteration_at_target"] or "not reached",
            f"max abs error {r['meta_max_abs_error']:.1e}",
            f"{r['psro_seconds']:.0f} s",
        ]
        for r in rows
    ]
    parts = [
        table(EXACT_HEADER, exact),
        table(PSRO_HEADER, psro),
    ]
    for r in rows:
        v = abs(r["lp_value"])
        per_iteration = [
            [
                h["iteration"],
                f"{h['relative_nash_conv']:.2%}",
                f"{h['defender'] / v:.2%}",
                f"{h['attacker'] / v:.2%}",
                f"{h['br_defender']} ({h['br_gap_defender'] / v:.2%})",
                f"{h['br_attacker']} ({h['br_gap_attacker'] / v:.2%})",
                f"{h['train_seconds']:.0f} s",
            ]
            for h in r["history"]
        ]
        parts.append(
            f"PSRO on {r['scenario']}, per iteration (NashConv / v; learned actions and the gap "
            "of each to an exact best response):\n\n" + table(ITERATION_HEADER, per_iteration)
        )
    return "\n\n".join(parts)


def run(
    quick: bool = False,
    seed: int = 0,
    out: Path | None = None,
    games: Sequence[str] | None = None,
) -> str:
    """The ``game`` table (Markdown); ``quick``: 3 PSRO iterations on game-m10, 2,048 steps.

    Args:
        quick: The reduced run.
        seed: Seed of the PSRO runs.
        out: Folder for ``game.json`` (the rows run) and the plots (none written when None).
        games: Only these rows (names of :data:`GAMES`; None: all of the run's).

    Raises:
        ValueError: For a game that is not a row of the table (listing the rows).
    """
    settings = QUICK if quick else FULL
    if games is not None:
        names = [s.scenario for s in settings]
        unknown = [g for g in games if g not in names]
        if unknown or not games:
            raise ValueError(f"games must be some of {', '.join(names)}, got {list(games)!r}")
        settings = tuple(s for s in settings if s.scenario in games)
    start = time.perf_counter()
    rows = [psro_against_exact(s, seed) for s in settings]
    if out is not None:
        write_rows(out / "game.json", rows)
        for r in rows:
            plot_row(r, out / f"results_game_{r['scenario'].replace('-', '_')}.png")
    machine = f"{platform.machine()}, {platform.processor() or platform.system()}"
    return (
        format_game(rows)
        + f"\n\nWall time {time.perf_counter() - start:.0f} s (seed {seed}; {machine})."
    )


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m experiments.results.game [--games ...]``: the table, or some of its rows."""
    parser = argparse.ArgumentParser(
        prog="python -m experiments.results.game",
        description="PSRO with learned best responses against the exact equilibrium.",
    )
    parser.add_argument("--games", nargs="+", choices=GAMES, default=None, help="rows to run")
    parser.add_argument("--quick", action="store_true", help="reduced run")
    parser.add_argument("--seed", type=int, default=0, help="seed of the PSRO runs")
    parser.add_argument("--out", type=Path, default=None, help="folder for JSON rows and plots")
    args = parser.parse_args(argv)
    print(run(args.quick, args.seed, args.out, args.games), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
