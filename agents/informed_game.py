"""Exact IBR / FSP / PSRO (double oracle) on the informed-attacker Bayesian sensor game.

In the informed model (:mod:`baselines.game.bayesian`) nature draws the attacker's type s with
prior p_s, the attacker observes it and plays one strategy per type, so the game is no matrix
game over the attacker's actions: its pure strategies are the type tuples ``(a_1, ..., a_S)``.
The population loop of :mod:`agents.population` runs on them with exact best responses: the
attacker answers the defender's mix x type by type (``argmax_j (L_s'x)_j``), the defender
answers the attacker's per-type mixes (y_s) with ``argmin_i Σ_s p_s (L_s y_s)_i``. PSRO's
meta-game is exact, ``Σ_s p_s L_s[D, a_s]`` for a defender subset D and a type tuple, so PSRO
is double oracle on the Bayesian game and stops at its fixed point, an equilibrium of the full
game. A mix over type tuples is played as its marginal per type (the attacker decides once per
episode, after seeing its type), the (S, n) strategy the Bayesian game scores.

:func:`run_informed_task` is ``train.py game --task`` on such a task (the default ``--algo
exact``): the run folder holds ``config.json``, ``state.json`` (the populations and the
iterations' records), ``scores.json`` (the final mixes ``x`` and ``y``, one row per type) and
``learning_curve.png``.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from contextlib import ExitStack
from typing import Any

import numpy as np

from baselines.game import solve_zero_sum

SIDES = ("attacker", "defender")


def best_responses(game: Any, x: np.ndarray, y: np.ndarray) -> tuple[tuple[int, ...], int]:
    """The attacker's best type tuple against ``x`` and the defender's best action against ``y``.

    Ties go to the lowest action. ``y``: (S, n), one mix per type.
    """
    per_type = np.einsum("i,sij->sj", x, game.matrices)  # (S, n): (L_s'x)_j
    attack = tuple(int(a) for a in per_type.argmax(axis=1))
    defence = int(np.einsum("s,sij,sj->i", game.priors, game.matrices, y).argmin())
    return attack, defence


def tuple_payoff(game: Any, defender: int, attacker: tuple[int, ...]) -> float:
    """``Σ_s p_s L_s[defender, attacker[s]]``: the exact payoff of a pure pair."""
    s = np.arange(game.n_types)
    return float(game.priors @ game.matrices[s, defender, np.asarray(attacker)])


def mixes(
    method: str, game: Any, defenders: list[int], attackers: list[tuple[int, ...]]
) -> tuple[np.ndarray, np.ndarray]:
    """The defender's (m,) and the attacker's (S, n) strategies after an iteration of ``method``.

    ``"ibr"``: the last answers; ``"fsp"``: the uniform mix over each population; ``"psro"``:
    the equilibrium of the exact meta-game, spread over the actions (the attacker's per type).
    """
    S, m, n = game.matrices.shape
    if method == "ibr":
        wx, wy = np.eye(len(defenders))[-1], np.eye(len(attackers))[-1]
    elif method == "fsp":
        wx, wy = np.ones(len(defenders)), np.ones(len(attackers))
    else:
        meta = np.array([[tuple_payoff(game, d, a) for a in attackers] for d in defenders])
        wx, wy, _ = solve_zero_sum(meta)
    x = np.zeros(m)
    np.add.at(x, defenders, wx)
    y = np.zeros((S, n))
    tuples = np.asarray(attackers)
    for s in range(S):
        np.add.at(y[s], tuples[:, s], wy)
    return x / x.sum(), y / y.sum(axis=1, keepdims=True)


def run_informed_population(
    method: str,
    game: Any,
    iterations: int,
    converge: bool,
    stop: Callable[[], bool] | None = None,
    on_iteration: Callable[[dict[str, Any], dict[str, list[Any]]], None] | None = None,
) -> list[dict[str, Any]]:
    """Iterate ``method`` with exact answers from uniform mixes; the iterations' records.

    Each record has the keys of :func:`agents.population.run_population`'s (``br_attacker``
    is the type tuple, ``y`` the (S, n) mix as nested lists).

    Args:
        method: ``"psro"``, ``"fsp"`` or ``"ibr"``.
        game: The :class:`~baselines.game.bayesian.BayesianGame` (informed).
        iterations: The most iterations.
        converge: Also stop at the fixed point (:func:`agents.population.at_fixed_point`).
        stop: Polled before each iteration; True ends the loop.
        on_iteration: Called with each record and the populations.
    """
    from agents.population import at_fixed_point

    S, m, n = game.matrices.shape
    value = game.value
    x, y = np.full(m, 1.0 / m), np.full((S, n), 1.0 / n)
    pops: dict[str, list[Any]] = {"attacker": [], "defender": []}
    history: list[dict[str, Any]] = []
    start = time.perf_counter()
    for it in range(1, iterations + 1):
        if (stop is not None and stop()) or (converge and history and at_fixed_point(method, pops)):
            break
        attack, defence = best_responses(game, x, y)
        against_x = np.einsum("i,sij->sj", x, game.matrices)[np.arange(S), list(attack)]
        gap_att = game.defender_worst_case(x) - float(game.priors @ against_x)
        gap_def = float(
            np.einsum("s,sij,sj->i", game.priors, game.matrices, y)[defence]
        ) - game.attacker_worst_case(y)
        pops["attacker"].append(attack)
        pops["defender"].append(defence)
        x, y = mixes(method, game, pops["defender"], pops["attacker"])
        e = game.exploitability(x, y, value)
        rec: dict[str, Any] = {
            "iteration": it,
            "timesteps": 0,
            "train_seconds": round(time.perf_counter() - start, 3),
            "defender": e.defender,
            "attacker": e.attacker,
            "nash_conv": e.nash_conv,
            "relative_nash_conv": e.nash_conv / abs(value),
            "br_attacker": list(attack),
            "br_defender": defence,
            "br_gap_attacker": float(gap_att),
            "br_gap_defender": float(gap_def),
            "x": x.tolist(),
            "y": y.tolist(),
        }
        history.append(rec)
        if on_iteration is not None:
            on_iteration(rec, pops)
    return history


def run_informed_task(
    cfg: Any,
    entries: dict[str, Any],
    env_kwargs: dict[str, Any],
    prefix: str,
    state_file: str,
    result: Callable[..., Any],
    report: Any = print,
) -> Any:
    """``train.py game --task`` on an informed-attacker Bayesian game task (exact answers).

    Args:
        cfg: The game command's :class:`~agents.config.GameConfig` (``--task``, ``--method``,
            ``--iterations``, ``--final-eval-episodes``, the run settings).
        entries: Each side's :class:`agents.game_task_runs.GameTaskEntry`.
        env_kwargs: The task's env options.
        prefix: The run folder's name without its time.
        state_file: The name of the folder's loop state (the game runs' ``state.json``).
        result: Builds the result (:class:`agents.selfplay.SelfPlayResult`).
        report: Called with one line per iteration (None: silent).

    Returns:
        ``result(...)``: an :class:`agents.selfplay.SelfPlayResult` whose ``y`` is (S, n), one
        mix per type.

    Raises:
        FileExistsError: When the run folder exists.
    """
    from agents.game_task_runs import EXACT, task_resolved
    from agents.lifecycle import game_scores, open_run
    from agents.plots import exploitability_curve
    from agents.population import report_line
    from agents.runs import write_json
    from agents.seeding import seed_everything
    from agents.training import make_env

    attacker = entries["attacker"]
    task = attacker.task
    with make_env(lambda: attacker.make_resolved(env_kwargs), attacker.gym_id) as env:
        reference = attacker.reference_of(env)
    game = reference.bayes
    value = float(game.value)
    S, m, n = game.matrices.shape
    with ExitStack() as stack:
        run = open_run(cfg, stack, prefix, state_file, report, fresh=True)
        run_dir = run.path
        run.begin()
        run.write_config(
            "game",
            cfg,
            {
                "algo": EXACT,
                "hyperparameters": {},
                "reward_scale": None,
                "expected_rewards": False,
                "reference": {"name": reference.name, "value": value},
                **task_resolved(task),
            },
        )
        seed_everything(cfg.run.seed, cfg.run.torch_threads)
        stop = run.watch_signals()

        def on_iteration(rec: dict[str, Any], pops: dict[str, list[Any]]) -> None:
            write_json(
                run_dir / state_file,
                {"populations": pops, "history": [*history_so_far, rec]},
            )
            history_so_far.append(rec)
            if report is not None:
                report(report_line(rec))

        history_so_far: list[dict[str, Any]] = []
        # double oracle adds a new strategy in every iteration before its fixed point
        iterations = m + n**S if cfg.converges and cfg.iterations is None else cfg.n_iterations
        history = run_informed_population(
            cfg.method, game, iterations, cfg.converges, lambda: stop.requested, on_iteration
        )
        if not history:
            run.discard()
            return result(
                run_dir, cfg.method, np.zeros(0), np.zeros(0), value, [], interrupted=stop.signum
            )
        x, y = np.array(history[-1]["x"]), np.array(history[-1]["y"])
        seconds = history[-1]["train_seconds"]
        evaluations = informed_evaluations(entries, env_kwargs, game, x, y, cfg)
        pops = {
            "attacker": [rec["br_attacker"] for rec in history],
            "defender": [rec["br_defender"] for rec in history],
        }
        run.write_scores(
            game_scores(cfg.method, value, x, y, history, 0, seconds, populations=pops),
            evaluations,
        )
        exploitability_curve(
            run_dir / "learning_curve.png",
            history,
            value,
            f"{cfg.method.upper()} (exact best responses) on task {task.name}",
        )
        return result(
            run_dir, cfg.method, x, y, value, history, evaluations, pops, seconds,
            interrupted=stop.signum,
        )  # fmt: skip


def informed_evaluations(
    entries: dict[str, Any],
    env_kwargs: dict[str, Any],
    game: Any,
    x: np.ndarray,
    y: np.ndarray,
    cfg: Any,
) -> dict[str, Any]:
    """Each side's final mix and Bayesian equilibrium mix, played against the other final mix."""
    from agents.evaluate import evaluate
    from agents.seeding import derived_seed
    from baselines.game import MixedStrategyPolicy, TypedMixedStrategyPolicy

    seed = derived_seed(cfg.run.seed, 20_000)
    sol = game.solution
    rows = {}
    for label, side, probs, other in (
        ("attacker mix (exact)", "attacker", y, x),
        ("attacker Bayesian equilibrium", "attacker", sol.y, x),
        ("defender mix (exact)", "defender", x, y),
        ("defender Bayesian equilibrium", "defender", sol.x, y),
    ):
        entry = entries[side]
        policy = TypedMixedStrategyPolicy if side == "attacker" else MixedStrategyPolicy
        opponent = MixedStrategyPolicy if side == "attacker" else TypedMixedStrategyPolicy
        with entry.make_resolved(
            env_kwargs, opponent=opponent(other, seed=derived_seed(seed, 1))
        ) as env:
            player = policy(probs, seed=seed)
            reference = entry.reference_of(env)
            rows[label] = evaluate(player, env, cfg.final_eval_episodes, seed, reference)
    return rows
