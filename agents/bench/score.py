"""``python -m agents.bench score``: score any agent on a named benchmark task.

The agent (a ``train.py`` run folder, a model file, a trusted stable-baselines3 ``.zip``, an
RLlib run's state, a torch-ppo policy or a ``module:function`` callable; see
:mod:`agents.bench.agents`) plays the task's env for ``episodes`` episodes under each of
``seeds`` evaluation seeds (seed ``s`` plays episodes reset with ``s·SEED_STRIDE + i``). The
report gives the raw mean return with its 95 % Student-t interval over all those episodes, the
normalised score of that mean (``task.normalise``: 0 = random play, 1 = the certified optimum,
or on a task whose reference is only bounded the best known value: :func:`scale_legend`; for
games the exploitability-based score relative to the game value), its interval (the raw
interval's ends normalised), the normalised score of each seed, and the task's stored
references beside it (random play, each heuristic, the optimum or best known value with its
certified bound).

>>> from fdia_env.tasks import names
>>> code = main(["--task", names()[0], "--agent", "random", "--seeds", "1", "--episodes", "2"])
... # doctest: +SKIP
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from agents.bench.outputs import OutputPathError, check_new_file, write_text

SEED_STRIDE = 100_000  # evaluation seed s plays the episodes reset with s·SEED_STRIDE + i


@dataclass(frozen=True)
class Score:
    """What :func:`score` returns.

    Attributes:
        task: The task's name.
        agent: What the agent was given as.
        description: The agent's kind (algorithm, steps trained).
        seeds: The evaluation seeds.
        returns: (len(seeds), episodes) undiscounted episode returns.
        mean: Mean return over every episode.
        ci95: Half-width of its 95 % Student-t interval (NaN for one episode).
        normalised: ``task.normalise`` of the score's raw value.
        normalised_ci: The interval's ends normalised (lower, upper).
        per_seed: Normalised score of each seed's mean.
        raw_name: What the raw value is (``"return"``, or for games ``"exploitability"``).
        raw: The raw value normalised (the mean return; a game's exploitability).
        extras: Further numbers (a game's relative exploitability, ...).
    """

    task: str
    agent: str
    description: str
    seeds: tuple[int, ...]
    returns: np.ndarray = field(repr=False)
    mean: float
    ci95: float
    normalised: float
    normalised_ci: tuple[float, float]
    per_seed: tuple[float, ...]
    raw_name: str = "return"
    raw: float = math.nan
    extras: dict[str, float] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (NaN as None)."""
        return {
            "task": self.task,
            "agent": self.agent,
            "description": self.description,
            "seeds": list(self.seeds),
            "episodes": int(self.returns.shape[1]),
            "mean": _clean(self.mean),
            "ci95": _clean(self.ci95),
            "normalised": _clean(self.normalised),
            "normalised_ci": [_clean(v) for v in self.normalised_ci],
            "per_seed": [_clean(v) for v in self.per_seed],
            "raw_name": self.raw_name,
            "raw": _clean(self.raw),
            "extras": {k: _clean(v) for k, v in self.extras.items()},
        }


def _clean(v: float | None) -> float | None:
    return None if v is None or not math.isfinite(float(v)) else float(v)


def _check_seeds(seeds: Sequence[int]) -> tuple[int, ...]:
    out = tuple(seeds)
    if not out or any(isinstance(s, bool) or not isinstance(s, int) or s < 0 for s in out):
        raise ValueError(f"seeds must be a non-empty sequence of integers >= 0, got {seeds!r}")
    if len(set(out)) != len(out):
        raise ValueError(f"seeds must be distinct, got {seeds!r}")
    return out


def _is_game(task: Any) -> bool:
    return bool(getattr(task, "is_game", False))


def score_policy(
    task: Any,
    policy: Any,
    seeds: Sequence[int] = (0, 1, 2),
    episodes: int | None = None,
    agent: str = "policy",
    description: str = "",
    deterministic: bool | None = None,
) -> Score:
    """Play ``policy`` on ``task`` and normalise its score (see the module docstring).

    Args:
        task: A :class:`fdia_env.tasks.Task` (or its name).
        policy: Anything with stable-baselines3's ``predict``, or ``"random"``.
        seeds: Evaluation seeds.
        episodes: Episodes per seed (default: the task's ``episodes``).
        agent: The agent's name in the report.
        description: Its kind.
        deterministic: Passed to ``predict``; None (default): the most likely action in a
            single-player task, the policy's action distribution (its mixed strategy) in a
            game, where the equilibrium is mixed.

    Raises:
        ValueError: For a bad task name (naming ``task``), bad ``seeds`` or ``episodes``.
        agents.evaluate.InvalidActionError: (a ValueError) Naming ``agent`` when the policy
            returns an action outside the env's action space (the env's own check; nothing is
            rounded or converted).
    """
    from agents.evaluate import InvalidActionError, evaluate, t_interval

    task = _task(task)
    seeds = _check_seeds(seeds)
    n = task.episodes if episodes is None else episodes
    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise ValueError(f"episodes must be a positive integer, got {episodes!r}")
    if deterministic is None:
        deterministic = not _is_game(task)
    env = task.make_env()
    try:
        runs = [
            evaluate(policy, env, n, seed=s * SEED_STRIDE, deterministic=deterministic)
            for s in seeds
        ]
    except InvalidActionError as exc:
        raise InvalidActionError(f"agent {agent}: {exc}") from None
    finally:
        env.close()
    returns = np.stack([r.returns for r in runs])
    mean = float(returns.mean())
    ci95 = t_interval(returns.ravel())
    extras: dict[str, float] = {}
    if _is_game(task):
        # one mixed strategy per seed; the raw number is its worst-case return, value − expl.
        if any(r.score is None or r.score_name != "exploitability" for r in runs):
            raise ValueError(f"task {task.name}: its env gives no exploitability to score")
        expl = np.array([max(float(r.score), 0.0) for r in runs])
        value = float(task.references.optimum.value)
        raw, raw_name = value - float(expl.mean()), "worst-case return"
        per_seed = tuple(float(task.normalise_exploitability(e)) for e in expl)
        spread = t_interval(expl) if expl.size > 1 else 0.0
        spread = 0.0 if not math.isfinite(spread) else spread
        ends = sorted(task.normalise(raw + d) for d in (-spread, spread))
        extras["exploitability"] = float(expl.mean())
        extras["relative_exploitability"] = float(
            np.mean([r.extras.get("relative_exploitability", math.nan) for r in runs])
        )
    else:
        raw, raw_name = mean, "return"
        per_seed = tuple(float(task.normalise(float(r.mean))) for r in runs)
        half = 0.0 if not math.isfinite(ci95) else ci95
        ends = sorted(task.normalise(mean + d) for d in (-half, half))
    return Score(
        task=task.name,
        agent=agent,
        description=description,
        seeds=seeds,
        returns=returns,
        mean=mean,
        ci95=ci95,
        normalised=float(task.normalise(raw)),
        normalised_ci=(float(ends[0]), float(ends[1])),
        per_seed=per_seed,
        raw_name=raw_name,
        raw=raw,
        extras=extras,
    )


def _task(task: Any) -> Any:
    from fdia_env.tasks import get

    return get(task) if isinstance(task, str) else task


def score(
    task: Any,
    agent: str | Path,
    seeds: Sequence[int] = (0, 1, 2),
    episodes: int | None = None,
    algo: str | None = None,
    trust_checkpoint: bool = False,
    deterministic: bool | None = None,
) -> Score:
    """Load ``agent`` (:func:`agents.bench.agents.load_agent`) and score it on ``task``.

    Raises:
        ValueError: For a bad task name (naming ``task``), an agent that cannot be loaded or was
            trained on another task (naming ``agent``), bad ``seeds`` or ``episodes``.
        agents.checkpoint.UntrustedCheckpointError: For an SB3 ``.zip`` without
            ``trust_checkpoint``.
    """
    from agents.bench.agents import load_agent

    task = _task(task)
    env = task.make_env()
    try:
        loaded = load_agent(agent, task, env, algo=algo, trust_checkpoint=trust_checkpoint)
    finally:
        env.close()
    return score_policy(
        task, loaded.policy, seeds, episodes, str(agent), loaded.description, deterministic
    )


# ------------------------------------------------------------------------------ report


def _fmt(v: float | None, digits: int = 6) -> str:
    return "-" if v is None or not math.isfinite(float(v)) else f"{float(v):.{digits}g}"


def reference_rows(task: Any) -> list[tuple[str, float | None, str]]:
    """(name, raw number, note) of each stored reference: random, heuristics, the optimum."""
    refs = task.references
    rand = refs.random
    how = "exact" if rand.episodes == 0 else f"± {_fmt(rand.ci95, 3)}, {rand.episodes} episodes"
    rows: list[tuple[str, float | None, str]] = [("random", rand.mean, how)]
    for name, value in refs.heuristics.items():
        rows.append((name, value, "heuristic"))
    best = refs.optimum
    if best.certified:
        note = "certified optimum"
    else:
        note = f"best known, certified bound {_fmt(best.bound)} (gap {best.gap:.2%})"
    rows.append((best.name, best.value, note))
    return rows


def scale_legend(task: Any) -> str:
    """What 0 and 1 of the normalised score are: random play, and the optimum or the best known.

    Where the optimum is only bounded, 1 is the best known value, and the certified bound's own
    normalised score says how far above it the optimum can lie.
    """
    best = task.references.optimum
    if best.certified:
        return "0 = random, 1 = optimum"
    return (
        f"0 = random, 1 = best known ({best.name}); the optimum is at most "
        f"{task.normalise(best.bound):.4f}"
    )


def report(result: Score, task: Any) -> str:
    """The text ``score`` prints."""
    n_seeds, n_eps = result.returns.shape
    lo, hi = result.normalised_ci
    unit = "worst-case return" if result.raw_name != "return" else "return"
    lines = [
        f"task        {task.name} ({task.family}, {task.player}, {task.difficulty})",
        f"agent       {result.agent}" + (f": {result.description}" if result.description else ""),
        f"episodes    {n_seeds * n_eps} ({n_seeds} seed{'s' * (n_seeds != 1)} x {n_eps})",
        f"raw return  {_fmt(result.mean)} ± {_fmt(result.ci95, 3)} (95 % CI over episodes"
        " and seeds)",
    ]
    if result.raw_name != "return":
        expl, rel = result.extras["exploitability"], result.extras["relative_exploitability"]
        lines.append(
            f"exploitability {_fmt(expl)} ({rel:.2%} of the game value): worst-case return "
            f"{_fmt(result.raw)}"
        )
    lines += [
        f"normalised  {result.normalised:.4f} [{lo:.4f}, {hi:.4f}] ({scale_legend(task)})",
        "per seed    " + ", ".join(f"{v:.4f}" for v in result.per_seed),
        f"references ({unit}, normalised):",
    ]
    rows = reference_rows(task)
    width = max([26, *(len(name) for name, _, _ in rows)])
    for name, value, note in rows:
        lines.append(f"  {name:<{width}} {_fmt(value):>12}  {task.normalise(value):7.4f}  {note}")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m agents.bench score``: print an agent's score on a task (exit 0; 2 on an error).

    Args:
        argv: The arguments after ``score``.
    """
    parser = argparse.ArgumentParser(
        prog="python -m agents.bench score",
        description="Score an agent on a benchmark task: raw return, normalised score "
        "(0 = random play, 1 = the certified optimum, or the best known value where the task's "
        "reference is only bounded) with its 95 % CI, and the references.",
    )
    parser.add_argument(
        "--task", required=True, help="task name (fdia_env.tasks.names() lists them)"
    )
    parser.add_argument(
        "--agent",
        required=True,
        help="a train.py run folder, a model .json, an SB3 .zip (with --trust-checkpoint), an "
        "RLlib run's rllib_state.json, a torch-ppo policy .json, 'module:function' or 'random'",
    )
    parser.add_argument("--seeds", type=int, default=3, help="evaluation seeds (default 3)")
    parser.add_argument(
        "--episodes", type=int, default=None, help="episodes per seed (default: the task's)"
    )
    parser.add_argument("--algo", default=None, help="the algorithm of an SB3 .zip")
    parser.add_argument(
        "--trust-checkpoint",
        action="store_true",
        help="allow an SB3 .zip, which is unpickled and can run code (only files you trust)",
    )
    mode = parser.add_mutually_exclusive_group()
    mode.add_argument(
        "--stochastic",
        action="store_true",
        help="sample the policy's actions (the default in games: its mixed strategy)",
    )
    mode.add_argument(
        "--deterministic",
        action="store_true",
        help="the most likely action (the default in single-player tasks)",
    )
    parser.add_argument(
        "--json",
        type=Path,
        default=None,
        help="also write the score as JSON to this file (missing parent folders are created)",
    )
    args = parser.parse_args(list(sys.argv[1:] if argv is None else argv))
    if args.seeds < 1:
        parser.error(f"--seeds must be >= 1, got {args.seeds}")
    try:
        if args.json is not None:  # before scoring: a bad path is reported at once
            check_new_file("--json", args.json)
        task = _task(args.task)
        result = score(
            task,
            args.agent,
            seeds=range(args.seeds),
            episodes=args.episodes,
            algo=args.algo,
            trust_checkpoint=args.trust_checkpoint,
            deterministic=False if args.stochastic else True if args.deterministic else None,
        )
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(report(result, task))
    if args.json is not None:
        try:
            write_text("--json", args.json, json.dumps(result.to_dict(), indent=2) + "\n")
        except OutputPathError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 2
    return 0
