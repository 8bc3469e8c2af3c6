"""Recompute the stored references of the benchmark tasks and compare them, or write them.

Every stored number is recomputed with the installed solvers: the deterministic ones (optima,
heuristics, game values, bounds) must agree to :data:`RTOL`, and so must random play's mean,
whose episodes are seeded. ``seconds`` in the JSON file is how long a task's computation took;
``--cheap`` verifies only the tasks under :data:`CHEAP_SECONDS`.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from agents.bench.outputs import read_text, write_text
from agents.bench.references import compute
from fdia_env import tasks
from fdia_env.tasks.payoffs import FOLDER, MANIFEST
from fdia_env.tasks.stored import check_references, recorded, write_digests
from fdia_env.tasks.task import References

RTOL = 1e-7
ATOL = 1e-12
CHEAP_SECONDS = 5.0
REFERENCES_PATH = tasks.REFERENCES_PATH


@dataclass(frozen=True)
class Check:
    """One task's verification: the numbers that differ (empty when it passes)."""

    task: str
    seconds: float
    mismatches: tuple[str, ...]

    @property
    def ok(self) -> bool:
        """Whether every recomputed number equals the stored one."""
        return not self.mismatches


def _close(a: Any, b: Any) -> bool:
    if a is None or b is None:
        return a is b
    return math.isclose(float(a), float(b), rel_tol=RTOL, abs_tol=ATOL)


def compare(stored: References, fresh: References) -> list[str]:
    """The numbers of ``fresh`` that differ from ``stored`` (``"field: stored != fresh"``)."""
    out = []
    pairs = [
        ("random.mean", stored.random.mean, fresh.random.mean),
        ("random.ci95", stored.random.ci95, fresh.random.ci95),
        ("optimum.value", stored.optimum.value, fresh.optimum.value),
        ("optimum.bound", stored.optimum.bound, fresh.optimum.bound),
        ("game_value", stored.game_value, fresh.game_value),
    ]
    for name in sorted(set(stored.heuristics) | set(fresh.heuristics)):
        pairs.append(
            (f"heuristics[{name!r}]", stored.heuristics.get(name), fresh.heuristics.get(name))
        )
    for label, a, b in pairs:
        if not _close(a, b):
            out.append(f"{label}: stored {a!r} != recomputed {b!r}")
    if stored.optimum.certified != fresh.optimum.certified:
        out.append(f"optimum.certified: {stored.optimum.certified} != {fresh.optimum.certified}")
    if stored.objective != fresh.objective or stored.metric != fresh.metric:
        out.append("objective/metric differ")
    return out


def stored_seconds(name: str) -> float:
    """How long the stored computation of task ``name`` took (inf if not recorded)."""
    return float(tasks.stored_references().get(name, {}).get("seconds", math.inf))


def verify(names: Iterable[str]) -> list[Check]:
    """Recompute and compare the references of the tasks ``names``."""
    checks = []
    for name in names:
        task = tasks.get(name)
        start = time.perf_counter()
        fresh = compute(tasks.spec(name))
        seconds = time.perf_counter() - start
        checks.append(Check(name, seconds, tuple(compare(task.references, fresh))))
    return checks


def _existing(path: Path, keep: bool) -> dict[str, Any]:
    """The stored entries ``write`` keeps: checked (and, in the package, their digest too)."""
    if not keep or not path.exists():
        return {}
    package = path.resolve() == REFERENCES_PATH
    expected = recorded().REFERENCES if package else None
    return check_references(path, path.read_bytes(), expected)


def write(
    names: Iterable[str], path: Path = REFERENCES_PATH, keep: bool = True
) -> dict[str, float]:
    """Compute the references of ``names`` and store them in ``path``.

    Writing the package's ``references.json`` rewrites its recorded SHA-256 in
    :mod:`fdia_env.tasks.digests` too.

    Args:
        names: The tasks to compute.
        path: The JSON file.
        keep: Keep the other tasks' stored entries (the file must pass its checks: an edited
            file is refused); False writes ``names`` only.

    Returns:
        Task name → seconds its computation took.

    Raises:
        StoredDataError: When ``keep`` and the stored file is changed or malformed.
    """
    data = _existing(path, keep)
    took = {}
    for name in names:
        start = time.perf_counter()
        refs = compute(tasks.spec(name))
        took[name] = time.perf_counter() - start
        data[name] = {**refs.to_dict(), "seconds": round(took[name], 3)}
        order = [s.name for s in tasks.SPECS]
        data = {
            k: data[k]
            for k in sorted(
                data, key=lambda k: (k not in order, order.index(k) if k in order else 0, k)
            )
        }
        path.write_text(json.dumps(data, indent=1, ensure_ascii=False) + "\n", encoding="utf-8")
        if path.resolve() == REFERENCES_PATH:
            write_digests(path, path.with_name(MANIFEST), path.with_name(FOLDER))
    if path.resolve() == REFERENCES_PATH:
        tasks.stored_references.cache_clear()
    return took


TABLE_START = "<!-- tasks:start -->"
TABLE_END = "<!-- tasks:end -->"


def _num(x: float) -> str:
    return f"{x:.4g}"


def tasks_table() -> str:
    """The markdown table of every task and its stored references (docs/benchmark.md)."""
    lines = [
        "| task | player | grade | random: raw (ratio to optimum) | best heuristic: raw "
        "(normalised) | certified reference: raw (solver) |",
        "|---|---|---|---|---|---|",
    ]
    for task in tasks.TASKS.values():
        refs = task.references
        best = refs.best_heuristic
        heur = (
            "-" if best is None else (f"{best[0]}: {_num(best[1])} ({refs.normalise(best[1]):.3f})")
        )
        opt = refs.optimum
        where = opt.name if opt.certified else f"{opt.name}, bound {_num(opt.bound)}"
        lines.append(
            f"| `{task.name}` | {task.player} | {task.difficulty} | "
            f"{_num(refs.random.mean)} ({refs.random_ratio:.3f}) | {heur} | "
            f"{_num(opt.value)} ({where}) |"
        )
    return "\n".join(lines)


def write_table(page: Path) -> bool:
    """Replace the table between the markers of ``page``; True when the page changed.

    Raises:
        ValueError: When ``page`` lacks the markers.
        agents.bench.outputs.OutputPathError: (a ValueError) Naming ``--page`` and the path
            when it cannot be read or written.
    """
    text = read_text("--page", page)
    if TABLE_START not in text or TABLE_END not in text:
        raise ValueError(f"page {page} has no {TABLE_START} ... {TABLE_END} markers")
    head, rest = text.split(TABLE_START, 1)
    _, tail = rest.split(TABLE_END, 1)
    new = f"{head}{TABLE_START}\n\n{tasks_table()}\n\n{TABLE_END}{tail}"
    if new != text:
        write_text("--page", page, new)
    return new != text
